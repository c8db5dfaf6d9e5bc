#include "solvers/projected_solve.hpp"

#include "solvers/constraint_correction.hpp"
#include "solvers/constraint_rows.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <map>

namespace softbody {

namespace {

// CombineConstraints: at most this many constraints per vertex are considered
// (a contact with its two friction tangents and the normals of up to three
// obstacles); the candidate sets are their 2^6 - 1 subsets.
constexpr int kMaxConstraintsPerVertex = 6;
// A constraint counts as kept when it is violated by less than this fraction of
// the largest prescribed speed (round-off of the least-norm solve).
constexpr double kViolationRoundOff = 1e-12;
// The violation and norm of "no candidate yet": above any real candidate's.
constexpr double kNoCandidate = 1e300;

// The inner CG: relative tolerance (as tight as the unconstrained solve's
// -ksp_rtol 1e-10 of the presets), no divergence test (at rest b is tiny next
// to the warm start's residual) and an iteration cap far above the at most one
// iteration per constraint a direct preconditioner needs. -contact_ksp_*
// options override them.
constexpr PetscReal kInnerRelativeTolerance = 1e-10;
constexpr PetscReal kNoDivergenceTest = 1e300;
constexpr PetscInt kInnerMaxIterations = 10000;
// Solve's choice between the two paths for two-sided constraints: the
// projected Delassus path costs m2 + 2 projected solves of about this many CG
// iterations each (one back-solve per iteration with the direct preset), the
// Delassus path m1 + m2 + 1 back-solves and a dense problem of that size. It
// is taken when the m1 one-sided rows are at least this many times m2 + 2.
// Measured on infomgp-p3/fertility (two statues pressed into each other and
// the ground; 2 ranks, direct preset: 700-900 one-sided rows, 1-3 two-sided):
// 13 iterations per projected solve on average, at most 34.
constexpr PetscInt kProjectedSolveCost = 16;
// With an iterative unconstrained solver the Delassus path costs m1 + m2 + 1
// Krylov solves, the augmented Lagrangian path a few projected solves (its
// outer iterations, each slower than an unconstrained solve: the penalty is
// not in the preconditioner) while its rows hold, up to its 60 where rows
// conflict with the one-sided constraints. Measured: with CG + GAMG, 1 rank,
// two stacked boxes of 422 and 1 302 rows, 17 to 25 unconstrained solves'
// iterations; with the corotational warp, three stacked blocks at rest (50 to
// 110 rows, the guard's zones among them) 150 against 56 ms per step, the
// zones' conflicts taking 60 outer iterations. So it is taken from this many
// rows on, where the Delassus path's cost is out of reach.
constexpr PetscInt kAugmentedSolveCost = 300;
// With a factorisation the Delassus path keeps columns of A^-1 while they fit
// (two_sided_solve.cpp), else takes a back-solve per row (four per sweep of the
// factor on one rank), and reduces an m x m matrix over the ranks; the
// augmented path takes a few projected solves of one back-solve per CG
// iteration, its multipliers starting from the resting contacts' last
// reactions. Measured (1 rank, linear, two boxes stacked on the ground):
// 2 x 10 080 tets, about 770 rows, columns kept: Delassus 244 ms per contact
// step, augmented 576 ms; 2 x 50 700 tets, 2 006 rows, columns too big: first
// contact 6.5 s against 2.7 s CPU, at rest 7.5 s against 6.0 s. So it is taken
// from this many rows on, between the two.
constexpr PetscInt kAugmentedFactorCost = 1500;

// A candidate set of imposed constraints, ranked by CombineConstraints' order.
struct Candidate {
  double violation = kNoCandidate, norm = kNoCandidate;
  int size = 0, immobile = 0;

