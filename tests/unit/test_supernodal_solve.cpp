// The supernodal factor's solves against a dense Cholesky solve (LAPACK dposv)
// of the same matrix: softbody's tiled copy of CHOLMOD's factor
// (TiledFactor, double precision) on matrices whose supernodes have whole
// panels of four columns and plain columns left over, solving out of place
// and in place; and the PC "supernodal" (one rank) in double and in single
// precision.
#include <cholmod.h>
#include <gtest/gtest.h>
#include <petscksp.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "petsc_environment.hpp"
#include "solvers/solver.hpp"
#include "solvers/supernodal/supernodal.hpp"
#include "solvers/supernodal/tiled_factor.hpp"

extern "C" void dposv_(const char *uplo, const int *n, const int *nrhs, double *a, const int *lda,
                       double *b, const int *ldb, int *info);

using namespace softbody;

namespace {

// Relative accuracy a double-precision direct solve must reach on these well
// conditioned matrices (condition numbers below 10): a few hundred ulps.
constexpr double kDoubleTolerance = 1e-12;
// The single-precision factor: float's 6e-8 times the same margin.
constexpr double kSingleTolerance = 1e-5;

// A symmetric, strictly diagonally dominant (so SPD) dense matrix with the
// pattern of an n x n x n grid of nodes with `dofs` unknowns each, every unknown
// coupled to all of its own node's and of its 6 neighbours' unknowns; random
// off-diagonal values in [-1, 1], diagonal 1 + the row's absolute sum.
std::vector<double> GridDense(int n, int dofs, unsigned seed) {
  const int size = n * n * n * dofs;
  std::vector<double> a(static_cast<size_t>(size) * size, 0.0);
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  auto node = [n](int i, int j, int k) { return i + n * (j + n * k); };
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const int neighbours[7][3] = {{i, j, k},     {i + 1, j, k}, {i, j + 1, k}, {i, j, k + 1},
                                      {i - 1, j, k}, {i, j - 1, k}, {i, j, k - 1}};
        for (const auto &q : neighbours) {
          if (q[0] < 0 || q[0] >= n || q[1] < 0 || q[1] >= n || q[2] < 0 || q[2] >= n) continue;
          const int me = node(i, j, k), other = node(q[0], q[1], q[2]);
          if (other < me) continue;  // each pair once, mirrored
          for (int a0 = 0; a0 < dofs; ++a0)
            for (int b0 = 0; b0 < dofs; ++b0) {
              const int r = me * dofs + a0, c = other * dofs + b0;
              if (r >= c) continue;
              a[static_cast<size_t>(r) * size + c] = a[static_cast<size_t>(c) * size + r] =
                  value(random);
            }
        }
      }
  for (int r = 0; r < size; ++r) {
    double sum = 0;
    for (int c = 0; c < size; ++c) sum += std::fabs(a[static_cast<size_t>(r) * size + c]);
    a[static_cast<size_t>(r) * size + r] = 1.0 + sum;
  }
  return a;
}

// x = A^-1 b by LAPACK's dense Cholesky.
std::vector<double> DenseSolve(std::vector<double> a, std::vector<double> b) {
  const int n = static_cast<int>(b.size()), one = 1;
  int info = 0;
  dposv_("L", &n, &one, a.data(), &n, b.data(), &n, &info);
  EXPECT_EQ(info, 0);
  return b;
}

double RelativeDifference(const std::vector<double> &x, const std::vector<double> &reference) {
  double difference = 0, largest = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    difference = std::max(difference, std::fabs(x[i] - reference[i]));
    largest = std::max(largest, std::fabs(reference[i]));
  }
  return difference / largest;
}

std::vector<double> RandomVector(int n, unsigned seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  std::vector<double> b(n);
  for (double &v : b) v = value(random);
  return b;
}

// CHOLMOD's supernodal factor of the dense SPD matrix a (its lower triangle).
cholmod_factor *CholmodFactor(const std::vector<double> &a, int n, cholmod_common *common) {
  cholmod_dense dense;
  std::fill(reinterpret_cast<char *>(&dense), reinterpret_cast<char *>(&dense + 1), 0);
  dense.nrow = dense.ncol = dense.d = n;
  dense.nzmax = static_cast<size_t>(n) * n;
  dense.x = const_cast<double *>(a.data());
  dense.xtype = CHOLMOD_REAL;
  dense.dtype = CHOLMOD_DOUBLE;
  cholmod_sparse *sparse = cholmod_dense_to_sparse(&dense, 1, common);
  sparse->stype = -1;
  cholmod_factor *L = cholmod_analyze(sparse, common);
  EXPECT_TRUE(cholmod_factorize(sparse, L, common));
  EXPECT_EQ(common->status, CHOLMOD_OK);
  cholmod_free_sparse(&sparse, common);
  return L;
}

}  // namespace

