#include "solvers/mixed_lcp.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace softbody {

namespace {

// Gauss-Seidel sweeps before the first active-set solve: enough to settle
// which contacts of a resting stack push (measured: tens), few enough to be
// cheap next to the m back-solves that built D.
constexpr int kWarmSweeps = 200;
// Active-set solves (one row in or out each) before falling back to
// Gauss-Seidel alone.
constexpr int kMaxPivots = 100;
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
  const Eigen::VectorXd la = Daa.completeOrthogonalDecomposition().solve(-ga);
  for (Eigen::Index a = 0; a < k; ++a) lambda[rows[a]] = la[a];
  return lambda;
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
  // One change per solve: the most pulling active row leaves, else the most
  // violated inactive one joins.
  for (; result.pivots < kMaxPivots; ++result.pivots) {
    const Eigen::VectorXd lambda = SolveActive(D, g, active);
    const Eigen::VectorXd r = D * lambda + g;
    const double pull = -kPullRoundOff * lambda.cwiseAbs().maxCoeff();
    Eigen::Index leaves = -1, joins = -1;
    for (Eigen::Index i = 0; i < m; ++i) {
      if (!unilateral[i]) continue;
      if (active[i] && lambda[i] < pull && (leaves < 0 || lambda[i] < lambda[leaves])) leaves = i;
      if (!active[i] && r[i] < -tolerance && (joins < 0 || r[i] < r[joins])) joins = i;
    }
    if (leaves >= 0) {
      active[leaves] = 0;
    } else if (joins >= 0) {
      active[joins] = 1;
    } else if (Violation(lambda, r, unilateral) <= tolerance) {
      result.lambda = lambda;
      for (Eigen::Index i = 0; i < m; ++i)
        if (unilateral[i]) result.lambda[i] = std::max(result.lambda[i], 0.0);
      result.residual = Violation(result.lambda, D * result.lambda + g, unilateral);
      result.exact = true;
      ++result.pivots;
      return result;
    } else {
      break;  // the active rows cannot all hold (inconsistent bilateral rows)
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
