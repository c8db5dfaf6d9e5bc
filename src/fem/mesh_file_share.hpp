// A body's share read straight from its softbody .h5 mesh file by every rank.
//
// Each rank reads its even slabs of the file's vertices and tets (ReadMeshSlabs,
// parallel HDF5); DistributeScene moves them to the scene's slabs (for a scene of
// this one body they are the scene's slabs already). The placement (PlaceMesh) needs the mesh's
// volume-weighted centroid: its sum runs over the tets in file order, rank after rank (each rank
// adds its tets to the running sum it receives from the rank before), so the placed positions are
// bit for bit those of the serial reader. The tets are checked for degeneracy before and after
// placement, as the serial reader checks them.
#pragma once

#include <petscsys.h>

#include "fem/mesh_share.hpp"
#include "io/scene.hpp"

namespace softbody {

// Collective. The share of scene body b alone, whose mesh is deferred
// (Body::mesh_deferred): num_vertices, first_vertex, rest (placed), num_all_tets,
// first_tet and tets in the file's numbering (0-based, the body's own vertices);
// velocities empty. Bad input fails on every rank with one PETSC_ERR_USER_INPUT
// line naming the file.
PetscErrorCode ReadBodyShareFromFile(MPI_Comm comm, const Scene &scene, size_t b, MeshShare *share);

}  // namespace softbody
