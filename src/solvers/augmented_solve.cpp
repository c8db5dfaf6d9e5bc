// ProjectedSolver's augmented Lagrangian path for two-sided constraints
// (projected_solve.hpp). The two-sided rows J_j v >= c_j (all inequalities)
// with multipliers lambda_j >= 0 and penalties rho_j > 0; each outer iteration
//
//     S = { j : lambda_j + rho_j (c_j - J_j v) > 0 }          (rows that push)
//     (A + J_S^T R J_S) v = b + J_S^T (lambda_S + R c_S)      (projected solve,
//                                                               one-sided rows in P)
//     lambda_j <- max(0, lambda_j + rho_j (c_j - J_j v)) for j in S, 0 outside
//
// (Hestenes-Powell multipliers with the inequalities' projection, e.g.
// Nocedal & Wright, "Numerical Optimization", 17.4), until every row holds to
// a tolerance and no row of S pulls. The multiplier error shrinks per outer
// iteration like 1 / (1 + rho_j (J A^-1 J^T)_jj) >= about 1 / (1 + kappa):
// kappa, the penalty's stiffness along a row over A's, trades outer
// iterations (fewer when large) for the inner CG's (the unconstrained
// preconditioner does not see the penalty: more when large).
// Why not PETSc's own: TAO's bound-constrained solvers take bounds on the
// unknowns, not on J v; its augmented-Lagrangian solver (TAOALMM) needs the
// constraint Jacobian as a Mat and re-solves its subproblems with its own
// line-searched quasi-Newton method, where this path keeps softbody's
// projected CG (the one-sided constraints and the constraint correction)
// and the unconstrained solver's preconditioner.
#include <algorithm>
#include <cmath>

#include <Eigen/Core>
#include <vector>

#include "solvers/constraint_rows.hpp"
#include "solvers/projected_solve.hpp"

