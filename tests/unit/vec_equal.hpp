// Whether two PETSc vectors of the same layout hold the same values bit for
// bit on every rank (std::equal on the local arrays, then a logical and over
// PETSC_COMM_WORLD). Collective.
#pragma once

#include <mpi.h>
#include <petscvec.h>

#include <algorithm>

namespace softbody {

inline bool BitwiseEqual(Vec a, Vec b) {
  PetscInt n;
  VecGetLocalSize(a, &n);
  const PetscScalar *pa, *pb;
  VecGetArrayRead(a, &pa);
  VecGetArrayRead(b, &pb);
  int equal = std::equal(pa, pa + n, pb);
  VecRestoreArrayRead(a, &pa);
  VecRestoreArrayRead(b, &pb);
  MPI_Allreduce(MPI_IN_PLACE, &equal, 1, MPI_INT, MPI_LAND, PETSC_COMM_WORLD);
  return equal;
}

}  // namespace softbody
