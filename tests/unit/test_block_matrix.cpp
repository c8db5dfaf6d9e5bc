// CopyToBlockMatrix (block_matrix.hpp): the MATBAIJ copy of the row assembler's
// stiffness equals PETSc's own MatConvert to MATBAIJ (MatEqual: same pattern,
// same values) and multiplies as the MATAIJ original does, on any number of
// ranks; a matrix with an entry outside full 3 x 3 blocks fails on every rank
// with PETSC_ERR_ARG_WRONG.
// Runs on ranks: 1 3 4
#include <gtest/gtest.h>
#include <petscmat.h>

#include "box_stiffness.hpp"
#include "fem/block_matrix.hpp"
#include "petsc_environment.hpp"

using namespace softbody;

namespace {

// The stiffness K of a 5 x 4 x 3-cell box (row assembler, MATAIJ, block size 3).
struct Stiffness : BoxStiffness {
  Stiffness() : BoxStiffness(5, 4, 3) {}
};

}  // namespace

TEST(CopyToBlockMatrix, EqualsPetscConversion) {
  Stiffness s;
  Mat copy, converted;
  ASSERT_EQ(CopyToBlockMatrix(s.K, &copy), 0);
  ASSERT_EQ(MatConvert(s.K, MATBAIJ, MAT_INITIAL_MATRIX, &converted), 0);
  MatType type;
  MatGetType(copy, &type);
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  EXPECT_STREQ(type, size == 1 ? MATSEQBAIJ : MATMPIBAIJ);
  PetscInt block_size;
  MatGetBlockSize(copy, &block_size);
  EXPECT_EQ(block_size, 3);
  PetscBool equal;
  MatEqual(copy, converted, &equal);
  EXPECT_TRUE(equal);
  // Products: against the MATAIJ original, to round-off (the sums' order differs).
  Vec x, y, z;
  MatCreateVecs(s.K, &x, &y);
  VecDuplicate(y, &z);
  VecCopy(s.state.rest_positions, x);
  VecShift(x, 0.37);
  MatMult(s.K, x, y);
  MatMult(copy, x, z);
  PetscReal scale, difference;
  VecNorm(y, NORM_2, &scale);
  VecAXPY(z, -1.0, y);
  VecNorm(z, NORM_2, &difference);
  EXPECT_GT(scale, 0.0);
  EXPECT_LT(difference, 1e-13 * scale);
  VecDestroy(&x);
  VecDestroy(&y);
  VecDestroy(&z);
  MatDestroy(&copy);
  MatDestroy(&converted);
}

// One entry added outside the blocks, on the last rank only: every rank fails.
TEST(CopyToBlockMatrix, EntryOutsideBlocksFailsEverywhere) {
  Stiffness s;
  PetscInt begin, end, columns;
  MatGetOwnershipRange(s.K, &begin, &end);
  MatGetSize(s.K, nullptr, &columns);
  Mat broken;
  MatCreate(PETSC_COMM_WORLD, &broken);
  PetscInt rows, local_columns;
  MatGetLocalSize(s.K, &rows, &local_columns);
  MatSetSizes(broken, rows, local_columns, PETSC_DETERMINE, PETSC_DETERMINE);
  MatSetType(broken, MATAIJ);
  MatSetUp(broken);
  MatSetOption(broken, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_FALSE);
  for (PetscInt row = begin; row < end; ++row) {  // a copy of K ...
    PetscInt count;
    const PetscInt *cols;
    const PetscScalar *values;
    MatGetRow(s.K, row, &count, &cols, &values);
    MatSetValues(broken, 1, &row, count, cols, values, INSERT_VALUES);
    MatRestoreRow(s.K, row, &count, &cols, &values);
  }
  PetscMPIInt rank, size;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  if (rank == size - 1) {  // ... with one entry of a block whose other entries are missing
    const PetscInt row = end - 1, column = (row + 3 * 7) % columns;
    PetscBool present = PETSC_FALSE;
    PetscInt count;
    const PetscInt *cols;
    MatGetRow(s.K, row, &count, &cols, nullptr);
    for (PetscInt k = 0; k < count; ++k) present = PetscBool(present || cols[k] / 3 == column / 3);
    MatRestoreRow(s.K, row, &count, &cols, nullptr);
    ASSERT_FALSE(present) << "pick another column for the test";
    const PetscScalar one = 1.0;
    MatSetValues(broken, 1, &row, 1, &column, &one, INSERT_VALUES);
  }
  MatAssemblyBegin(broken, MAT_FINAL_ASSEMBLY);
  MatAssemblyEnd(broken, MAT_FINAL_ASSEMBLY);
  Mat copy = nullptr;
  PetscPushErrorHandler(PetscReturnErrorHandler, nullptr);
  const PetscErrorCode error = CopyToBlockMatrix(broken, &copy);
  PetscPopErrorHandler();
  EXPECT_EQ(error, PETSC_ERR_ARG_WRONG);
  MatDestroy(&broken);
}
