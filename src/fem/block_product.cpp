#include "fem/block_product.hpp"

#include <cstring>

namespace softbody {

namespace {

// Four doubles in one vector register (GCC/Clang vector extension).
typedef double Lanes __attribute__((vector_size(4 * sizeof(double))));

inline Lanes Load(const double *p) {
  Lanes v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}

// A block's column (3 values, column-major) in lanes 0-2; lane 3 is not used.
// Reads a fourth value only where one follows inside the array.
inline Lanes Column(const double *values, bool last) {
  if (!last) return Load(values);
  return Lanes{values[0], values[1], values[2], 0.0};
}

// z = y + A x over A's block rows (y null: z = A x); A sequential BAIJ of
// block size 3. Per block row r, z_r = y_r + sum over its blocks B of
// ((B_0 x_0 + B_1 x_1) + B_2 x_2), B_c the block's column c: PETSc's order.
PetscErrorCode BlockProduct(Mat A, Vec xx, Vec yy, Vec zz) {
  PetscFunctionBeginUser;
  PetscInt rows;
  const PetscInt *ia, *ja;
  PetscBool done;
  PetscCall(MatGetRowIJ(A, 0, PETSC_FALSE, PETSC_TRUE, &rows, &ia, &ja, &done));
  PetscCheck(done, PETSC_COMM_SELF, PETSC_ERR_SUP, "no block row structure");
  PetscScalar *values;
  PetscCall(MatSeqBAIJGetArray(A, &values));
  const PetscScalar *x, *y = nullptr;
  PetscScalar *z;
  PetscCall(VecGetArrayRead(xx, &x));
  if (yy && yy != zz) PetscCall(VecGetArrayRead(yy, &y));
  PetscCall(VecGetArray(zz, &z));
  const PetscScalar *sums = yy ? (yy == zz ? z : y) : nullptr;
  const PetscInt blocks = ia[rows];
  for (PetscInt r = 0; r < rows; ++r) {
    Lanes acc = sums ? Lanes{sums[3 * r], sums[3 * r + 1], sums[3 * r + 2], 0.0}
                     : Lanes{0.0, 0.0, 0.0, 0.0};
    for (PetscInt k = ia[r]; k < ia[r + 1]; ++k) {
      const double *b = values + 9 * k;
      const double *xb = x + 3 * ja[k];
      const Lanes x0 = {xb[0], xb[0], xb[0], xb[0]}, x1 = {xb[1], xb[1], xb[1], xb[1]},
                  x2 = {xb[2], xb[2], xb[2], xb[2]};
      const Lanes t = Load(b) * x0 + Load(b + 3) * x1;
      acc = acc + (t + Column(b + 6, k + 1 == blocks) * x2);
    }
    z[3 * r] = acc[0];
    z[3 * r + 1] = acc[1];
    z[3 * r + 2] = acc[2];
  }
  PetscCall(VecRestoreArray(zz, &z));
  if (yy && yy != zz) PetscCall(VecRestoreArrayRead(yy, &y));
  PetscCall(VecRestoreArrayRead(xx, &x));
  PetscCall(MatSeqBAIJRestoreArray(A, &values));
  PetscCall(MatRestoreRowIJ(A, 0, PETSC_FALSE, PETSC_TRUE, &rows, &ia, &ja, &done));
  PetscCall(PetscLogFlops(18.0 * blocks));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode BlockMult(Mat A, Vec x, Vec z) {
  return BlockProduct(A, x, nullptr, z);
}

PetscErrorCode BlockMultAdd(Mat A, Vec x, Vec y, Vec z) {
  return BlockProduct(A, x, y, z);
}

}  // namespace

PetscErrorCode UseBlockProducts(Mat blocks) {
  PetscFunctionBeginUser;
  PetscInt block_size;
  PetscCall(MatGetBlockSize(blocks, &block_size));
  PetscBool sequential, parallel;
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(blocks), MATSEQBAIJ, &sequential));
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(blocks), MATMPIBAIJ, &parallel));
  PetscCheck(block_size == 3 && (sequential || parallel), PETSC_COMM_SELF, PETSC_ERR_ARG_WRONG,
             "block products need a BAIJ matrix of block size 3");
  if (sequential) {
    PetscCall(MatSetOperation(blocks, MATOP_MULT, reinterpret_cast<void (*)(void)>(BlockMult)));
  } else {
    Mat diagonal, off;
    PetscCall(MatMPIBAIJGetSeqBAIJ(blocks, &diagonal, &off, nullptr));
    PetscCall(MatSetOperation(diagonal, MATOP_MULT, reinterpret_cast<void (*)(void)>(BlockMult)));
    PetscCall(MatSetOperation(off, MATOP_MULT_ADD, reinterpret_cast<void (*)(void)>(BlockMultAdd)));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
