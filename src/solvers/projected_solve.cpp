#include "solvers/projected_solve.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <map>

namespace softbody {

ProjectedSolver::~ProjectedSolver() {
  KSPDestroy(&inner_);
  MatDestroy(&shell_);
  VecDestroy(&work_);
  VecDestroy(&work2_);
  VecDestroy(&z_);
  VecDestroy(&rhs_);
  VecDestroy(&w_);
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
  const int k = static_cast<int>(std::min<size_t>(constraints.size(), 6));
  // Candidate active sets S (bit masks), each solved exactly: p = least-norm
  // solution of N_S^T p = c_S, in span(N_S).
  ConstrainedVertex best{vertex, Eigen::Matrix3d::Zero(), 0, Eigen::Vector3d::Zero()};
  double best_violation = 1e300, best_norm = 1e300;
  int best_size = 0, best_immobile = 0;
  for (int mask = 1; mask < (1 << k); ++mask) {
    Eigen::Matrix3d N = Eigen::Matrix3d::Zero();
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    int members = 0;
    for (int j = 0; j < k; ++j) members += (mask >> j) & 1;
    if (members > 3) continue;  // at most three independent directions
    int size = 0, immobile = 0;
    for (int j = 0; j < k; ++j)
      if (mask & (1 << j)) {
        N.col(size) = constraints[j].normal;
        c[size++] = constraints[j].velocity;
        immobile += constraints[j].immobile;
      }
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(N.leftCols(size),
                                                Eigen::ComputeThinU | Eigen::ComputeThinV);
    if (svd.singularValues()[size - 1] < kMinSeparation) continue;  // near-parallel directions
    const Eigen::Vector3d p =
        N.leftCols(size).transpose().completeOrthogonalDecomposition().solve(c.head(size));
    double violation = 0, scale = 0;
    for (int j = 0; j < k; ++j) {
      violation = std::max(violation, constraints[j].velocity - constraints[j].normal.dot(p));
      scale = std::max(scale, std::abs(constraints[j].velocity));
    }
    violation = std::max(violation, 1e-12 * scale);  // round-off counts as kept
    const double norm = p.norm();
    const bool better =
        violation < best_violation ||
        (violation == best_violation &&
         (size > best_size ||
          (size == best_size &&
           (immobile > best_immobile || (immobile == best_immobile && norm < best_norm)))));
    if (!better) continue;
    best_violation = violation;
    best_norm = norm;
    best_size = size;
    best_immobile = immobile;
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

// y = P A P w + (I - P) w
PetscErrorCode ProjectedSolver::ApplyOperator(Mat shell, Vec w, Vec y) {
  PetscFunctionBeginUser;
  ProjectedSolver *self;
  PetscCall(MatShellGetContext(shell, &self));
  PetscCall(self->ProjectVec(w, self->work_, true));
  PetscCall(MatMult(self->A_, self->work_, self->work2_));
  PetscCall(self->ProjectVec(self->work2_, y, true));
  PetscCall(self->ProjectVec(w, self->work_, false));
  PetscCall(VecAXPY(y, 1.0, self->work_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// y = P M^-1 P w + (I - P) w
PetscErrorCode ProjectedSolver::ApplyPreconditioner(PC shell, Vec w, Vec y) {
  PetscFunctionBeginUser;
  ProjectedSolver *self;
  PetscCall(PCShellGetContext(shell, &self));
  PetscCall(self->ProjectVec(w, self->work_, true));
  PetscCall(PCApply(self->unconstrained_pc_, self->work_, self->work2_));
  PetscCall(self->ProjectVec(self->work2_, y, true));
  PetscCall(self->ProjectVec(w, self->work_, false));
  PetscCall(VecAXPY(y, 1.0, self->work_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ProjectedSolver::Solve(KSP solver, Vec b,
                                      const std::vector<VelocityConstraint> &constraints, Vec v,
                                      std::vector<PetscReal> *reactions, PetscInt *iterations) {
  PetscFunctionBeginUser;
  PetscCall(KSPSetUp(solver));  // refreshes the preconditioner if A changed
  PetscCall(KSPGetOperators(solver, &A_, nullptr));
  PetscCall(KSPGetPC(solver, &unconstrained_pc_));
  GroupByVertex(constraints);
  if (!inner_) {
    PetscInt n, N;
    PetscCall(VecGetLocalSize(b, &n));
    PetscCall(VecGetSize(b, &N));
    for (Vec *work : {&work_, &work2_, &z_, &rhs_, &w_}) PetscCall(VecDuplicate(b, work));
    PetscCall(MatCreateShell(PetscObjectComm((PetscObject)b), n, n, N, N, this, &shell_));
    PetscCall(MatShellSetOperation(shell_, MATOP_MULT, (void (*)(void))ApplyOperator));
    PetscCall(KSPCreate(PetscObjectComm((PetscObject)b), &inner_));
    PetscCall(KSPSetOptionsPrefix(inner_, "contact_"));
    PetscCall(KSPSetType(inner_, KSPCG));
    // No divergence test: at rest b is tiny next to the warm start's residual.
    PetscCall(KSPSetTolerances(inner_, 1e-10, PETSC_DEFAULT, 1e300, 10000));
    PetscCall(KSPSetOperators(inner_, shell_, shell_));
    PC pc;
    PetscCall(KSPGetPC(inner_, &pc));
    PetscCall(PCSetType(pc, PCSHELL));
    PetscCall(PCShellSetContext(pc, this));
    PetscCall(PCShellSetApply(pc, ApplyPreconditioner));
    PetscCall(PCShellSetName(pc, "P M^-1 P + I - P"));
    PetscCall(KSPSetInitialGuessNonzero(inner_, PETSC_TRUE));
    PetscCall(KSPSetFromOptions(inner_));
  }
  // z: the prescribed normal velocities; rhs = P (b - A z); w from the guess.
  PetscCall(VecZeroEntries(z_));
  PetscScalar *z;
  PetscCall(VecGetArray(z_, &z));
  for (const ConstrainedVertex &c : vertices_)
    for (int k = 0; k < 3; ++k) z[3 * c.vertex + k] = c.prescribed[k];
  PetscCall(VecRestoreArray(z_, &z));
  PetscCall(MatMult(A_, z_, work_));
  PetscCall(VecAYPX(work_, -1.0, b));
  PetscCall(ProjectVec(work_, rhs_, true));
  PetscCall(ProjectVec(v, w_, true));
  PetscCall(KSPSolve(inner_, rhs_, w_));
  KSPConvergedReason reason;
  PetscCall(KSPGetConvergedReason(inner_, &reason));
  PetscCall(KSPGetIterationNumber(inner_, iterations));
  PetscCheck(reason >= 0, PetscObjectComm((PetscObject)b), PETSC_ERR_NOT_CONVERGED,
             "the contact-constrained solve did not converge (%s after %" PetscInt_FMT
             " iterations)",
             KSPConvergedReasons[reason], *iterations);
  // v = P w + z; reactions from A v - b.
  PetscCall(ProjectVec(w_, v, true));
  PetscCall(VecAXPY(v, 1.0, z_));
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

}  // namespace softbody
