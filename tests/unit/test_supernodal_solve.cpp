// The supernodal factor's solves against a dense Cholesky solve (LAPACK dposv)
// of the same matrix: softbody's tiled copy of CHOLMOD's factor
// (TiledFactor, in double and in single precision) on matrices whose supernodes have whole
// panels of four columns and plain columns left over, solving out of place
// and in place, and its sweeps stopped at a column inside a supernode (as the
// split factor's interior); and the PC "supernodal" in double and in single
// precision, on one rank and split on two.
// Runs on ranks: 1 2
#include <cholmod.h>
#include <gtest/gtest.h>
#include <petscksp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <type_traits>
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
    if (!std::isfinite(x[i])) return std::numeric_limits<double>::infinity();
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

// The tiled factor in each precision, with the accuracy its solves must reach.
template <typename Real>
class TiledFactorTest : public ::testing::Test {
 protected:
  using Factor = TiledFactor<Real>;
  static constexpr double kTolerance =
      std::is_same_v<Real, double> ? kDoubleTolerance : kSingleTolerance;
};
using Precisions = ::testing::Types<double, float>;
TYPED_TEST_SUITE(TiledFactorTest, Precisions);

}  // namespace

TYPED_TEST(TiledFactorTest, SolvesLikeDenseCholesky) {
  using Factor = typename TestFixture::Factor;
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
      panels += (super[k + 1] - super[k]) / Factor::kPanel;
      plain += (super[k + 1] - super[k]) % Factor::kPanel;
    }
    EXPECT_GT(panels, 0);
    EXPECT_GT(plain, 0);
    Factor tiled;
    tiled.From(L);
    EXPECT_EQ(tiled.size(), n);
    const std::vector<double> b = RandomVector(n, 11u);
    const std::vector<double> reference = DenseSolve(a, b);
    std::vector<double> x(n, 0.0);
    tiled.Solve(b.data(), x.data());
    EXPECT_LT(RelativeDifference(x, reference), TestFixture::kTolerance) << c.grid << " " << c.dofs;
    std::vector<double> in_place = b;
    tiled.Solve(in_place.data(), in_place.data());
    EXPECT_EQ(in_place, x);
    cholmod_free_factor(&L, &common);
    cholmod_finish(&common);
  }
}

// SolveColumns: seven columns (a group of four and one of three) in a matrix
// with a leading dimension larger than n; each equals Solve's result to
// round-off (the sums of the dot products run in another order) and is the
// same bits whichever group and lane it went through; rows beyond n are untouched.
TYPED_TEST(TiledFactorTest, ColumnsFourAtATimeEqualSingleSolves) {
  using Factor = typename TestFixture::Factor;
  const int grid = 6, dofs = 3, n = grid * grid * grid * dofs, count = 7, ld = n + 5;
  const double kRoundOff = std::is_same_v<TypeParam, double> ? 1e-13 : TestFixture::kTolerance;
  const std::vector<double> a = GridDense(grid, dofs, 13u);
  cholmod_common common;
  cholmod_start(&common);
  common.supernodal = CHOLMOD_SUPERNODAL;
  cholmod_factor *L = CholmodFactor(a, n, &common);
  Factor tiled;
  tiled.From(L);
  std::vector<double> b(static_cast<size_t>(ld) * count, 0.0);
  for (int j = 0; j < count; ++j) {
    const std::vector<double> column = RandomVector(n, 20u + j);
    std::copy(column.begin(), column.end(), b.begin() + static_cast<size_t>(j) * ld);
  }
  constexpr double kUntouched = -7.25;
  std::vector<double> x(b.size(), kUntouched);
  tiled.SolveColumns(count, b.data(), ld, x.data(), ld);
  for (int j = 0; j < count; ++j) {
    std::vector<double> single(n);
    tiled.Solve(b.data() + static_cast<size_t>(j) * ld, single.data());
    const std::vector<double> column(x.begin() + static_cast<size_t>(j) * ld,
                                     x.begin() + static_cast<size_t>(j) * ld + n);
    EXPECT_LT(RelativeDifference(column, single), kRoundOff) << "column " << j;
    for (int i = n; i < ld; ++i) EXPECT_EQ(x[static_cast<size_t>(j) * ld + i], kUntouched);
  }
  // The same column in another lane of another group: the same bits.
  std::vector<double> one(x.begin() + 5 * static_cast<size_t>(ld),
                          x.begin() + 5 * static_cast<size_t>(ld) + n);
  std::vector<double> again(n);
  tiled.SolveColumns(1, b.data() + 5 * static_cast<size_t>(ld), ld, again.data(), n);
  EXPECT_EQ(again, one);
  cholmod_free_factor(&L, &common);
  cholmod_finish(&common);
}

