// ProjectedSolver's two paths for two-sided constraints (projected_solve.hpp):
// the Delassus path and the projected Delassus path.
#include <algorithm>
#include <cmath>
#include <map>

#include <petsc/private/petscimpl.h>  // PetscObjectStateGet: A's values changed

#include "solvers/constraint_rows.hpp"
#include "solvers/mixed_lcp.hpp"
#include "solvers/projected_solve.hpp"
#include "solvers/supernodal/supernodal.hpp"

namespace softbody {

namespace {

// The complementarity problem is solved to this fraction of the largest
// velocity it involves (m/s): far below the contact gap over a step, at the
// round-off of the back-solves that built D.
constexpr double kLcpRelativeTolerance = 1e-10;
// The Delassus path's kept columns on one rank: 3 vectors of its local size
// per vertex of the solve's rows (the constraint correction's budget). Beyond
// it, a back-solve per row.
constexpr double kDelassusColumnBudgetBytes = 256.0 * 1024 * 1024;

// Rows whose A^-1 J_j^T one application of a factorisation's PCMatApply
// solves together (on one rank the supernodal factor sweeps once per four).
constexpr PetscInt kRowsPerBatch = 16;

// Collective. partial[j m + i] = J_i A^-1 J_j^T over the owned entries for the
// rows j of [first, first + count) (count <= kRowsPerBatch), by one PCMatApply of
// the solver's PC on the columns J_j^T; B and X dense blocks of kRowsPerBatch
// columns laid out as the solver's vectors.
PetscErrorCode BatchOfRowSolves(KSP solver, const std::vector<Row> &rows, size_t first,
                                PetscInt count, PetscInt begin, PetscInt end, Mat B, Mat X,
                                double *partial, PetscInt *iterations) {
  PetscFunctionBeginUser;
  PetscInt lda;
  PetscCall(MatDenseGetLDA(B, &lda));
  PetscScalar *b;
  PetscCall(MatDenseGetArrayWrite(B, &b));
  std::fill(b, b + lda * kRowsPerBatch, 0.0);
  for (PetscInt c = 0; c < count; ++c)
    AddRowTranspose(rows[first + c], 1.0, begin, end, b + c * lda);
  PetscCall(MatDenseRestoreArrayWrite(B, &b));
  PC pc;
  PetscCall(KSPGetPC(solver, &pc));
  PetscCall(PCMatApply(pc, B, X));
  PCFailedReason failed;
  PetscCall(PCGetFailedReason(pc, &failed));
  PetscCheck(failed == PC_NOERROR, PetscObjectComm((PetscObject)solver), PETSC_ERR_NOT_CONVERGED,
             "a two-sided contact solve did not converge (%s)", PCFailedReasons[failed]);
  const PetscScalar *x;
  PetscCall(MatDenseGetLDA(X, &lda));
  PetscCall(MatDenseGetArrayRead(X, &x));
  const size_t m = rows.size();
  for (PetscInt c = 0; c < count; ++c)
    for (size_t i = 0; i < m; ++i)
      partial[(first + c) * m + i] = RowDot(rows[i], begin, end, x + c * lda);
  PetscCall(MatDenseRestoreArrayRead(X, &x));
  *iterations += count;
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. x = A^-1 y with the unconstrained solver (zero initial guess).
PetscErrorCode SolveUnconstrained(KSP solver, Vec y, Vec x, PetscInt *iterations) {
  PetscFunctionBeginUser;
  PetscCall(VecZeroEntries(x));
  PetscCall(KSPSolve(solver, y, x));
  KSPConvergedReason reason;
  PetscInt its;
  PetscCall(KSPGetConvergedReason(solver, &reason));
  PetscCall(KSPGetIterationNumber(solver, &its));
  PetscCheck(reason >= 0, PetscObjectComm((PetscObject)y), PETSC_ERR_NOT_CONVERGED,
             "a two-sided contact solve did not converge (%s after %" PetscInt_FMT " iterations)",
             KSPConvergedReasons[reason], its);
  *iterations += std::max<PetscInt>(its, 1);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// A two-sided row all of whose vertices have their whole velocity prescribed
// (three bilateral rows: the collision guard's zones) can only conflict with
// them: it leaves the problem (lambda 0). Returns the rows kept.
std::vector<Eigen::Index> KeptRows(const std::vector<Row> &rows) {
  std::map<PetscInt, int> bilateral;
  for (const Row &row : rows)
    if (!row.unilateral) ++bilateral[row.vertex[0]];
  std::vector<Eigen::Index> kept;
  for (size_t i = 0; i < rows.size(); ++i) {
    bool determined = rows[i].unilateral;
    for (int a = 0; a < 4 && determined; ++a)
      determined = rows[i].vertex[a] < 0 || rows[i].weight[a] == 0 ||
                   (bilateral.count(rows[i].vertex[a]) && bilateral[rows[i].vertex[a]] == 3);
    if (!determined) kept.push_back(static_cast<Eigen::Index>(i));
  }
  return kept;
}

// The complementarity problem of the rows `kept` (partial: D's columns j * m
// + i, then J v0 at m * m + i, reduced over the ranks); *lambda: every row's
// (0 for the rows left out). Reports the solve with PetscInfo on `object`.
PetscErrorCode SolveRows(PetscObject object, const std::vector<Row> &rows,
                         const std::vector<Eigen::Index> &kept, const std::vector<double> &partial,
                         Eigen::VectorXd *lambda) {
  PetscFunctionBeginUser;
  const Eigen::Index m = static_cast<Eigen::Index>(rows.size());
  const Eigen::Index k = static_cast<Eigen::Index>(kept.size());
  Eigen::MatrixXd D(k, k);
  Eigen::VectorXd g(k);
  std::vector<char> unilateral(k);
  double scale = 0;
  for (Eigen::Index a = 0; a < k; ++a) {
    const Eigen::Index i = kept[a];
    for (Eigen::Index c = 0; c < k; ++c)  // symmetrised: round-off of the solves
      D(a, c) = 0.5 * (partial[kept[c] * m + i] + partial[i * m + kept[c]]);
    g[a] = partial[m * m + i] - rows[i].value;
    unilateral[a] = rows[i].unilateral;
    scale = std::max({scale, std::abs(rows[i].value), std::abs(g[a])});
  }
  const MixedLcpResult lcp = SolveMixedLcp(D, g, unilateral, kLcpRelativeTolerance * scale);
  *lambda = Eigen::VectorXd::Zero(m);
  for (Eigen::Index a = 0; a < k; ++a) (*lambda)[kept[a]] = lcp.lambda[a];
  PetscCall(
      PetscInfo(object,
                "two-sided contact solve: %" PetscInt_FMT
                " rows (%d two-sided), %d sweeps, %d active-set solves, residual %g m/s (%s)\n",
                static_cast<PetscInt>(m),
                static_cast<int>(std::count(unilateral.begin(), unilateral.end(), 1)), lcp.sweeps,
                lcp.pivots, lcp.residual, lcp.exact ? "exact" : "Gauss-Seidel"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The rows' distinct vertices (those with a weight), ascending.
std::vector<PetscInt> RowVertices(const std::vector<Row> &rows) {
  std::vector<PetscInt> vertices;
  for (const Row &row : rows)
    for (int a = 0; a < 4; ++a)
      if (row.vertex[a] >= 0 && row.weight[a] != 0) vertices.push_back(row.vertex[a]);
  std::sort(vertices.begin(), vertices.end());
  vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
  return vertices;
}

// Not collective. With the supernodal factor, the batches' solves need A^-1 J_j^T
// only at the rows' vertices (RowDots reads nothing else): on (true) they
// compute those entries alone, off (false) every entry again.
PetscErrorCode SetRowTargets(KSP solver, const std::vector<Row> &rows, PetscInt begin, PetscInt end,
                             bool on) {
  PetscFunctionBeginUser;
  PC pc;
  PetscCall(KSPGetPC(solver, &pc));
  PetscBool supernodal;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCSupernodal, &supernodal));
  if (!supernodal) PetscFunctionReturn(PETSC_SUCCESS);
  std::vector<PetscInt> dofs;  // every vertex RowDot reads, its weight zero or not
  if (on)
    for (const Row &row : rows)
      for (const PetscInt p : row.vertex)
        if (p >= begin && p < end)
          for (int k = 0; k < 3; ++k) dofs.push_back(3 * (p - begin) + k);
  std::sort(dofs.begin(), dofs.end());
  dofs.erase(std::unique(dofs.begin(), dofs.end()), dofs.end());
  PetscCall(PCSupernodalSetSolveTargets(pc, static_cast<PetscInt>(dofs.size()), dofs.data()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// x = A^-1 J_row^T from the kept columns of the row's vertices.
PetscErrorCode CombineColumns(const Row &row, const std::map<PetscInt, std::array<Vec, 3>> &columns,
                              Vec x) {
  PetscFunctionBeginUser;
  std::vector<PetscScalar> weights;
  std::vector<Vec> vectors;
  for (int a = 0; a < 4; ++a) {
    if (row.vertex[a] < 0 || row.weight[a] == 0) continue;
    for (int k = 0; k < 3; ++k) {
      weights.push_back(row.weight[a] * row.direction[k]);
      vectors.push_back(columns.at(row.vertex[a])[k]);
    }
  }
  PetscCall(VecZeroEntries(x));
  PetscCall(VecMAXPY(x, static_cast<PetscInt>(vectors.size()), weights.data(), vectors.data()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

void ProjectedSolver::DropDelassusColumns(const std::vector<PetscInt> &keep) {
  for (auto it = delassus_columns_.begin(); it != delassus_columns_.end();) {
    if (std::binary_search(keep.begin(), keep.end(), it->first)) {
      ++it;
      continue;
    }
    for (Vec &column : it->second) VecDestroy(&column);
    it = delassus_columns_.erase(it);
  }
}

// A kept column is the same vector a fresh back-solve gives, and which
// columns are kept depends only on this solve's rows (the others are
// dropped), so D does not depend on the run's history: a restart continues
// bit for bit. A vertex that stays in contact costs its 3 back-solves once
// (while A keeps its values: linear mode), against one back-solve per row and
// solve without them.
PetscErrorCode ProjectedSolver::KeepDelassusColumns(KSP solver,
                                                    const std::vector<PetscInt> &vertices,
                                                    bool *ready, PetscInt *iterations) {
  PetscFunctionBeginUser;
  *ready = false;
  if (!correct_) PetscFunctionReturn(PETSC_SUCCESS);
  Mat A;
  PetscCall(KSPGetOperators(solver, &A, nullptr));
  PetscObjectState state;
  PetscCall(PetscObjectStateGet((PetscObject)A, &state));
  if (solver != delassus_solver_ || A != delassus_A_ || state != delassus_state_)
    DropDelassusColumns({});
  delassus_solver_ = solver, delassus_A_ = A, delassus_state_ = state;
  DropDelassusColumns(vertices);
  PetscInt local;
  PetscCall(VecGetLocalSize(work_, &local));
  double bytes = 3.0 * static_cast<double>(vertices.size()) * local * sizeof(PetscScalar);
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, &bytes, 1, MPI_DOUBLE, MPI_MAX,
                              PetscObjectComm((PetscObject)work_)));
  if (bytes > kDelassusColumnBudgetBytes) {  // a back-solve per row: keep nothing
    DropDelassusColumns({});
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  PetscInt begin, end;
  PetscCall(VecGetOwnershipRange(work_, &begin, &end));
  for (const PetscInt vertex : vertices) {
    if (delassus_columns_.count(vertex)) continue;
    std::array<Vec, 3> &columns = delassus_columns_[vertex];
    for (int k = 0; k < 3; ++k) {
      PetscCall(VecZeroEntries(work2_));
      if (3 * vertex >= begin && 3 * vertex < end)
        PetscCall(VecSetValue(work2_, 3 * vertex + k, 1.0, INSERT_VALUES));
      PetscCall(VecAssemblyBegin(work2_));
      PetscCall(VecAssemblyEnd(work2_));
      PetscCall(VecDuplicate(work_, &columns[k]));
      PetscCall(SolveUnconstrained(solver, work2_, columns[k], iterations));
    }
  }
  *ready = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ProjectedSolver::SolveTwoSided(KSP solver, Vec b,
                                              const std::vector<VelocityConstraint> &constraints,
                                              Vec v, std::vector<PetscReal> *reactions,
                                              PetscInt *iterations) {
  PetscFunctionBeginUser;
  RowSite site;
  PetscCall(GetRowSite(b, &site));
  const auto [comm, rank, begin, end] = site;
  std::vector<PetscInt> slot;
  const std::vector<Row> mine = LocalRows(vertices_, constraints, begin, rank, &slot);
  std::vector<Row> rows;
  PetscCall(OrderedRows(comm, mine, rank, &slot, &rows));
  const Eigen::Index m = static_cast<Eigen::Index>(rows.size());
  bool kept;
  PetscCall(KeepDelassusColumns(solver, RowVertices(rows), &kept, iterations));
  // Partial sums of D = J A^-1 J^T and of J v0 (v0 = A^-1 b) over the owned
  // entries: A^-1 J_j^T from the kept columns, else by a back-solve (with a
  // factorisation, kRowsPerBatch rows per application of it).
  std::vector<double> partial(static_cast<size_t>(m) * (m + 1), 0.0);
  bool batched = false;
  PetscCall(AppliesFactorOnce(solver, &batched));
  batched = batched && !kept && m > 0;
  if (batched) {
    Mat B, X;
    PetscInt local;
    PetscCall(VecGetLocalSize(b, &local));
    PetscCall(
        MatCreateDense(comm, local, PETSC_DECIDE, PETSC_DETERMINE, kRowsPerBatch, nullptr, &B));
    PetscCall(MatDuplicate(B, MAT_DO_NOT_COPY_VALUES, &X));
    PetscCall(SetRowTargets(solver, rows, begin, end, true));
    for (Eigen::Index j = 0; j < m; j += kRowsPerBatch)
      PetscCall(BatchOfRowSolves(solver, rows, static_cast<size_t>(j),
                                 std::min<PetscInt>(kRowsPerBatch, static_cast<PetscInt>(m - j)),
                                 begin, end, B, X, partial.data(), iterations));
    PetscCall(SetRowTargets(solver, rows, begin, end, false));
    PetscCall(MatDestroy(&B));
    PetscCall(MatDestroy(&X));
  }
  for (Eigen::Index j = batched ? m : 0; j <= m; ++j) {
    if (j < m && kept) {
      PetscCall(CombineColumns(rows[j], delassus_columns_, work_));
    } else if (j < m) {
      PetscCall(VecZeroEntries(work2_));
      PetscScalar *y;
      PetscCall(VecGetArray(work2_, &y));
      AddRowTranspose(rows[j], 1.0, begin, end, y);
      PetscCall(VecRestoreArray(work2_, &y));
      PetscCall(SolveUnconstrained(solver, work2_, work_, iterations));
    } else {
      PetscCall(SolveUnconstrained(solver, b, work_, iterations));
    }
    PetscCall(RowDots(rows, begin, end, work_, partial.data() + j * m));
  }
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, partial.data(),
                              static_cast<PetscMPIInt>(partial.size()), MPIU_REAL, MPI_SUM, comm));
  Eigen::VectorXd lambda;
  PetscCall(SolveRows((PetscObject)solver, rows, KeptRows(rows), partial, &lambda));
  // v = A^-1 (b + J^T lambda); the one-sided reactions from A v - (b + J_two^T lambda).
  PetscCall(VecCopy(b, rhs_));
  PetscCall(VecCopy(b, z_));
  PetscScalar *y, *two;
  PetscCall(VecGetArray(rhs_, &y));
  PetscCall(VecGetArray(z_, &two));
  for (Eigen::Index j = 0; j < m; ++j) {
    AddRowTranspose(rows[j], lambda[j], begin, end, y);
    if (rows[j].unilateral) AddRowTranspose(rows[j], lambda[j], begin, end, two);
  }
  PetscCall(VecRestoreArray(rhs_, &y));
  PetscCall(VecRestoreArray(z_, &two));
  PetscCall(SolveUnconstrained(solver, rhs_, v, iterations));
  PetscCall(Reactions(z_, v, constraints, reactions));
  for (size_t i = 0; i < constraints.size(); ++i)
    if (slot[i] >= 0) (*reactions)[i] = lambda[slot[i]];
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ProjectedSolver::SolveTwoSidedProjected(
    KSP solver, Vec b, const std::vector<VelocityConstraint> &constraints, Vec v,
    std::vector<PetscReal> *reactions, PetscInt *iterations) {
  PetscFunctionBeginUser;
  RowSite site;
  PetscCall(GetRowSite(b, &site));
  const auto [comm, rank, begin, end] = site;
  std::vector<PetscInt> slot;
  const std::vector<Row> mine = LocalRows({}, constraints, begin, rank, &slot);  // J_2's rows
  std::vector<Row> rows;
  PetscCall(OrderedRows(comm, mine, rank, &slot, &rows));
  const Eigen::Index m = static_cast<Eigen::Index>(rows.size());
  // v0 = S(b) (from the guess v), then the columns G J_2j^T: partial sums of
  // D_2 = J_2 G J_2^T and of J_2 v0 over the owned entries.
  std::vector<double> partial(static_cast<size_t>(m) * (m + 1), 0.0);
  PetscCall(SolveConstrained(b, true, v, iterations));
  PetscCall(RowDots(rows, begin, end, v, partial.data() + m * m));
  for (Eigen::Index j = 0; j < m; ++j) {
    PetscCall(VecZeroEntries(column_rhs_));
    PetscScalar *y;
    PetscCall(VecGetArray(column_rhs_, &y));
    AddRowTranspose(rows[j], 1.0, begin, end, y);
    PetscCall(VecRestoreArray(column_rhs_, &y));
    PetscCall(VecZeroEntries(column_));
    PetscCall(SolveConstrained(column_rhs_, false, column_, iterations));
    PetscCall(RowDots(rows, begin, end, column_, partial.data() + j * m));
  }
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, partial.data(),
                              static_cast<PetscMPIInt>(partial.size()), MPIU_REAL, MPI_SUM, comm));
  // A row whose vertices are all held has a zero column (P removes them): it
  // can only conflict with the one-sided constraints and leaves (lambda 0).
  std::vector<Eigen::Index> kept;
  for (Eigen::Index i = 0; i < m; ++i)
    if (partial[i * m + i] > 0) kept.push_back(i);
  Eigen::VectorXd lambda;
  PetscCall(SolveRows((PetscObject)solver, rows, kept, partial, &lambda));
  // v = S(b + J_2^T lambda) from v0; the one-sided reactions from A v - (b + J_2^T lambda).
  PetscCall(VecCopy(b, column_rhs_));
  PetscScalar *y;
  PetscCall(VecGetArray(column_rhs_, &y));
  for (Eigen::Index j = 0; j < m; ++j) AddRowTranspose(rows[j], lambda[j], begin, end, y);
  PetscCall(VecRestoreArray(column_rhs_, &y));
  PetscCall(SolveConstrained(column_rhs_, true, v, iterations));
  PetscCall(Reactions(column_rhs_, v, constraints, reactions));
  for (size_t i = 0; i < constraints.size(); ++i)
    if (slot[i] >= 0) (*reactions)[i] = lambda[slot[i]];
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
