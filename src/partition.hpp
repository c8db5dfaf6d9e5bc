// Degrees of freedom and their distribution.
//
// Free vertices are the vertices of bodies that are not fixed and that belong to
// at least one tet (a stray vertex has no mass and no stiffness: it stays put).
// Their natural order ("free index") follows the scene's natural vertex order.
// METIS splits the free-vertex graph (vertices adjacent when they share a tet)
// into one part per rank; the vertices are renumbered part by part, keeping the
// natural order inside a part, so rank r owns the contiguous block
// [vertex_start[r], vertex_start[r+1]) of "PETSc vertex" indices. DOF 3 p + c is
// coordinate c of PETSc vertex p (block size 3).
#pragma once

#include <petscsys.h>

#include <vector>

#include "scene.hpp"

namespace softbody {

struct DofLayout {
  std::vector<PetscInt> free_of_natural;     // natural vertex -> free index, or -1
  std::vector<PetscInt> natural_of_free;     // free index -> natural vertex
  std::vector<PetscInt> petsc_of_free;       // free index -> PETSc vertex
  std::vector<PetscInt> vertex_start;        // size ranks + 1: ownership of PETSc vertices
  PetscMPIInt rank = 0, size = 1;

  PetscInt num_free() const { return static_cast<PetscInt>(natural_of_free.size()); }
  PetscInt local_begin() const { return vertex_start[rank]; }
  PetscInt local_count() const { return vertex_start[rank + 1] - vertex_start[rank]; }
  // Natural-order layout of the free vertices with the same local sizes as the
  // PETSc layout: rank r holds free indices [vertex_start[r], vertex_start[r+1]).
};

// Collective. Rank 0 partitions with METIS and broadcasts the parts.
PetscErrorCode BuildDofLayout(MPI_Comm comm, const Scene &scene, DofLayout *layout);

// Not collective. The body of each vertex this rank owns, in PETSc order.
std::vector<int32_t> OwnedVertexBodies(const Scene &scene, const DofLayout &layout);

}  // namespace softbody
