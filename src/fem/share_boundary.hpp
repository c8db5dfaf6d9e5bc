// The boundary triangles of the scene's meshes, found from the ranks' shares of
// the tets (mesh_share.hpp) without any rank holding a mesh whole.
//
// A face is on the boundary when exactly one tet has it. Every rank sends each
// face of its tets (key: its sorted natural vertices) to the rank whose vertex
// slab holds the face's smallest vertex, which sorts what it receives and keeps
// the faces that came once. A kept face is oriented outward as its tet's face in
// BoundaryTriangles (mesh.hpp): the tet's signed volume, from the rest positions
// in the slabs, decides. Each rank ends with the boundary triangles whose
// smallest vertex is in its slab, sorted by key; in rank order these are the rows
// of BoundaryTriangles of each body in turn, in natural vertex numbers.
#pragma once

#include <petscsys.h>

#include <array>
#include <vector>

#include "fem/mesh_share.hpp"

namespace softbody {

// Collective. This rank's boundary triangles (natural vertices, outward order).
PetscErrorCode ShareBoundaryTriangles(MPI_Comm comm, const MeshShare &share,
                                      std::vector<std::array<PetscInt, 3>> *triangles);

}  // namespace softbody