// Sparse right-hand sides (one node's unknowns each, as a contact row's J^T):
// the forward sweep skips the supernodes still zero, and the solution is
// LAPACK's to the precision's accuracy; with SetSolveTargets on some rows, the
// backward sweep visits only their supernodes' paths, and those rows are the
// unrestricted solve's bits; an empty target list restores full solves.
TYPED_TEST(TiledFactorTest, SparseColumnsAndTargetRows) {
  using Factor = typename TestFixture::Factor;
  const int grid = 7, dofs = 3, n = grid * grid * grid * dofs, count = 6;
  const std::vector<double> a = GridDense(grid, dofs, 29u);
  cholmod_common common;
  cholmod_start(&common);
  common.supernodal = CHOLMOD_SUPERNODAL;
  cholmod_factor *L = CholmodFactor(a, n, &common);
  Factor tiled;
  tiled.From(L);
  const int nodes[count] = {0, 17, 100, 171, 250, 342};  // spread over the grid
  std::vector<double> b(static_cast<size_t>(n) * count, 0.0);
  std::vector<int> targets;
  for (int j = 0; j < count; ++j)
    for (int d = 0; d < dofs; ++d) {
      b[static_cast<size_t>(j) * n + nodes[j] * dofs + d] = 1.0 + d;
      targets.push_back(nodes[j] * dofs + d);
    }
  std::vector<double> full(b.size()), restricted(b.size(), 0.0), again(b.size());
  tiled.SolveColumns(count, b.data(), n, full.data(), n);
  for (int j = 0; j < count; ++j) {
    const std::vector<double> column(b.begin() + static_cast<size_t>(j) * n,
                                     b.begin() + static_cast<size_t>(j + 1) * n);
    const std::vector<double> x(full.begin() + static_cast<size_t>(j) * n,
                                full.begin() + static_cast<size_t>(j + 1) * n);
    EXPECT_LT(RelativeDifference(x, DenseSolve(a, column)), TestFixture::kTolerance)
        << "column " << j;
  }
  tiled.SetSolveTargets(targets);
  tiled.SolveColumns(count, b.data(), n, restricted.data(), n);
  for (int j = 0; j < count; ++j)
    for (const int row : targets)
      EXPECT_EQ(restricted[static_cast<size_t>(j) * n + row],
                full[static_cast<size_t>(j) * n + row])
          << "column " << j << ", row " << row;
  tiled.SetSolveTargets({});
  tiled.SolveColumns(count, b.data(), n, again.data(), n);
  EXPECT_EQ(again, full);
  cholmod_free_factor(&L, &common);
  cholmod_finish(&common);
}

TYPED_TEST(TiledFactorTest, SweepsStoppedInsideASupernode) {
  using Factor = typename TestFixture::Factor;
  const int grid = 6, dofs = 3, n = grid * grid * grid * dofs;
  const std::vector<double> a = GridDense(grid, dofs, 17u);
  cholmod_common common;
  cholmod_start(&common);
  common.supernodal = CHOLMOD_SUPERNODAL;
  cholmod_factor *L = CholmodFactor(a, n, &common);
  // The limit: inside the widest supernode, past one whole panel and inside the next.
  const int *super = static_cast<const int *>(L->super);
  size_t widest = 0;
  for (size_t k = 0; k < L->nsuper; ++k)
    if (super[k + 1] - super[k] > super[widest + 1] - super[widest]) widest = k;
  ASSERT_GE(super[widest + 1] - super[widest], 2 * Factor::kPanel);
  const int limit = super[widest] + Factor::kPanel + 2;
  Factor whole, cut;
  whole.From(L);
  cut.From(L, limit);
  EXPECT_EQ(cut.EntriesBefore(n), whole.EntriesBefore(n));
  const std::vector<double> b = RandomVector(n, 23u);
  std::vector<double> x(n);
  whole.Solve(b.data(), x.data());
  // Forward over the columns before the limit, then the rows from the limit on
  // set to the solution's: the backward sweep must give the solution's others.
  auto *y = cut.y();
  const int *permutation = cut.permutation();
  for (int i = 0; i < n; ++i) y[i] = static_cast<TypeParam>(b[permutation[i]]);
  cut.Forward(limit);
  for (int i = limit; i < n; ++i) y[i] = static_cast<TypeParam>(x[permutation[i]]);
  cut.Backward(limit);
  std::vector<double> interior(limit), reference(limit);
  for (int i = 0; i < limit; ++i) {
    interior[i] = y[i];
    reference[i] = x[permutation[i]];
  }
  EXPECT_LT(RelativeDifference(interior, reference), TestFixture::kTolerance);
  // The whole solve through both pieces of the cut supernode.
  std::vector<double> through_cut(n);
  cut.Solve(b.data(), through_cut.data());
  EXPECT_LT(RelativeDifference(through_cut, x), TestFixture::kTolerance);
  cholmod_free_factor(&L, &common);
  cholmod_finish(&common);
}

