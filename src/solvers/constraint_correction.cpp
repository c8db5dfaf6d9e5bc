#include "solvers/constraint_correction.hpp"

#include <petsc/private/petscimpl.h>  // PetscObjectStateGet: A's values changed

#include <algorithm>

#include "common/exchange.hpp"

namespace softbody {

namespace {

// S is m x m, formed from m^2 numbers summed over the ranks (8 MB at this
// size) and factorised in m^3 / 3 flops per solve with new rows. Measured on
// the bunny drop (linear, 1 rank; 100 to 700 directions, most of them the
// guard's held vertices): capped at 100, 200, 400 and 800 directions, a
// contact step took 17.7, 16.7, 16.8 and 15.2 ms of CPU (17.7 ms without the
// correction): the factorisation of S costs less than the ~20 CG iterations it saves.
constexpr PetscInt kMaxCorrectedRows = 1000;
// The columns one rank keeps: 3 vectors of its local size per vertex ever
// constrained while A keeps its state. Beyond this many bytes the correction
// stands aside.
constexpr double kColumnBudgetBytes = 256.0 * 1024 * 1024;

}  // namespace

ConstraintCorrection::~ConstraintCorrection() {
  Clear();
}

void ConstraintCorrection::Clear() {
  for (auto &[vertex, columns] : columns_)
    for (Vec &column : columns) VecDestroy(&column);
  columns_.clear();
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

// Every rank loops over the same vertices (collective applications of M^-1).
PetscErrorCode ConstraintCorrection::ComputeColumns(Vec like, bool *within_budget) {
  PetscFunctionBeginUser;
  PetscInt local;
  PetscCall(VecGetLocalSize(like, &local));
  size_t missing = 0;
  for (const PetscInt vertex : vertices_) missing += columns_.count(vertex) == 0;
  double bytes = 3.0 * (columns_.size() + missing) * local * sizeof(PetscScalar);
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, &bytes, 1, MPI_DOUBLE, MPI_MAX,
                              PetscObjectComm((PetscObject)like)));
  *within_budget = bytes <= kColumnBudgetBytes;
  if (!*within_budget) PetscFunctionReturn(PETSC_SUCCESS);
  Vec unit;
  PetscCall(VecDuplicate(like, &unit));
  for (const PetscInt vertex : vertices_) {
    if (columns_.count(vertex)) continue;
    std::array<Vec, 3> &columns = columns_[vertex];
    for (int k = 0; k < 3; ++k) {
      PetscCall(VecZeroEntries(unit));
      if (vertex >= begin_ && vertex < end_)
        PetscCall(VecSetValue(unit, 3 * vertex + k, 1.0, INSERT_VALUES));
      PetscCall(VecAssemblyBegin(unit));
      PetscCall(VecAssemblyEnd(unit));
      PetscCall(VecDuplicate(like, &columns[k]));
      PetscCall(PCApply(pc_, unit, columns[k]));
      ++column_solves_;
    }
  }
  PetscCall(VecDestroy(&unit));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// S_ij = c_i^T M^-1 c_j = c_i^T U_j at row i's vertex, on the rank that owns
// it; summed over the ranks. Per column j, U_j is first formed at this rank's
// constrained vertices only (3 numbers each), then dotted with the rows.
PetscErrorCode ConstraintCorrection::FactoriseSchurComplement(bool *positive) {
  PetscFunctionBeginUser;
  const Eigen::Index m = static_cast<Eigen::Index>(rows_.size());
  std::vector<size_t> owned;  // slots of vertices_ this rank owns
  std::vector<Eigen::Index> slot_of_row(m);
  for (size_t slot = 0, j = 0; slot < vertices_.size(); ++slot) {
    if (vertices_[slot] >= begin_ && vertices_[slot] < end_) owned.push_back(slot);
    for (; j < static_cast<size_t>(m) && rows_[j].vertex == vertices_[slot]; ++j)
      slot_of_row[j] = static_cast<Eigen::Index>(slot);
  }
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(m, m);
  Eigen::Matrix3Xd at_vertices(3, vertices_.size());  // U_j at the owned constrained vertices
  for (Eigen::Index j = 0; j < m; ++j) {
    const std::array<Vec, 3> &columns = columns_.at(rows_[j].vertex);
    const PetscScalar *values[3];
    for (int k = 0; k < 3; ++k) PetscCall(VecGetArrayRead(columns[k], &values[k]));
    for (const size_t slot : owned) {
      const PetscInt at = 3 * (vertices_[slot] - begin_);
      for (int c = 0; c < 3; ++c)
        at_vertices(c, slot) = rows_[j].direction[0] * values[0][at + c] +
                               rows_[j].direction[1] * values[1][at + c] +
                               rows_[j].direction[2] * values[2][at + c];
    }
    for (int k = 0; k < 3; ++k) PetscCall(VecRestoreArrayRead(columns[k], &values[k]));
    for (Eigen::Index i = 0; i < m; ++i) {
      const Row &row = rows_[i];
      if (row.vertex < begin_ || row.vertex >= end_) continue;
      const auto u = at_vertices.col(slot_of_row[i]);
      S(i, j) = row.direction[0] * u[0] + row.direction[1] * u[1] + row.direction[2] * u[2];
    }
  }
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, S.data(), static_cast<PetscMPIInt>(S.size()), MPIU_REAL,
                              MPI_SUM, PetscObjectComm((PetscObject)A_)));
  S = 0.5 * (S + S.transpose()).eval();  // symmetric up to the round-off of M^-1
  schur_.compute(S);
  *positive = schur_.info() == Eigen::Success;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ConstraintCorrection::Setup(PC pc, Mat A,
                                           const std::vector<ConstrainedVertex> &vertices,
                                           bool *active) {
  PetscFunctionBeginUser;
  *active = false;
  PetscObjectState state;
  PetscCall(PetscObjectStateGet((PetscObject)A, &state));
  if (pc != pc_ || A != A_ || state != a_state_) {  // new M^-1: new columns and S
    Clear();
    factorised_rows_.clear();
  }
  pc_ = pc, A_ = A, a_state_ = state;
  Vec like;
  PetscCall(MatCreateVecs(A, &like, nullptr));
  PetscCall(GatherRows(like, vertices));
  const PetscInt m = static_cast<PetscInt>(rows_.size());
  bool ready = m > 0 && m <= kMaxCorrectedRows;
  if (ready) PetscCall(ComputeColumns(like, &ready));
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
    PetscCall(FactoriseSchurComplement(&ready));  // the same S on every rank
    if (ready) factorised_rows_ = rows_;
  }
  if (!ready) PetscFunctionReturn(PETSC_SUCCESS);
  *active = true;
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
