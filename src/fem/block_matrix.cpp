#include "fem/block_matrix.hpp"

#include <algorithm>
#include <vector>

namespace softbody {

namespace {

constexpr PetscInt kBlock = 3;  // DOFs per vertex

// Not collective. Whether the three rows from `row` (a multiple of 3) have the
// same columns, in full blocks; their block columns in *block_columns.
PetscErrorCode RowsInBlocks(Mat matrix, PetscInt row, std::vector<PetscInt> *block_columns,
                            bool *blocked) {
  PetscFunctionBeginUser;
  *blocked = true;
  for (PetscInt r = 0; r < kBlock; ++r) {
    PetscInt count;
    const PetscInt *columns;
    PetscCall(MatGetRow(matrix, row + r, &count, &columns, nullptr));
    if (r == 0) {
      block_columns->resize(count / kBlock);
      for (PetscInt k = 0; k < count / kBlock; ++k)
        (*block_columns)[k] = columns[kBlock * k] / kBlock;
    }
    *blocked = *blocked && count == kBlock * static_cast<PetscInt>(block_columns->size());
    for (PetscInt k = 0; *blocked && k < count; ++k)
      *blocked = columns[k] == kBlock * (*block_columns)[k / kBlock] + k % kBlock;
    PetscCall(MatRestoreRow(matrix, row + r, &count, &columns, nullptr));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. The blocks of each owned block row of `matrix` in the diagonal
// part (columns owned here) and in the off-diagonal part; fails on every rank
// when a row is not in full blocks.
PetscErrorCode CountBlocks(Mat matrix, std::vector<PetscInt> *diagonal,
                           std::vector<PetscInt> *off) {
  PetscFunctionBeginUser;
  PetscInt row_begin, row_end, column_begin, column_end;
  PetscCall(MatGetOwnershipRange(matrix, &row_begin, &row_end));
  PetscCall(MatGetOwnershipRangeColumn(matrix, &column_begin, &column_end));
  diagonal->assign((row_end - row_begin) / kBlock, 0);
  off->assign(diagonal->size(), 0);
  PetscInt first_bad = PETSC_MAX_INT;
  std::vector<PetscInt> block_columns;
  for (size_t b = 0; b < diagonal->size() && first_bad == PETSC_MAX_INT; ++b) {
    const PetscInt row = row_begin + kBlock * static_cast<PetscInt>(b);
    bool blocked;
    PetscCall(RowsInBlocks(matrix, row, &block_columns, &blocked));
    if (!blocked) first_bad = row;
    for (PetscInt column : block_columns)
      ++(kBlock * column >= column_begin && kBlock * column < column_end ? (*diagonal)[b]
                                                                         : (*off)[b]);
  }
  MPI_Comm comm;
  PetscCall(PetscObjectGetComm(reinterpret_cast<PetscObject>(matrix), &comm));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &first_bad, 1, MPIU_INT, MPI_MIN, comm));
  PetscCheck(first_bad == PETSC_MAX_INT, comm, PETSC_ERR_ARG_WRONG,
             "rows %" PetscInt_FMT " to %" PetscInt_FMT " are not in full 3 x 3 blocks", first_bad,
             first_bad + kBlock - 1);
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode CopyToBlockMatrix(Mat matrix, Mat *blocks) {
  PetscFunctionBeginUser;
  MPI_Comm comm;
  PetscCall(PetscObjectGetComm(reinterpret_cast<PetscObject>(matrix), &comm));
  PetscInt rows, columns, global_rows, global_columns, row_begin, row_end;
  PetscCall(MatGetLocalSize(matrix, &rows, &columns));
  PetscCall(MatGetSize(matrix, &global_rows, &global_columns));
  PetscCall(MatGetOwnershipRange(matrix, &row_begin, &row_end));
  int whole = row_begin % kBlock == 0 && rows % kBlock == 0 && columns % kBlock == 0;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &whole, 1, MPI_INT, MPI_LAND, comm));
  PetscCheck(whole, comm, PETSC_ERR_ARG_WRONG, "ownership ranges not in whole 3 x 3 blocks");
  std::vector<PetscInt> diagonal, off;
  PetscCall(CountBlocks(matrix, &diagonal, &off));
  PetscCall(MatCreate(comm, blocks));
  PetscCall(MatSetSizes(*blocks, rows, columns, global_rows, global_columns));
  PetscCall(MatSetType(*blocks, MATBAIJ));
  PetscCall(
      MatXAIJSetPreallocation(*blocks, kBlock, diagonal.data(), off.data(), nullptr, nullptr));
  PetscCall(MatSetOption(*blocks, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  std::vector<PetscInt> block_columns;
  std::vector<PetscScalar> values;  // the block row, row-major: its three rows one after another
  for (PetscInt row = row_begin; row < row_end; row += kBlock) {
    for (PetscInt r = 0; r < kBlock; ++r) {
      PetscInt count;
      const PetscInt *row_columns;
      const PetscScalar *row_values;
      PetscCall(MatGetRow(matrix, row + r, &count, &row_columns, &row_values));
      if (r == 0) {  // the three rows' columns are the same (CountBlocks)
        block_columns.resize(count / kBlock);
        for (PetscInt k = 0; k < count / kBlock; ++k)
          block_columns[k] = row_columns[kBlock * k] / kBlock;
        values.resize(kBlock * count);
      }
      std::copy(row_values, row_values + count, values.begin() + r * count);
      PetscCall(MatRestoreRow(matrix, row + r, &count, &row_columns, &row_values));
    }
    const PetscInt block_row = row / kBlock;
    PetscCall(MatSetValuesBlocked(*blocks, 1, &block_row,
                                  static_cast<PetscInt>(block_columns.size()), block_columns.data(),
                                  values.data(), INSERT_VALUES));
  }
  PetscCall(MatAssemblyBegin(*blocks, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(*blocks, MAT_FINAL_ASSEMBLY));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
