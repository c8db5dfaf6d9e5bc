// A small dense mixed linear complementarity problem, solved identically on
// every rank: find lambda with
//
//     r = D lambda + g,   r_i = 0 for bilateral rows,
//     lambda_i >= 0, r_i >= 0, lambda_i r_i = 0 for unilateral rows,
//
// D symmetric positive semi-definite (a Delassus operator J A^-1 J^T; rows may
// be redundant, e.g. two contacts between the same pair of points). Projected
// Gauss-Seidel finds the active set, then an active-set loop solves the active
// rows exactly (least norm, so redundant rows do no harm) until no active
// unilateral row pulls and no inactive one is violated. Pure.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace softbody {

struct MixedLcpResult {
  Eigen::VectorXd lambda;
  double residual = 0;  // largest violation of the conditions above, in units of r
  int sweeps = 0;       // Gauss-Seidel sweeps
  int pivots = 0;       // active-set solves
  bool exact = false;   // an active-set solve met every condition to the tolerance
};

// unilateral[i]: row i is a contact (lambda_i >= 0); tolerance: in units of r
// (velocity, m/s), the violation accepted.
MixedLcpResult SolveMixedLcp(const Eigen::MatrixXd &D, const Eigen::VectorXd &g,
                             const std::vector<char> &unilateral, double tolerance);

}  // namespace softbody
