#include "fem/matrix_pages.hpp"

#include <sys/mman.h>

#include <cstddef>
#include <cstdint>

namespace softbody {

namespace {

// Linux's MADV_COLLAPSE (6.1), which glibc 2.36's headers do not define yet.
constexpr int kAdviseCollapse = 25;
constexpr uintptr_t kHugePage = uintptr_t{2} << 20;

// The hints for the whole huge pages inside [begin, begin + bytes).
void AdviseHugePages(const void *begin, size_t bytes) {
  const uintptr_t start = reinterpret_cast<uintptr_t>(begin);
  const uintptr_t first = (start + kHugePage - 1) / kHugePage * kHugePage;
  const uintptr_t last = (start + bytes) / kHugePage * kHugePage;
  if (last <= first) return;
  void *range = reinterpret_cast<void *>(first);
  if (madvise(range, last - first, MADV_HUGEPAGE) == 0)
    madvise(range, last - first, kAdviseCollapse);  // a refusal keeps the 4 KB pages
}

// One sequential part: its values (nonzeros x entries per nonzero) and its
// column indices (one per nonzero, or per block for BAIJ).
PetscErrorCode MovePart(Mat part, bool blocked) {
  PetscFunctionBeginUser;
  PetscInt rows;
  const PetscInt *ia, *ja;
  PetscBool done;
  PetscCall(MatGetRowIJ(part, 0, PETSC_FALSE, blocked ? PETSC_TRUE : PETSC_FALSE, &rows, &ia, &ja,
                        &done));
  if (!done) PetscFunctionReturn(PETSC_SUCCESS);
  PetscInt block = 1;
  if (blocked) PetscCall(MatGetBlockSize(part, &block));
  const size_t entries = static_cast<size_t>(ia[rows]);
  PetscScalar *values;
  if (blocked)
    PetscCall(MatSeqBAIJGetArray(part, &values));
  else
    PetscCall(MatSeqAIJGetArray(part, &values));
  AdviseHugePages(values, entries * block * block * sizeof(PetscScalar));
  AdviseHugePages(ja, entries * sizeof(PetscInt));
  if (blocked)
    PetscCall(MatSeqBAIJRestoreArray(part, &values));
  else
    PetscCall(MatSeqAIJRestoreArray(part, &values));
  PetscCall(MatRestoreRowIJ(part, 0, PETSC_FALSE, blocked ? PETSC_TRUE : PETSC_FALSE, &rows, &ia,
                            &ja, &done));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode MoveMatrixToHugePages(Mat matrix) {
  PetscFunctionBeginUser;
  PetscBool seq_aij, mpi_aij, seq_baij, mpi_baij;
  PetscCall(PetscObjectBaseTypeCompare((PetscObject)matrix, MATSEQAIJ, &seq_aij));
  PetscCall(PetscObjectBaseTypeCompare((PetscObject)matrix, MATMPIAIJ, &mpi_aij));
  PetscCall(PetscObjectTypeCompare((PetscObject)matrix, MATSEQBAIJ, &seq_baij));
  PetscCall(PetscObjectTypeCompare((PetscObject)matrix, MATMPIBAIJ, &mpi_baij));
  if (seq_aij || seq_baij) PetscCall(MovePart(matrix, seq_baij));
  if (mpi_aij || mpi_baij) {
    Mat diagonal, off;
    if (mpi_aij)
      PetscCall(MatMPIAIJGetSeqAIJ(matrix, &diagonal, &off, nullptr));
    else
      PetscCall(MatMPIBAIJGetSeqBAIJ(matrix, &diagonal, &off, nullptr));
    PetscCall(MovePart(diagonal, mpi_baij));
    PetscCall(MovePart(off, mpi_baij));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