TEST(SupernodalPC, SolvesLikeDenseCholeskyOnOneRankAndSplit) {
  const int grid = 6, dofs = 3, n = grid * grid * grid * dofs;
  const std::vector<double> a = GridDense(grid, dofs, 5u);
  const std::vector<double> b = RandomVector(n, 9u);
  const std::vector<double> reference = DenseSolve(a, b);
  Mat A;
  ASSERT_EQ(MatCreateAIJ(PETSC_COMM_WORLD, PETSC_DECIDE, PETSC_DECIDE, n, n, 7 * dofs, nullptr,
                         7 * dofs, nullptr, &A),
            PETSC_SUCCESS);
  PetscInt begin, end;
  ASSERT_EQ(MatGetOwnershipRange(A, &begin, &end), PETSC_SUCCESS);
  for (PetscInt r = begin; r < end; ++r)
    for (int c = 0; c < n; ++c)
      if (a[static_cast<size_t>(r) * n + c] != 0.0)
        ASSERT_EQ(MatSetValue(A, r, c, a[static_cast<size_t>(r) * n + c], INSERT_VALUES),
                  PETSC_SUCCESS);
  ASSERT_EQ(MatAssemblyBegin(A, MAT_FINAL_ASSEMBLY), PETSC_SUCCESS);
  ASSERT_EQ(MatAssemblyEnd(A, MAT_FINAL_ASSEMBLY), PETSC_SUCCESS);
  ASSERT_EQ(RegisterPreconditioners(), PETSC_SUCCESS);
  for (const bool single : {false, true}) {
    KSP ksp;
    PC pc;
    ASSERT_EQ(KSPCreate(PETSC_COMM_WORLD, &ksp), PETSC_SUCCESS);
    ASSERT_EQ(KSPSetOperators(ksp, A, A), PETSC_SUCCESS);
    ASSERT_EQ(KSPSetType(ksp, KSPPREONLY), PETSC_SUCCESS);
    ASSERT_EQ(KSPGetPC(ksp, &pc), PETSC_SUCCESS);
    ASSERT_EQ(PCSetType(pc, kPCSupernodal), PETSC_SUCCESS);
    ASSERT_EQ(PCSupernodalSetSinglePrecision(pc, single), PETSC_SUCCESS);
    ASSERT_EQ(KSPSetFromOptions(ksp), PETSC_SUCCESS);
    SupernodalPrediction prediction;
    ASSERT_EQ(PCSupernodalPredict(pc, &prediction), PETSC_SUCCESS);
    EXPECT_EQ(prediction.separator > 0, Size() > 1);  // split on several ranks
    Vec bv, xv, all;
    VecScatter gather;
    ASSERT_EQ(MatCreateVecs(A, &xv, &bv), PETSC_SUCCESS);
    for (PetscInt r = begin; r < end; ++r)
      ASSERT_EQ(VecSetValue(bv, r, b[r], INSERT_VALUES), PETSC_SUCCESS);
    ASSERT_EQ(VecAssemblyBegin(bv), PETSC_SUCCESS);
    ASSERT_EQ(VecAssemblyEnd(bv), PETSC_SUCCESS);
    ASSERT_EQ(KSPSolve(ksp, bv, xv), PETSC_SUCCESS);
    ASSERT_EQ(VecScatterCreateToAll(xv, &gather, &all), PETSC_SUCCESS);
    ASSERT_EQ(VecScatterBegin(gather, xv, all, INSERT_VALUES, SCATTER_FORWARD), PETSC_SUCCESS);
    ASSERT_EQ(VecScatterEnd(gather, xv, all, INSERT_VALUES, SCATTER_FORWARD), PETSC_SUCCESS);
    const double *solution;
    ASSERT_EQ(VecGetArrayRead(all, &solution), PETSC_SUCCESS);
    const std::vector<double> x(solution, solution + n);
    ASSERT_EQ(VecRestoreArrayRead(all, &solution), PETSC_SUCCESS);
    EXPECT_LT(RelativeDifference(x, reference), single ? kSingleTolerance : kDoubleTolerance)
        << (single ? "single" : "double") << " on " << Size() << " rank(s)";
    VecScatterDestroy(&gather);
    VecDestroy(&all);
    VecDestroy(&bv);
    VecDestroy(&xv);
    KSPDestroy(&ksp);
  }
  MatDestroy(&A);
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
