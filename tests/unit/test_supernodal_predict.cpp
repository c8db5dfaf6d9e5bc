// The supernodal factor's size predictor (PCSupernodalPredict) against the
// factor the set-up then builds, on one rank, and the choice between that
// factor and multigrid (ChooseFactorOrMultigrid) at a budget below and above
// the prediction; the separator's dense blocks in 64-bit arithmetic past the
// size whose square overflows an int (n_S = 46 341).
#include <gtest/gtest.h>
#include <petscksp.h>

#include <string>

#include "petsc_environment.hpp"
#include "solvers/solver.hpp"
#include "solvers/supernodal/supernodal.hpp"

using namespace softbody;

namespace {

// A symmetric, strictly diagonally dominant (so SPD) matrix with block size 3
// and the pattern of a 3D mesh: every component of a node of an n x n x n grid
// coupled to every component of itself and of its 6 neighbours; diagonal 19
// against at most 1 + 6 x 1.5 = 10 off it.
PetscErrorCode GridMatrix(PetscInt n, Mat *A) {
  PetscFunctionBeginUser;
  const PetscInt nodes = n * n * n;
  PetscCall(MatCreateSeqAIJ(PETSC_COMM_SELF, 3 * nodes, 3 * nodes, 3 * 7, nullptr, A));
  PetscCall(MatSetBlockSize(*A, 3));
  auto node = [n](PetscInt i, PetscInt j, PetscInt k) { return i + n * (j + n * k); };
  for (PetscInt k = 0; k < n; ++k)
    for (PetscInt j = 0; j < n; ++j)
      for (PetscInt i = 0; i < n; ++i) {
        const PetscInt me = node(i, j, k);
        const PetscInt neighbours[6][3] = {{i - 1, j, k}, {i + 1, j, k}, {i, j - 1, k},
                                           {i, j + 1, k}, {i, j, k - 1}, {i, j, k + 1}};
        for (PetscInt a = 0; a < 3; ++a) {
          PetscCall(MatSetValue(*A, 3 * me + a, 3 * me + a, 19.0, INSERT_VALUES));
          for (PetscInt b = 0; b < 3; ++b)
            if (a != b) PetscCall(MatSetValue(*A, 3 * me + a, 3 * me + b, 0.5, INSERT_VALUES));
          for (const auto &q : neighbours) {
            if (q[0] < 0 || q[0] >= n || q[1] < 0 || q[1] >= n || q[2] < 0 || q[2] >= n) continue;
            const PetscInt other = node(q[0], q[1], q[2]);
            for (PetscInt b = 0; b < 3; ++b)
              PetscCall(
                  MatSetValue(*A, 3 * me + a, 3 * other + b, a == b ? -1.0 : -0.25, INSERT_VALUES));
          }
        }
      }
  PetscCall(MatAssemblyBegin(*A, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(*A, MAT_FINAL_ASSEMBLY));
  PetscCall(MatSetOption(*A, MAT_SPD, PETSC_TRUE));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// A preonly KSP with a supernodal PC on A, options read (with `budget_mb`).
PetscErrorCode SupernodalSolver(Mat A, const char *budget_mb, KSP *ksp) {
  PetscFunctionBeginUser;
  PetscCall(RegisterPreconditioners());
  PetscCall(PetscOptionsClearValue(nullptr, "-ksp_type"));
  PetscCall(PetscOptionsClearValue(nullptr, "-pc_type"));
  PetscCall(PetscOptionsSetValue(nullptr, "-pc_supernodal_budget_mb", budget_mb));
  PetscCall(KSPCreate(PETSC_COMM_SELF, ksp));
  PetscCall(KSPSetOperators(*ksp, A, A));
  PetscCall(KSPSetType(*ksp, KSPPREONLY));
  PC pc;
  PetscCall(KSPGetPC(*ksp, &pc));
  PetscCall(PCSetType(pc, kPCSupernodal));
  PetscCall(KSPSetFromOptions(*ksp));
  PetscFunctionReturn(PETSC_SUCCESS);
}

TEST(SupernodalPredict, FactorEntriesEqualTheSetUp) {
  Mat A;
  ASSERT_EQ(GridMatrix(12, &A), PETSC_SUCCESS);
  for (const char *precision : {"double", "single"}) {
    ASSERT_EQ(PetscOptionsSetValue(nullptr, "-pc_supernodal_precision", precision), PETSC_SUCCESS);
    KSP ksp;
    ASSERT_EQ(SupernodalSolver(A, "1e6", &ksp), PETSC_SUCCESS);
    PC pc;
    ASSERT_EQ(KSPGetPC(ksp, &pc), PETSC_SUCCESS);
    SupernodalPrediction prediction;
    ASSERT_EQ(PCSupernodalPredict(pc, &prediction), PETSC_SUCCESS);
    EXPECT_TRUE(prediction.analysed && prediction.affordable);
    EXPECT_EQ(prediction.separator, 0);  // one rank: no split
    ASSERT_EQ(PCSetUp(pc), PETSC_SUCCESS);
    double stored, nonzeros, flops;
    int bytes_per_entry;
    ASSERT_EQ(PCSupernodalGetFactorSize(pc, &stored, &nonzeros, &flops, &bytes_per_entry),
              PETSC_SUCCESS);
    EXPECT_GT(stored, 3 * 12 * 12 * 12);
    EXPECT_EQ(prediction.factor_entries, stored) << precision;
    // CHOLMOD's factor in double and its copy for the solves at 8 or 4 bytes.
    EXPECT_DOUBLE_EQ(prediction.bytes, stored * (8 + bytes_per_entry)) << precision;
    KSPDestroy(&ksp);
  }
  PetscOptionsClearValue(nullptr, "-pc_supernodal_precision");
  MatDestroy(&A);
}

TEST(SolverChoice, BudgetBelowThePredictionChoosesMultigrid) {
  Mat A;
  ASSERT_EQ(GridMatrix(12, &A), PETSC_SUCCESS);
  struct Case {
    const char *budget_mb;
    bool scalable;
    const char *pc_type, *ksp_type, *reason;
  };
  for (const Case &c : {Case{"0.01", true, PCGAMG, KSPCG, "CG + GAMG: the factor would need "},
                        Case{"1e6", false, kPCSupernodal, KSPPREONLY, "supernodal factor: "}}) {
    KSP ksp;
    ASSERT_EQ(SupernodalSolver(A, c.budget_mb, &ksp), PETSC_SUCCESS);
    PC pc;
    ASSERT_EQ(KSPGetPC(ksp, &pc), PETSC_SUCCESS);
    SolverChoice choice;
    ASSERT_EQ(ChooseFactorOrMultigrid(ksp, pc, &choice), PETSC_SUCCESS);
    EXPECT_TRUE(choice.checked);
    EXPECT_EQ(choice.scalable, c.scalable) << c.budget_mb;
    EXPECT_EQ(choice.reason.rfind(c.reason, 0), 0u) << choice.reason;
    PetscBool same;
    ASSERT_EQ(KSPGetPC(ksp, &pc), PETSC_SUCCESS);
    ASSERT_EQ(PetscObjectTypeCompare((PetscObject)pc, c.pc_type, &same), PETSC_SUCCESS);
    EXPECT_TRUE(same) << c.budget_mb;
    ASSERT_EQ(PetscObjectTypeCompare((PetscObject)ksp, c.ksp_type, &same), PETSC_SUCCESS);
    EXPECT_TRUE(same) << c.budget_mb;
    KSPDestroy(&ksp);
  }
  for (const char *name :
       {"-ksp_type", "-pc_type", "-ksp_rtol", "-pc_gamg_use_sa_esteig", "-pc_supernodal_budget_mb"})
    PetscOptionsClearValue(nullptr, name);
  MatDestroy(&A);
}

TEST(SupernodalSeparatorBytes, SixtyFourBitPastIntOverflow) {
  // n_S = 46 341: n_S^2 = 2 147 488 281 > INT_MAX. Every rank: two blocks in
  // double and MPI's reduction buffer (at most 2^24 entries); rank 0 the dense
  // factor at 8 or 4 bytes.
  const double n = 46341.0, square = n * n;
  EXPECT_DOUBLE_EQ(SupernodalSeparatorBytes(46341, 8), 16 * square + 8 * 16777216.0 + 8 * square);
  EXPECT_DOUBLE_EQ(SupernodalSeparatorBytes(46341, 4), 16 * square + 8 * 16777216.0 + 4 * square);
  EXPECT_DOUBLE_EQ(SupernodalSeparatorBytes(100, 8), 32 * 1e4);
}

}  // namespace
