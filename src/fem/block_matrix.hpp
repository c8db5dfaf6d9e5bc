// A copy of a matrix of 3 x 3 blocks in PETSc's block format (MATBAIJ).
//
// Why not MatConvert: PETSc 3.18's MatConvert from MATMPIAIJ to MATMPIBAIJ
// sizes the off-diagonal part by visiting every global block column for every
// owned block row, O(N^2 / 9) per rank: 0.85 s for the 61 k rows of the
// 103 k-tet TetGen mesh on 2 ranks, 68 s for 537 k rows (999 600 tets). The copy
// here counts each block row's blocks from the row itself and inserts whole
// blocks into the preallocated pattern: O(nonzeros).
#pragma once

#include <petscmat.h>

namespace softbody {

// Collective. *blocks = a new MATBAIJ (block size 3) matrix equal to `matrix`
// (MATAIJ, any layout whose ownership ranges are whole blocks), entry for entry.
// Every nonzero of `matrix` must lie in a full 3 x 3 block whose three rows have
// the same columns (a pattern of vertex pairs, as RowAssembler::CreateMatrix
// builds); else PETSC_ERR_ARG_WRONG.
PetscErrorCode CopyToBlockMatrix(Mat matrix, Mat *blocks);

}  // namespace softbody
