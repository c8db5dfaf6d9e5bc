#include "solvers/constraint_correction.hpp"

#include <petsc/private/petscimpl.h>  // PetscObjectStateGet: A's values changed

#include <algorithm>

#include "common/exchange.hpp"

namespace softbody {

namespace {

// S is m x m and factorised in m^3 / 3 flops per solve with new rows.
// Measured on the bunny drop (linear, 1 rank; 100 to 700 directions, most of
// them the guard's held vertices): capped at 100, 200, 400 and 800
// directions, a contact step took 17.7, 16.7, 16.8 and 15.2 ms of CPU (17.7
// ms without the correction): the factorisation of S costs less than the ~20
// CG iterations it saves. Above 1 000 it was not kept: a 2 x 0.25 x 2 m slab
// of 5e4 tets resting on the ground (1 764 directions, 1 rank) took 62.8
// plain iterations per step (423 ms), against 1.1 with the correction after
// 5 292 back-solves for its block (28 s) and 920 MB instead of 247 MB peak:
// the block would pay only after about 70 steps.
constexpr PetscInt kMaxCorrectedRows = 1000;

}  // namespace

ConstraintCorrection::~ConstraintCorrection() {
  VecDestroy(&residual_);
}

PetscErrorCode ConstraintCorrection::GatherRows(Vec like,
                                                const std::vector<ConstrainedVertex> &vertices) {
  PetscFunctionBeginUser;
  PetscInt begin, end;
  PetscCall(VecGetOwnershipRange(like, &begin, &end));
  begin_ = begin / 3, end_ = end / 3;
  std::vector<Row> mine;
  for (const ConstrainedVertex &c : vertices)
    for (int j = 0; j < c.rank; ++j)
      mine.push_back({begin_ + c.vertex, {c.basis(0, j), c.basis(1, j), c.basis(2, j)}});
  PetscCall(AllGatherRecords(PetscObjectComm((PetscObject)like), mine, &rows_));
  std::stable_sort(rows_.begin(), rows_.end(),
                   [](const Row &a, const Row &b) { return a.vertex < b.vertex; });
  vertices_.clear();
  for (const Row &row : rows_)
    if (vertices_.empty() || vertices_.back() != row.vertex) vertices_.push_back(row.vertex);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// S_ij = c_i^T B c_j, B the block of A^-1 between the rows' vertices (the
// same numbers on every rank).
PetscErrorCode ConstraintCorrection::FactoriseSchurComplement(const InverseBlock &inverse,
                                                              bool *positive) {
  PetscFunctionBeginUser;
  const Eigen::Index m = static_cast<Eigen::Index>(rows_.size());
  const Eigen::MatrixXd &B = inverse.block();
  Eigen::MatrixXd S(m, m);
  for (Eigen::Index j = 0; j < m; ++j) {
    const Eigen::Map<const Eigen::Vector3d> cj(rows_[j].direction);
    const Eigen::Index sj = inverse.slot(rows_[j].vertex);
    for (Eigen::Index i = 0; i < m; ++i) {
      const Eigen::Map<const Eigen::Vector3d> ci(rows_[i].direction);
      S(i, j) = ci.dot(B.block<3, 3>(inverse.slot(rows_[i].vertex), sj) * cj);
    }
  }
  S = 0.5 * (S + S.transpose()).eval();  // symmetric up to the round-off of M^-1
  schur_.compute(S);
  *positive = schur_.info() == Eigen::Success;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ConstraintCorrection::Setup(KSP solver, PC pc, Mat A, InverseBlock *inverse,
                                           const std::vector<ConstrainedVertex> &vertices,
                                           bool *active) {
  PetscFunctionBeginUser;
  *active = false;
  PetscObjectState state;
  PetscCall(PetscObjectStateGet((PetscObject)A, &state));
  if (pc != pc_ || A != A_ || state != a_state_) factorised_rows_.clear();  // new M^-1: new S
  pc_ = pc, A_ = A, a_state_ = state;
  Vec like;
  PetscCall(MatCreateVecs(A, &like, nullptr));
  PetscCall(GatherRows(like, vertices));
  const PetscInt m = static_cast<PetscInt>(rows_.size());
  bool ready = m > 0 && m <= kMaxCorrectedRows;
  if (ready) {
    PetscCall(inverse->Refresh(solver));
    std::vector<PetscInt> missing;
    for (const PetscInt vertex : vertices_)
      if (!inverse->holds(vertex)) missing.push_back(vertex);
    PetscCall(inverse->Add(like, missing, vertices_, &ready, &column_solves_));
  }
  PetscCall(VecDestroy(&like));
  const bool same_rows =
      ready && factorised_rows_.size() == rows_.size() &&
      std::equal(rows_.begin(), rows_.end(), factorised_rows_.begin(),
                 [](const Row &a, const Row &b) {
                   return a.vertex == b.vertex && a.direction[0] == b.direction[0] &&
                          a.direction[1] == b.direction[1] && a.direction[2] == b.direction[2];
                 });
  if (ready && !same_rows) {
    factorised_rows_.clear();
    PetscCall(FactoriseSchurComplement(*inverse, &ready));  // the same S on every rank
    if (ready) factorised_rows_ = rows_;
  }
  *active = ready;
  PetscFunctionReturn(PETSC_SUCCESS);
}

// y = M^-1 (w - C S^-1 C^T M^-1 w) = M^-1 w - U S^-1 U^T w: two applications
// of M^-1 and sparse work at the constrained vertices (cheaper than adding the
// 3 columns of each constrained vertex when they are more than a few).
PetscErrorCode ConstraintCorrection::Apply(Vec w, Vec y) {
  PetscFunctionBeginUser;
  if (!residual_) PetscCall(VecDuplicate(w, &residual_));
  PetscCall(PCApply(pc_, w, y));
  const Eigen::Index m = static_cast<Eigen::Index>(rows_.size());
  Eigen::VectorXd t = Eigen::VectorXd::Zero(m);
  const PetscScalar *values;
  PetscCall(VecGetArrayRead(y, &values));
  for (Eigen::Index i = 0; i < m; ++i) {
    const Row &row = rows_[i];
    if (row.vertex < begin_ || row.vertex >= end_) continue;
    const PetscInt at = 3 * (row.vertex - begin_);
    for (int c = 0; c < 3; ++c) t[i] += row.direction[c] * values[at + c];
  }
  PetscCall(VecRestoreArrayRead(y, &values));
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, t.data(), static_cast<PetscMPIInt>(m), MPIU_REAL,
                              MPI_SUM, PetscObjectComm((PetscObject)w)));
  const Eigen::VectorXd s = schur_.solve(t);
  PetscCall(VecCopy(w, residual_));
  PetscScalar *r;
  PetscCall(VecGetArray(residual_, &r));
  for (Eigen::Index i = 0; i < m; ++i) {
    const Row &row = rows_[i];
    if (row.vertex < begin_ || row.vertex >= end_) continue;
    const PetscInt at = 3 * (row.vertex - begin_);
    for (int c = 0; c < 3; ++c) r[at + c] -= s[i] * row.direction[c];
  }
  PetscCall(VecRestoreArray(residual_, &r));
  PetscCall(PCApply(pc_, residual_, y));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