TEST(TiledFactor, SolvesLikeDenseCholesky) {
  struct Case {
    int grid, dofs;
  };
  for (const Case c : {Case{9, 1}, Case{6, 3}, Case{5, 2}}) {
    const int n = c.grid * c.grid * c.grid * c.dofs;
    const std::vector<double> a = GridDense(c.grid, c.dofs, 7u + c.dofs);
    cholmod_common common;
    cholmod_start(&common);
    common.supernodal = CHOLMOD_SUPERNODAL;
    cholmod_factor *L = CholmodFactor(a, n, &common);
    ASSERT_TRUE(L->is_super);
    // Coverage: supernodes with whole panels and with plain columns left over.
    const int *super = static_cast<const int *>(L->super);
    int panels = 0, plain = 0;
    for (size_t k = 0; k < L->nsuper; ++k) {
      panels += (super[k + 1] - super[k]) / TiledFactor::kPanel;
      plain += (super[k + 1] - super[k]) % TiledFactor::kPanel;
    }
    EXPECT_GT(panels, 0);
    EXPECT_GT(plain, 0);
    TiledFactor tiled;
    tiled.From(L);
    EXPECT_EQ(tiled.size(), n);
    const std::vector<double> b = RandomVector(n, 11u);
    const std::vector<double> reference = DenseSolve(a, b);
    std::vector<double> x(n, 0.0);
    tiled.Solve(b.data(), x.data());
    EXPECT_LT(RelativeDifference(x, reference), kDoubleTolerance) << c.grid << " " << c.dofs;
    std::vector<double> in_place = b;
    tiled.Solve(in_place.data(), in_place.data());
    EXPECT_EQ(in_place, x);
    cholmod_free_factor(&L, &common);
    cholmod_finish(&common);
  }
}

TEST(SupernodalPC, OneRankSolvesLikeDenseCholesky) {
  const int grid = 6, dofs = 3, n = grid * grid * grid * dofs;
  const std::vector<double> a = GridDense(grid, dofs, 3u);
  Mat A;
  ASSERT_EQ(MatCreateSeqAIJ(PETSC_COMM_SELF, n, n, 7 * dofs, nullptr, &A), PETSC_SUCCESS);
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < n; ++c)
      if (a[static_cast<size_t>(r) * n + c] != 0.0)
        ASSERT_EQ(MatSetValue(A, r, c, a[static_cast<size_t>(r) * n + c], INSERT_VALUES),
                  PETSC_SUCCESS);
  ASSERT_EQ(MatAssemblyBegin(A, MAT_FINAL_ASSEMBLY), PETSC_SUCCESS);
  ASSERT_EQ(MatAssemblyEnd(A, MAT_FINAL_ASSEMBLY), PETSC_SUCCESS);
  const std::vector<double> b = RandomVector(n, 5u);
  const std::vector<double> reference = DenseSolve(a, b);
  ASSERT_EQ(RegisterPreconditioners(), PETSC_SUCCESS);
  for (const bool single : {false, true}) {
    KSP ksp;
    PC pc;
    ASSERT_EQ(KSPCreate(PETSC_COMM_SELF, &ksp), PETSC_SUCCESS);
    ASSERT_EQ(KSPSetOperators(ksp, A, A), PETSC_SUCCESS);
    ASSERT_EQ(KSPSetType(ksp, KSPPREONLY), PETSC_SUCCESS);
    ASSERT_EQ(KSPGetPC(ksp, &pc), PETSC_SUCCESS);
    ASSERT_EQ(PCSetType(pc, kPCSupernodal), PETSC_SUCCESS);
    ASSERT_EQ(PCSupernodalSetSinglePrecision(pc, single), PETSC_SUCCESS);
    Vec bv, xv;
    ASSERT_EQ(MatCreateVecs(A, &xv, &bv), PETSC_SUCCESS);
    double *values;
    ASSERT_EQ(VecGetArrayWrite(bv, &values), PETSC_SUCCESS);
    std::copy(b.begin(), b.end(), values);
    ASSERT_EQ(VecRestoreArrayWrite(bv, &values), PETSC_SUCCESS);
    ASSERT_EQ(KSPSolve(ksp, bv, xv), PETSC_SUCCESS);
    const double *solution;
    ASSERT_EQ(VecGetArrayRead(xv, &solution), PETSC_SUCCESS);
    const std::vector<double> x(solution, solution + n);
    ASSERT_EQ(VecRestoreArrayRead(xv, &solution), PETSC_SUCCESS);
    EXPECT_LT(RelativeDifference(x, reference), single ? kSingleTolerance : kDoubleTolerance)
        << (single ? "single" : "double");
    VecDestroy(&bv);
    VecDestroy(&xv);
    KSPDestroy(&ksp);
  }
  MatDestroy(&A);
}
