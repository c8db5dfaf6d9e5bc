#include "solvers/mixed_lcp.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

namespace softbody {

namespace {

// Gauss-Seidel sweeps before the first active-set solve: enough to settle
// which contacts of a resting stack push (measured: tens), few enough to be
// cheap next to the m back-solves that built D.
constexpr int kWarmSweeps = 200;
// Active-set solves before falling back to Gauss-Seidel alone.
constexpr int kMaxPivots = 100;
// Block principal pivoting (Judice & Pires 1994): every infeasible row
// changes side at once while the count of infeasible rows keeps falling;
// after this many solves in a row without a new lowest count, one row at a
// time (the most pulling leaves, else the most violated joins), which cannot
// cycle. A resting box on another (600 rows, hundreds changing side) took 100
// one-row solves and still fell back to Gauss-Seidel.
constexpr int kBlockTries = 3;
// The active rows are solved by a pivoted LDL^T of D_aa whose pivots below
// k eps times the largest count as zero (the rows are redundant there, D_aa
// singular): a redundant row gets no reaction, with the rank threshold of the
// complete orthogonal decomposition used before (the same results on the
// stack of three blocks, 10 s) at about a quarter of its flops. A Cholesky of
// D_aa + 1e-12 max(diag) I instead gave nearly redundant rows large opposite
// reactions: the stack of three blocks (10 s) then swayed at 1.4e-8 of its
// potential energy instead of resting at 1.8e-10.
// An active row's lambda below -kPullRoundOff times the largest |lambda| pulls;
// smaller negatives are the least-norm solve's round-off.
constexpr double kPullRoundOff = 1e-12;
// Gauss-Seidel sweeps when the active-set loop does not settle (an
// inconsistent problem: the best it can do, at a bounded cost).
constexpr int kMaxSweeps = 2000;

// Largest violation of the conditions at lambda (r = D lambda + g).
double Violation(const Eigen::VectorXd &lambda, const Eigen::VectorXd &r,
                 const std::vector<char> &unilateral) {
  double worst = 0;
  for (Eigen::Index i = 0; i < r.size(); ++i) {
    if (!unilateral[i]) {
      worst = std::max(worst, std::abs(r[i]));
      continue;
    }
    worst = std::max(worst, -r[i]);
    if (lambda[i] > 0) worst = std::max(worst, std::abs(r[i]));
  }
  return worst;
}

void Sweep(const Eigen::MatrixXd &D, const Eigen::VectorXd &g, const std::vector<char> &unilateral,
           Eigen::VectorXd *lambda) {
  for (Eigen::Index i = 0; i < g.size(); ++i) {
    if (!(D(i, i) > 0)) continue;
    const double r = D.col(i).dot(*lambda) + g[i];  // D symmetric: its column is contiguous
    double next = (*lambda)[i] - r / D(i, i);
    if (unilateral[i]) next = std::max(next, 0.0);
    (*lambda)[i] = next;
  }
}

// Solves the rows in `active` exactly (least norm), the others at zero.
Eigen::VectorXd SolveActive(const Eigen::MatrixXd &D, const Eigen::VectorXd &g,
                            const std::vector<char> &active) {
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < g.size(); ++i)
    if (active[i]) rows.push_back(i);
  const Eigen::Index k = static_cast<Eigen::Index>(rows.size());
  Eigen::MatrixXd Daa(k, k);
  Eigen::VectorXd ga(k);
  for (Eigen::Index a = 0; a < k; ++a) {
    ga[a] = g[rows[a]];
    for (Eigen::Index b = 0; b < k; ++b) Daa(a, b) = D(rows[a], rows[b]);
  }
  Eigen::VectorXd lambda = Eigen::VectorXd::Zero(g.size());
  if (k == 0) return lambda;
  Eigen::LDLT<Eigen::MatrixXd> ldlt(Daa);
  const Eigen::VectorXd d = ldlt.vectorD();
  const double threshold =
      static_cast<double>(k) * std::numeric_limits<double>::epsilon() * d.cwiseAbs().maxCoeff();
  Eigen::VectorXd la = ldlt.transpositionsP() * (-ga);
  ldlt.matrixL().solveInPlace(la);
  for (Eigen::Index a = 0; a < k; ++a) la[a] = std::abs(d[a]) > threshold ? la[a] / d[a] : 0.0;
  ldlt.matrixU().solveInPlace(la);
  la = ldlt.transpositionsP().transpose() * la;
  for (Eigen::Index a = 0; a < k; ++a) lambda[rows[a]] = la[a];
  return lambda;
}

// The unilateral rows on the wrong side at the active set's solution: active
// ones that pull (lambda below round-off of zero), inactive ones violated.
std::vector<Eigen::Index> Infeasible(const Eigen::VectorXd &lambda, const Eigen::VectorXd &r,
                                     const std::vector<char> &unilateral,
                                     const std::vector<char> &active, double tolerance) {
  const double pull = -kPullRoundOff * lambda.cwiseAbs().maxCoeff();
  std::vector<Eigen::Index> rows;
  for (Eigen::Index i = 0; i < r.size(); ++i)
    if (unilateral[i] && ((active[i] && lambda[i] < pull) || (!active[i] && r[i] < -tolerance)))
      rows.push_back(i);
  return rows;
}

// Of the infeasible rows: the most pulling active one, else the most violated.
Eigen::Index SinglePivot(const Eigen::VectorXd &lambda, const Eigen::VectorXd &r,
                         const std::vector<char> &active,
                         const std::vector<Eigen::Index> &infeasible) {
  Eigen::Index leaves = -1, joins = -1;
  for (const Eigen::Index i : infeasible) {
    if (active[i] && (leaves < 0 || lambda[i] < lambda[leaves])) leaves = i;
    if (!active[i] && (joins < 0 || r[i] < r[joins])) joins = i;
  }
  return leaves >= 0 ? leaves : joins;
}

}  // namespace