namespace softbody {

namespace {

// The penalty's stiffness along a row over A's diagonal along it (above).
constexpr double kPenaltyOverStiffness = 10.0;
// Every row holds to this fraction of the velocity scale (the largest of |v|,
// |c_j| of the rows that push and the rows' largest violation at the guess,
// m/s: bodies at rest have a small v, not a small violation to remove): above the inner CG's
// relative 1e-10, far below a contact gap over a step.
constexpr double kRelativeTolerance = 1e-8;
// Contacts found from both sides of a pair of faces give nearly the same row
// twice with right-hand sides apart by the detection's round-off (1e-5 m/s of
// a 0.8 m/s contact measured); both push, and the looser one's multiplier
// drains by only rho_j times that difference per outer iteration. So the
// iterations also stop once the violation falls by less than kStallRatio in
// an iteration (from the kStallAfter-th on) and is within this fraction of
// the velocity scale (1e-6 m of penetration over a step of 0.01 s at 1 m/s).
constexpr double kStallRelativeTolerance = 1e-4;
constexpr double kStallRatio = 0.9;
constexpr int kStallAfter = 3;
// Rows in conflict (with each other, or with the one-sided constraints and the
// guard's held zones) cannot all hold: their multipliers grow by rho_j g_j at
// every outer iteration and the violation does not move; rows at the edge of
// a contact patch can also go in and out of S in a cycle. Measured on a
// corotational flat contact (2 x 50 700 tets, warp CG): violations constant to
// 0.4 % for 5 to 20 outer iterations at 2.5e-4, 1.1e-4 and 6.2e-5 m/s (1.9e-4
// to 7.4e-4 of the speeds), or going round 6.8e-4, 9.2e-5 and 4.8e-5 m/s,
// most solves running to the limit. So the iterations also stop once the
// smallest violation so far has not fallen by kNoProgressRatio in
// kNoProgressOuters iterations and the violation lies within this fraction of
// the velocity scale (1e-4 m of penetration over a step of 0.01 s at 1 m/s,
// the order of a contact gap; the collision guard keeps the surfaces from
// crossing whatever is left). With 1e-3 two of twelve solves of that contact
// still ran to the limit (violations 1.5e-4 and 2.1e-3 m/s, the second
// growing from 2.6e-4 after its eighth outer iteration); with 1e-2 none did,
// and the run took half the CG iterations (docs/contact.md).
constexpr double kConflictRelativeTolerance = 1e-2;
constexpr double kNoProgressRatio = 0.99;
constexpr int kNoProgressOuters = 3;
// Outer iterations at most; a row set that cannot hold (rows in conflict with
// each other or with the one-sided constraints) ends there with the last
// multipliers.
constexpr int kMaxOuterIterations = 60;
// A row whose vertices the one-sided constraints hold whole (|P J_j^T|^2 at
// most this fraction of |J_j|^2) can only conflict with them: it leaves.
constexpr double kHeldRow = 1e-12;

// Collective. Per row of `rows`: q_j = J_j diag(A) J_j^T (the row's
// stiffness in A's units), n_j = |J_j|^2 and p_j = |P J_j^T|^2, as
// scales[3 j + 0, 1, 2]; diagonal: A's (owned entries); held: the one-sided
// constraints' vertices (ProjectedSolver::vertices_), whose projection P
// removes the span of their basis.
PetscErrorCode RowScales(const LocalRowSet &rows, const PetscScalar *diagonal, PetscInt owned,
                         const std::vector<ConstrainedVertex> &held, std::vector<double> *scales) {
  PetscFunctionBeginUser;
  std::vector<double> diagonal_owned(diagonal, diagonal + 3 * owned), removed_owned(9 * owned, 0.0);
  for (const ConstrainedVertex &c : held)  // the span P removes: sum_i q_i q_i^T
    for (int i = 0; i < c.rank; ++i)
      for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k)
          removed_owned[9 * c.vertex + 3 * r + k] += c.basis(r, i) * c.basis(k, i);
  std::vector<double> diagonal_at, removed_at;
  PetscCall(rows.AtRowVertices(diagonal_owned, 3, &diagonal_at));
  PetscCall(rows.AtRowVertices(removed_owned, 9, &removed_at));
  const size_t m = rows.rows().size();
  scales->assign(3 * m, 0.0);
  for (size_t j = 0; j < m; ++j)
    for (int a = 0; a < 4; ++a) {
      const Row &row = rows.rows()[j];
      const Eigen::Vector3d u =
          row.weight[a] * Eigen::Vector3d(row.direction[0], row.direction[1], row.direction[2]);
      const size_t e = 4 * j + a;
      const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> removed(
          &removed_at[9 * e]);
      for (int k = 0; k < 3; ++k) (*scales)[3 * j] += u[k] * u[k] * diagonal_at[3 * e + k];
      (*scales)[3 * j + 1] += u.squaredNorm();
      (*scales)[3 * j + 2] += (u - removed * u).squaredNorm();
    }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. g_j = c_j - J_j v for this rank's rows.
PetscErrorCode Gaps(const LocalRowSet &rows, Vec v, std::vector<double> *gaps) {
  PetscFunctionBeginUser;
  PetscCall(rows.Dots(v, gaps));
  for (size_t j = 0; j < gaps->size(); ++j) (*gaps)[j] = rows.rows()[j].value - (*gaps)[j];
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. f = b + sum_j J_j^T forces_j.
PetscErrorCode AddRowForces(const LocalRowSet &rows, const std::vector<double> &forces, Vec b,
                            Vec f) {
  PetscFunctionBeginUser;
  PetscCall(VecCopy(b, f));
  PetscCall(rows.AddTranspose(forces, f));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode ProjectedSolver::SolveTwoSidedAugmented(
    Vec b, const std::vector<VelocityConstraint> &constraints, Vec v,
    std::vector<PetscReal> *reactions, PetscInt *iterations) {
  PetscFunctionBeginUser;
  RowSite site;
  PetscCall(GetRowSite(b, &site));
  const auto [comm, rank, begin, end] = site;
  std::vector<PetscInt> slot;
  LocalRowSet set;  // this rank's two-sided rows
  PetscCall(set.Setup(b, LocalRows({}, constraints, begin, rank, &slot)));
  const std::vector<Row> &rows = set.rows();
  const size_t m = rows.size();

  // rho_j = kappa q_j / n_j^2: the penalty's Rayleigh quotient along J_j^T,
  // rho_j n_j, is kappa times A's diagonal one, q_j / n_j.
  std::vector<double> scales;
  PetscCall(MatGetDiagonal(A_, work_));
  const PetscScalar *diagonal;
  PetscCall(VecGetArrayRead(work_, &diagonal));
  const PetscErrorCode scaled = RowScales(set, diagonal, end - begin, vertices_, &scales);
  PetscCall(VecRestoreArrayRead(work_, &diagonal));
  PetscCall(scaled);
  std::vector<double> rho(m, 0.0);
  for (size_t j = 0; j < m; ++j) {
    const double q = scales[3 * j], n = scales[3 * j + 1], p = scales[3 * j + 2];
    if (p > kHeldRow * n) rho[j] = kPenaltyOverStiffness * q / (n * n);
  }

  // The multipliers start at the rows' guesses (a resting contact's last
  // reaction): a contact at rest then needs few outer iterations.
  std::vector<double> lambda(m, 0.0), gaps, forces(m, 0.0);
  for (size_t i = 0; i < constraints.size(); ++i)
    if (slot[i] >= 0 && rho[slot[i]] > 0) lambda[slot[i]] = std::max(0.0, constraints[i].guess);
  PetscCall(Gaps(set, v, &gaps));
  double first_gap = 0;  // the largest violation at the guess
  for (size_t j = 0; j < m; ++j)
    if (rho[j] > 0) first_gap = std::max(first_gap, gaps[j]);
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, &first_gap, 1, MPIU_REAL, MPI_MAX, comm));
  RowPenalty penalty{&set, std::vector<double>(m, 0.0)};
  int outer = 0, no_progress = 0;
  PetscInt active = 0;
  double violation = 0, last_violation = 1e300, best_violation = 1e300;
  for (bool converged = false; !converged && outer < kMaxOuterIterations; ++outer) {
    active = 0;
    double largest[2] = {0, 0};  // the violation, the largest |c_j| of S
    for (size_t j = 0; j < m; ++j) {
      const bool pushes = rho[j] > 0 && lambda[j] + rho[j] * gaps[j] > 0;
      penalty.rho[j] = pushes ? rho[j] : 0.0;
      forces[j] = pushes ? lambda[j] + rho[j] * rows[j].value : 0.0;
      active += pushes;
      if (pushes) largest[1] = std::max(largest[1], std::abs(rows[j].value));
    }
    PetscCall(AddRowForces(set, forces, b, column_rhs_));
    penalty_ = &penalty;
    const PetscErrorCode solved = SolveConstrained(column_rhs_, true, v, iterations);
    penalty_ = nullptr;
    PetscCall(solved);
    PetscCall(Gaps(set, v, &gaps));
    for (size_t j = 0; j < m; ++j) {
      if (rho[j] == 0) continue;
      // A row outside S had no force in this solve: its gap is the free
      // motion's, and lambda_j + rho_j g_j would overshoot by far where the
      // penalty is stiff (rho_j D_jj >> 1); it enters S next with lambda_j = 0.
      const double applied = penalty.rho[j] > 0 ? lambda[j] + rho[j] * gaps[j] : 0.0;
      lambda[j] = std::max(0.0, applied);
      largest[0] = std::max(largest[0], lambda[j] > 0 ? std::abs(gaps[j]) : gaps[j]);
      // a row of S that ended up pulling: its force was not lambda_j's
      if (applied < 0) largest[0] = std::max(largest[0], -applied / rho[j]);
    }
    PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, largest, 2, MPIU_REAL, MPI_MAX, comm));
    PetscReal speed;
    PetscCall(VecNorm(v, NORM_INFINITY, &speed));
    const double velocity_scale = std::max({largest[1], speed, first_gap});
    violation = largest[0];
    no_progress = violation < kNoProgressRatio * best_violation ? 0 : no_progress + 1;
    best_violation = std::min(best_violation, violation);
    const bool stalled = outer >= kStallAfter && violation > kStallRatio * last_violation &&
                         violation <= kStallRelativeTolerance * velocity_scale;
    const bool in_conflict = no_progress >= kNoProgressOuters &&
                             violation <= kConflictRelativeTolerance * velocity_scale;
    converged = violation <= kRelativeTolerance * velocity_scale || stalled || in_conflict;
    last_violation = violation;
  }
  augmented_outer_iterations_ = outer;
  PetscInt counts[2] = {static_cast<PetscInt>(m), active};
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, counts, 2, MPIU_INT, MPI_SUM, comm));
  PetscCall(PetscInfo(nullptr,
                      "two-sided contact, augmented Lagrangian path: %" PetscInt_FMT
                      " rows, %" PetscInt_FMT " pushing, %d outer iterations, largest violation "
                      "%g m/s\n",
                      counts[0], counts[1], outer, violation));
  // The one-sided reactions from A v - (b + J_2^T lambda).
  PetscCall(AddRowForces(set, lambda, b, column_rhs_));
  PetscCall(Reactions(column_rhs_, v, constraints, reactions));
  for (size_t i = 0; i < constraints.size(); ++i)
    if (slot[i] >= 0) (*reactions)[i] = lambda[slot[i]];
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