  bool BetterThan(const Candidate &o) const {
    return violation < o.violation ||
           (violation == o.violation &&
            (size > o.size || (size == o.size && (immobile > o.immobile ||
                                                  (immobile == o.immobile && norm < o.norm)))));
  }
};

// max_j (c_j - n_j . p) over the first k constraints, at least the round-off
// kViolationRoundOff max_j |c_j| (below that a constraint counts as kept).
double Violation(const std::vector<VelocityConstraint> &constraints, int k,
                 const Eigen::Vector3d &p) {
  double violation = 0, scale = 0;
  for (int j = 0; j < k; ++j) {
    violation = std::max(violation, constraints[j].velocity - constraints[j].normal.dot(p));
    scale = std::max(scale, std::abs(constraints[j].velocity));
  }
  return std::max(violation, kViolationRoundOff * scale);
}

}  // namespace

const char *const kTwoSidedPaths[] = {"auto",         "delassus", "projected", "augmented",
                                      "TwoSidedPath", "",         nullptr};

PetscInt ProjectedSolver::correction_column_solves() const {
  return correction_ ? correction_->column_solves() : 0;
}

PetscErrorCode ProjectedSolver::SetupCorrection() {
  PetscFunctionBeginUser;
  corrected_ = false;
  if (!correct_) PetscFunctionReturn(PETSC_SUCCESS);
  if (!correction_) correction_ = std::make_unique<ConstraintCorrection>();
  PetscCall(correction_->Setup(unconstrained_pc_, A_, vertices_, &corrected_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

ProjectedSolver::ProjectedSolver() = default;

ProjectedSolver::~ProjectedSolver() {
  KSPDestroy(&inner_);
  MatDestroy(&shell_);
  VecDestroy(&work_);
  VecDestroy(&work2_);
  VecDestroy(&z_);
  VecDestroy(&rhs_);
  VecDestroy(&w_);
  VecDestroy(&column_);
  VecDestroy(&column_rhs_);
  DropDelassusColumns({});
}

void ProjectedSolver::GroupByVertex(const std::vector<VelocityConstraint> &constraints) {
  std::map<PetscInt, std::vector<const VelocityConstraint *>> by_vertex;
  for (const VelocityConstraint &c : constraints) by_vertex[c.vertex].push_back(&c);
  vertices_.clear();
  for (const auto &[vertex, list] : by_vertex) {
    std::vector<VelocityConstraint> own;
    for (const VelocityConstraint *c : list) own.push_back(*c);
    vertices_.push_back(CombineConstraints(vertex, own));
  }
}

ConstrainedVertex CombineConstraints(PetscInt vertex,
                                     const std::vector<VelocityConstraint> &constraints) {
  if (std::any_of(constraints.begin(), constraints.end(),
                  [](const VelocityConstraint &c) { return c.prescribes_all; })) {
    ConstrainedVertex held{vertex, Eigen::Matrix3d::Identity(), 3, Eigen::Vector3d::Zero()};
    for (const VelocityConstraint &c : constraints)
      if (c.prescribes_all) held.prescribed += c.velocity * c.normal;
    return held;
  }
  const int k = static_cast<int>(
      std::min<size_t>(constraints.size(), static_cast<size_t>(kMaxConstraintsPerVertex)));
  // Candidate active sets S (bit masks), each solved exactly: p = least-norm
  // solution of N_S^T p = c_S, in span(N_S).
  ConstrainedVertex best{vertex, Eigen::Matrix3d::Zero(), 0, Eigen::Vector3d::Zero()};
  Candidate best_candidate;
  for (int mask = 1; mask < (1 << k); ++mask) {
    Eigen::Matrix3d N = Eigen::Matrix3d::Zero();
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    int members = 0;
    for (int j = 0; j < k; ++j) members += (mask >> j) & 1;
    if (members > 3) continue;  // at most three independent directions
    Candidate candidate;
    for (int j = 0; j < k; ++j)
      if (mask & (1 << j)) {
        N.col(candidate.size) = constraints[j].normal;
        c[candidate.size++] = constraints[j].velocity;
        candidate.immobile += constraints[j].immobile;
      }
    const int size = candidate.size;
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(N.leftCols(size),
                                                Eigen::ComputeThinU | Eigen::ComputeThinV);
    if (svd.singularValues()[size - 1] < kMinSeparation) continue;  // near-parallel directions
    const Eigen::Vector3d p =
        N.leftCols(size).transpose().completeOrthogonalDecomposition().solve(c.head(size));
    candidate.violation = Violation(constraints, k, p);
    candidate.norm = p.norm();
    if (!candidate.BetterThan(best_candidate)) continue;
    best_candidate = candidate;
    best.rank = size;
    best.basis.leftCols(size) = svd.matrixU();
    best.prescribed = p;
  }
  return best;
}

void ProjectedSolver::Project(const PetscScalar *w, PetscScalar *y, bool project) const {
  for (const ConstrainedVertex &c : vertices_) {
    const Eigen::Vector3d wi(w[3 * c.vertex], w[3 * c.vertex + 1], w[3 * c.vertex + 2]);
    const auto Q = c.basis.leftCols(c.rank);
    const Eigen::Vector3d constrained = Q * (Q.transpose() * wi);
    const Eigen::Vector3d yi = project ? Eigen::Vector3d(wi - constrained) : constrained;
    for (int k = 0; k < 3; ++k) y[3 * c.vertex + k] = yi[k];
  }
}

PetscErrorCode ProjectedSolver::ProjectVec(Vec w, Vec y, bool project) const {
  PetscFunctionBeginUser;
  if (project)
    PetscCall(VecCopy(w, y));
  else
    PetscCall(VecZeroEntries(y));
  const PetscScalar *win;
  PetscScalar *yout;
  PetscCall(VecGetArrayRead(w, &win));
  PetscCall(VecGetArray(y, &yout));
  Project(win, yout, project);
  PetscCall(VecRestoreArrayRead(w, &win));
  PetscCall(VecRestoreArray(y, &yout));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ProjectedSolver::ApplyA(Vec x, Vec y) const {
  PetscFunctionBeginUser;
  PetscCall(MatMult(A_, x, y));
  if (penalty_) PetscCall(penalty_->AddTo(x, y));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// y = P A P w + (I - P) w (A with the penalty's term: ApplyA)
PetscErrorCode ProjectedSolver::ApplyOperator(Mat shell, Vec w, Vec y) {
  PetscFunctionBeginUser;
  ProjectedSolver *self;
  PetscCall(MatShellGetContext(shell, &self));
  PetscCall(self->ProjectVec(w, self->work_, true));
  PetscCall(self->ApplyA(self->work_, self->work2_));
  PetscCall(self->ProjectVec(self->work2_, y, true));
  PetscCall(self->ProjectVec(w, self->work_, false));
  PetscCall(VecAXPY(y, 1.0, self->work_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// y = P M^-1 P w + (I - P) w, or with the constraint correction G in place of
// M^-1 (constraint_correction.hpp)
PetscErrorCode ProjectedSolver::ApplyPreconditioner(PC shell, Vec w, Vec y) {
  PetscFunctionBeginUser;
  ProjectedSolver *self;
  PetscCall(PCShellGetContext(shell, &self));
  PetscCall(self->ProjectVec(w, self->work_, true));
  if (self->corrected_)
    PetscCall(self->correction_->Apply(self->work_, self->work2_));
  else
    PetscCall(PCApply(self->unconstrained_pc_, self->work_, self->work2_));
  PetscCall(self->ProjectVec(self->work2_, y, true));
  PetscCall(self->ProjectVec(w, self->work_, false));
  PetscCall(VecAXPY(y, 1.0, self->work_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ProjectedSolver::CreateInnerSolver(Vec b) {
  PetscFunctionBeginUser;
  PetscInt n, N;
  PetscCall(VecGetLocalSize(b, &n));
  PetscCall(VecGetSize(b, &N));
  for (Vec *work : {&work_, &work2_, &z_, &rhs_, &w_, &column_, &column_rhs_})
    PetscCall(VecDuplicate(b, work));
  PetscCall(MatCreateShell(PetscObjectComm((PetscObject)b), n, n, N, N, this, &shell_));
  PetscCall(MatShellSetOperation(shell_, MATOP_MULT, (void (*)(void))ApplyOperator));
  PetscCall(KSPCreate(PetscObjectComm((PetscObject)b), &inner_));
  PetscCall(KSPSetOptionsPrefix(inner_, "contact_"));
  PetscCall(KSPSetType(inner_, KSPCG));
  PetscCall(KSPSetTolerances(inner_, kInnerRelativeTolerance, PETSC_DEFAULT, kNoDivergenceTest,
                             kInnerMaxIterations));
  PetscCall(KSPSetOperators(inner_, shell_, shell_));
  PC pc;
  PetscCall(KSPGetPC(inner_, &pc));
  PetscCall(PCSetType(pc, PCSHELL));
  PetscCall(PCShellSetContext(pc, this));
  PetscCall(PCShellSetApply(pc, ApplyPreconditioner));
  PetscCall(PCShellSetName(pc, "P M^-1 P + I - P"));
  PetscCall(KSPSetInitialGuessNonzero(inner_, PETSC_TRUE));
  PetscCall(KSPSetFromOptions(inner_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ProjectedSolver::SetPrescribedVelocities() {
  PetscFunctionBeginUser;
  PetscCall(VecZeroEntries(z_));
  PetscScalar *z;
  PetscCall(VecGetArray(z_, &z));
  for (const ConstrainedVertex &c : vertices_)
    for (int k = 0; k < 3; ++k) z[3 * c.vertex + k] = c.prescribed[k];
  PetscCall(VecRestoreArray(z_, &z));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ProjectedSolver::Reactions(Vec b, Vec v,
                                          const std::vector<VelocityConstraint> &constraints,
                                          std::vector<PetscReal> *reactions) {
  PetscFunctionBeginUser;
  PetscCall(MatMult(A_, v, work_));
  PetscCall(VecAXPY(work_, -1.0, b));
  const PetscScalar *residual;
  PetscCall(VecGetArrayRead(work_, &residual));
  reactions->resize(constraints.size());
  for (size_t i = 0; i < constraints.size(); ++i) {
    const VelocityConstraint &c = constraints[i];
    (*reactions)[i] = c.normal.dot(Eigen::Vector3d(
        residual[3 * c.vertex], residual[3 * c.vertex + 1], residual[3 * c.vertex + 2]));
  }
  PetscCall(VecRestoreArrayRead(work_, &residual));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ProjectedSolver::Solve(KSP solver, Vec b,
                                      const std::vector<VelocityConstraint> &constraints, Vec v,
                                      std::vector<PetscReal> *reactions, PetscInt *iterations) {
  PetscFunctionBeginUser;
  PetscCall(KSPSetUp(solver));  // refreshes the preconditioner if A changed
  PetscCall(KSPGetOperators(solver, &A_, nullptr));
  PetscCall(KSPGetPC(solver, &unconstrained_pc_));
  if (!inner_) PetscCall(CreateInnerSolver(b));
  std::vector<VelocityConstraint> one_sided;
  for (const VelocityConstraint &c : constraints)
    if (!c.two_sided) one_sided.push_back(c);
  GroupByVertex(one_sided);
  // Global counts: two-sided rows, one-sided rows (combined directions).
  PetscInt counts[2] = {static_cast<PetscInt>(constraints.size() - one_sided.size()), 0};
  for (const ConstrainedVertex &c : vertices_) counts[1] += c.rank;
  PetscCallMPI(
      MPIU_Allreduce(MPI_IN_PLACE, counts, 2, MPIU_INT, MPI_SUM, PetscObjectComm((PetscObject)b)));
  *iterations = 0;
  bool factor_once;
  PetscCall(AppliesFactorOnce(solver, &factor_once));
  const PetscInt augmented_from = factor_once ? kAugmentedFactorCost : kAugmentedSolveCost;
  const bool augmented =
      path_ == TwoSidedPath::kAugmented ||
      (path_ == TwoSidedPath::kAuto && counts[0] + counts[1] + 1 > augmented_from);
  if (counts[0] == 0) {
    PetscCall(SetupCorrection());
    PetscCall(SolveProjected(b, constraints, v, reactions, iterations));
  } else if (augmented) {
    PetscCall(SetupCorrection());
    PetscCall(SolveTwoSidedAugmented(b, constraints, v, reactions, iterations));
  } else if (path_ == TwoSidedPath::kProjected ||
             (path_ == TwoSidedPath::kAuto && counts[1] >= kProjectedSolveCost * (counts[0] + 2))) {
    PetscCall(SetupCorrection());
    PetscCall(SolveTwoSidedProjected(solver, b, constraints, v, reactions, iterations));
  } else {
    PetscCall(SolveTwoSided(solver, b, constraints, v, reactions, iterations));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// v = z + P w with (P A P + I - P) w = P (f - A z), z the prescribed velocities
// (prescribed) or zero: A v = f under the one-sided constraints (homogeneous
// ones when !prescribed). v: the initial guess on entry.
PetscErrorCode ProjectedSolver::SolveConstrained(Vec f, bool prescribed, Vec v,
                                                 PetscInt *iterations) {
  PetscFunctionBeginUser;
  if (prescribed) {
    PetscCall(SetPrescribedVelocities());
    PetscCall(ApplyA(z_, work_));
    PetscCall(VecAYPX(work_, -1.0, f));
    PetscCall(ProjectVec(work_, rhs_, true));
  } else {
    PetscCall(ProjectVec(f, rhs_, true));
  }
  PetscCall(ProjectVec(v, w_, true));
  PetscCall(KSPSolve(inner_, rhs_, w_));
  KSPConvergedReason reason;
  PetscInt its;
  PetscCall(KSPGetConvergedReason(inner_, &reason));
  PetscCall(KSPGetIterationNumber(inner_, &its));
  PetscCheck(reason >= 0, PetscObjectComm((PetscObject)f), PETSC_ERR_NOT_CONVERGED,
             "the contact-constrained solve did not converge (%s after %" PetscInt_FMT
             " iterations)",
             KSPConvergedReasons[reason], its);
  *iterations += its;
  PetscCall(ProjectVec(w_, v, true));
  if (prescribed) PetscCall(VecAXPY(v, 1.0, z_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ProjectedSolver::SolveProjected(Vec b,
                                               const std::vector<VelocityConstraint> &constraints,
                                               Vec v, std::vector<PetscReal> *reactions,
                                               PetscInt *iterations) {
  PetscFunctionBeginUser;
  PetscCall(SolveConstrained(b, true, v, iterations));
  PetscCall(Reactions(b, v, constraints, reactions));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
