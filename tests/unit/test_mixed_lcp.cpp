// SolveMixedLcp (solvers/mixed_lcp.hpp) on a contact-like problem with many
// rows changing side and redundant rows, checked against the complementarity
// conditions themselves and against projected Gauss-Seidel run to convergence
// (a second method: for a symmetric positive semi-definite D every solution
// has the same r = D lambda + g, even when lambda is not unique).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <vector>

#include "solvers/mixed_lcp.hpp"

namespace softbody {
namespace {

constexpr int kDofs = 400;     // a chain of unit masses and springs
constexpr int kRows = 300;     // contacts on the first 300 masses
constexpr int kRepeated = 30;  // rows given twice (D singular)
constexpr double kTolerance = 1e-10;
// Measured 1 to 3 on chains of this kind (the application's harder case, a
// box landing flat on another, is test_contact_cost.py (e)).
constexpr int kMaxExpectedPivots = 12;

// D = J A^-1 J^T for A = I + 50 L (L the chain's Laplacian) and J unit rows on
// the first kRows DOFs, then kRepeated of them again; g alternates in sign in
// long runs, so that about half the rows push.
void ContactProblem(Eigen::MatrixXd *D, Eigen::VectorXd *g) {
  Eigen::MatrixXd A = Eigen::MatrixXd::Identity(kDofs, kDofs);
  for (int i = 0; i + 1 < kDofs; ++i) {
    A(i, i) += 50, A(i + 1, i + 1) += 50;
    A(i, i + 1) -= 50, A(i + 1, i) -= 50;
  }
  const Eigen::MatrixXd inverse = A.inverse();
  std::vector<int> dof;
  for (int i = 0; i < kRows; ++i) dof.push_back(i);
  for (int i = 0; i < kRepeated; ++i) dof.push_back(7 * i);
  const int m = static_cast<int>(dof.size());
  D->resize(m, m);
  g->resize(m);
  for (int a = 0; a < m; ++a) {
    for (int b = 0; b < m; ++b) (*D)(a, b) = inverse(dof[a], dof[b]);
    (*g)[a] = std::sin(0.05 * dof[a]) - 0.2;
  }
}

double ResidualViolation(const Eigen::VectorXd &lambda, const Eigen::VectorXd &r) {
  double worst = 0;
  for (Eigen::Index i = 0; i < r.size(); ++i) {
    worst = std::max({worst, -lambda[i], -r[i]});
    worst = std::max(worst, std::min(std::abs(lambda[i]), std::abs(r[i])));
  }
  return worst;
}

TEST(MixedLcp, MeetsTheConditionsWithRedundantRowsAndAgreesWithGaussSeidel) {
  Eigen::MatrixXd D;
  Eigen::VectorXd g;
  ContactProblem(&D, &g);
  const std::vector<char> unilateral(g.size(), 1);
  const MixedLcpResult result = SolveMixedLcp(D, g, unilateral, kTolerance);
  const Eigen::VectorXd r = D * result.lambda + g;
  EXPECT_TRUE(result.exact);
  EXPECT_LE(result.pivots, kMaxExpectedPivots);
  EXPECT_LE(ResidualViolation(result.lambda, r), kTolerance);
  int pushing = 0;
  for (Eigen::Index i = 0; i < r.size(); ++i) pushing += result.lambda[i] > 0;
  EXPECT_GT(pushing, kRows / 4);  // the problem is not trivial
  EXPECT_LT(pushing, static_cast<int>(r.size()));

  // Projected Gauss-Seidel to convergence: the same r.
  Eigen::VectorXd lambda = Eigen::VectorXd::Zero(g.size());
  for (int sweep = 0; sweep < 20000; ++sweep)
    for (Eigen::Index i = 0; i < g.size(); ++i)
      lambda[i] = std::max(0.0, lambda[i] - (D.col(i).dot(lambda) + g[i]) / D(i, i));
  const Eigen::VectorXd reference = D * lambda + g;
  EXPECT_LE(ResidualViolation(lambda, reference), 1e-8);
  EXPECT_LE((r - reference).cwiseAbs().maxCoeff(), 1e-8);
}

}  // namespace
}  // namespace softbody
