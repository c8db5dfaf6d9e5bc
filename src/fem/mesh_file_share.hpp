// A body's share read straight from its softbody .h5 mesh file by every rank.
//
// Each rank reads its even slabs of the file's vertices and tets (ReadMeshSlabs,
// parallel HDF5); for a scene of this one body these are the rank's MeshShare
// slabs. The placement (PlaceMesh) needs the mesh's volume-weighted centroid: its
// sum runs over the tets in file order, rank after rank (each rank adds its tets
// to the running sum it receives from the rank before), so the placed positions
// are bit for bit those of the serial reader. The tets are checked for degeneracy
// before and after placement, as the serial reader checks them.
#pragma once

#include <petscsys.h>

#include "fem/mesh_share.hpp"
#include "io/scene.hpp"

namespace softbody {

// Collective. The shares of a scene of one body whose mesh is deferred
// (Body::mesh_deferred); rank 0 holds the scene's initial velocities. Bad input
// fails on every rank with one PETSC_ERR_USER_INPUT line naming the file.
PetscErrorCode ReadShareFromMeshFile(MPI_Comm comm, const Scene &scene, MeshShare *share);

}  // namespace softbody
