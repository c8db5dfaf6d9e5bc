// UseBlockProducts (block_product.hpp): products with K in 3 x 3 blocks equal
// PETSc's own MatMult_SeqBAIJ_3 / MatMult_MPIBAIJ bit for bit (the kernels keep
// its order and roundings), on 1, 3 and 4 ranks, where the parallel product
// also adds the off-diagonal part; and the time of both on a ~100 k-tet box
// (printed, best of several interleaved runs; not asserted: the machine may be
// shared).
// Runs on ranks: 1 3 4
#include <gtest/gtest.h>
#include <petscmat.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>

#include "box_stiffness.hpp"
#include "fem/block_matrix.hpp"
#include "fem/block_product.hpp"
#include "petsc_environment.hpp"
#include "vec_equal.hpp"

using namespace softbody;

namespace {

// K of an nx x ny x nz-cell box, in blocks, twice: petsc with PETSc's kernels,
// ours with UseBlockProducts; x a vector to multiply.
struct Products : BoxStiffness {
  Mat petsc = nullptr, ours = nullptr;
  Vec x = nullptr;

  Products(int nx, int ny, int nz) : BoxStiffness(nx, ny, nz) {
    CopyToBlockMatrix(K, &petsc);
    CopyToBlockMatrix(K, &ours);
    UseBlockProducts(ours);
    PetscMPIInt rank;
    MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
    // Displacements of all sizes and signs, as the products see them.
    VecDuplicate(state.rest_positions, &x);
    PetscInt begin, end;
    VecGetOwnershipRange(x, &begin, &end);
    std::mt19937 rng(7 + rank);
    std::uniform_real_distribution<double> uniform(-1.0, 1.0);
    for (PetscInt i = begin; i < end; ++i)
      VecSetValue(x, i, uniform(rng) * std::pow(10.0, 6 * uniform(rng)), INSERT_VALUES);
    VecAssemblyBegin(x);
    VecAssemblyEnd(x);
  }
  ~Products() {
    MatDestroy(&petsc);
    MatDestroy(&ours);
    VecDestroy(&x);
  }
};

double BestSeconds(Mat K, Vec x, Vec y, int repeats) {
  double best = 1e30;
  for (int r = 0; r < repeats; ++r) {
    MPI_Barrier(PETSC_COMM_WORLD);
    const auto start = std::chrono::steady_clock::now();
    MatMult(K, x, y);
    best = std::min(
        best, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  return best;
}

}  // namespace

TEST(BlockProducts, EqualPetscBitForBit) {
  Products p(6, 5, 4);
  Vec y, z;
  VecDuplicate(p.x, &y);
  VecDuplicate(p.x, &z);
  ASSERT_EQ(MatMult(p.petsc, p.x, y), 0);
  ASSERT_EQ(MatMult(p.ours, p.x, z), 0);
  PetscReal norm;
  VecNorm(y, NORM_2, &norm);
  EXPECT_GT(norm, 0.0);
  EXPECT_TRUE(BitwiseEqual(y, z));
  VecDestroy(&y);
  VecDestroy(&z);
}

TEST(BlockProducts, Speed) {
  Products p(40, 20, 21);
  Vec y, z;
  VecDuplicate(p.x, &y);
  VecDuplicate(p.x, &z);
  double petsc = 1e30, ours = 1e30;
  for (int round = 0; round < 5; ++round) {  // interleaved
    petsc = std::min(petsc, BestSeconds(p.petsc, p.x, y, 5));
    ours = std::min(ours, BestSeconds(p.ours, p.x, z, 5));
  }
  EXPECT_TRUE(BitwiseEqual(y, z));
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  PetscPrintf(PETSC_COMM_WORLD,
              "product with K of %lld tets on %d rank(s): PETSc %.3f ms, block products %.3f ms "
              "(best of 25 each)\n",
              (long long)p.scene.num_tets(), size, 1e3 * petsc, 1e3 * ours);
  VecDestroy(&y);
  VecDestroy(&z);
}