MixedLcpResult SolveMixedLcp(const Eigen::MatrixXd &D, const Eigen::VectorXd &g,
                             const std::vector<char> &unilateral, double tolerance) {
  MixedLcpResult result;
  const Eigen::Index m = g.size();
  result.lambda = Eigen::VectorXd::Zero(m);
  result.exact = m == 0;
  if (m == 0) return result;
  for (; result.sweeps < kWarmSweeps; ++result.sweeps) Sweep(D, g, unilateral, &result.lambda);
  std::vector<char> active(m);
  for (Eigen::Index i = 0; i < m; ++i) active[i] = !unilateral[i] || result.lambda[i] > 0;
  // Block pivots while they make progress, then one row at a time (kBlockTries).
  size_t fewest = static_cast<size_t>(m) + 1;
  int tries = kBlockTries;
  for (; result.pivots < kMaxPivots; ++result.pivots) {
    const Eigen::VectorXd lambda = SolveActive(D, g, active);
    const Eigen::VectorXd r = D * lambda + g;
    const std::vector<Eigen::Index> infeasible =
        Infeasible(lambda, r, unilateral, active, tolerance);
    if (infeasible.empty()) {
      if (Violation(lambda, r, unilateral) > tolerance) break;  // inconsistent bilateral rows
      result.lambda = lambda;
      for (Eigen::Index i = 0; i < m; ++i)
        if (unilateral[i]) result.lambda[i] = std::max(result.lambda[i], 0.0);
      result.residual = Violation(result.lambda, D * result.lambda + g, unilateral);
      result.exact = true;
      ++result.pivots;
      return result;
    }
    if (infeasible.size() < fewest) fewest = infeasible.size(), tries = kBlockTries;
    if (tries-- > 0) {
      for (const Eigen::Index i : infeasible) active[i] = !active[i];
    } else {
      const Eigen::Index i = SinglePivot(lambda, r, active, infeasible);
      active[i] = !active[i];
    }
  }
  for (; result.sweeps < kMaxSweeps; ++result.sweeps) {
    Sweep(D, g, unilateral, &result.lambda);
    if (Violation(result.lambda, D * result.lambda + g, unilateral) <= tolerance) break;
  }
  result.residual = Violation(result.lambda, D * result.lambda + g, unilateral);
  return result;
}

}  // namespace softbody
