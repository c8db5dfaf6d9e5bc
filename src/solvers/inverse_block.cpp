#include "solvers/inverse_block.hpp"

#include <petsc/private/petscimpl.h>  // PetscObjectStateGet: A's values changed

#include <algorithm>
#include <unordered_set>

namespace softbody {

namespace {

// The block on every rank: 512 MB holds about 2 600 vertices, enough for a
// box of 2.5e4 tets resting flat on another (2 004 rows over 2 100 vertices,
// 320 MB), whose Delassus solve otherwise costs a back-solve per row in every
// solve (20 s per step at 5e4 tets, one rank).
constexpr double kBlockBudgetBytes = 512.0 * 1024 * 1024;

// New vertices are added in chunks whose columns (every held DOF by the
// chunk's DOFs, summed over the ranks in one reduction) stay below this.
constexpr double kChunkBytes = 32.0 * 1024 * 1024;

double BlockBytes(size_t vertices) {
  return 9.0 * static_cast<double>(vertices) * static_cast<double>(vertices) * sizeof(double);
}

}  // namespace

PetscErrorCode InverseBlock::Refresh(KSP solver) {
  PetscFunctionBeginUser;
  Mat A;
  PetscCall(KSPGetOperators(solver, &A, nullptr));
  PetscObjectState state;
  PetscCall(PetscObjectStateGet((PetscObject)A, &state));
  if (solver != solver_ || A != A_ || state != a_state_) Retain({});
  solver_ = solver, A_ = A, a_state_ = state;
  PetscFunctionReturn(PETSC_SUCCESS);
}

void InverseBlock::Retain(const std::vector<PetscInt> &keep) {
  const std::unordered_set<PetscInt> wanted(keep.begin(), keep.end());
  std::vector<Eigen::Index> from;  // old first rows of the kept vertices
  std::vector<PetscInt> held;
  for (const PetscInt vertex : held_)
    if (wanted.count(vertex)) held.push_back(vertex), from.push_back(slot_.at(vertex));
  const Eigen::Index n = 3 * static_cast<Eigen::Index>(held.size());
  Eigen::MatrixXd block(n, n);
  for (size_t b = 0; b < held.size(); ++b)
    for (size_t a = 0; a < held.size(); ++a)
      block.block<3, 3>(3 * a, 3 * b) = block_.block<3, 3>(from[a], from[b]);
  block_.swap(block);
  held_.swap(held);
  slot_.clear();
  for (size_t a = 0; a < held_.size(); ++a) slot_[held_[a]] = 3 * static_cast<Eigen::Index>(a);
}

PetscErrorCode InverseBlock::Add(Vec like, const std::vector<PetscInt> &vertices,
                                 const std::vector<PetscInt> &keep, bool *added, PetscInt *solves) {
  PetscFunctionBeginUser;
  *added = vertices.empty();
  if (*added) PetscFunctionReturn(PETSC_SUCCESS);
  if (BlockBytes(held_.size() + vertices.size()) > kBlockBudgetBytes) Retain(keep);
  if (BlockBytes(held_.size() + vertices.size()) > kBlockBudgetBytes)
    PetscFunctionReturn(PETSC_SUCCESS);
  const double column_bytes = 3.0 * (held_.size() + vertices.size()) * sizeof(double);
  const size_t chunk = std::max<size_t>(1, static_cast<size_t>(kChunkBytes / (3 * column_bytes)));
  for (size_t first = 0; first < vertices.size(); first += chunk) {
    const std::vector<PetscInt> part(vertices.begin() + first,
                                     vertices.begin() + std::min(vertices.size(), first + chunk));
    PetscCall(AddChunk(like, part, solves));
  }
  *added = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode InverseBlock::AddChunk(Vec like, const std::vector<PetscInt> &vertices,
                                      PetscInt *solves) {
  PetscFunctionBeginUser;
  const Eigen::Index old = 3 * static_cast<Eigen::Index>(held_.size());
  const Eigen::Index fresh = 3 * static_cast<Eigen::Index>(vertices.size());
  std::vector<PetscInt> all = held_;  // slot order after the addition
  all.insert(all.end(), vertices.begin(), vertices.end());
  PetscInt begin, end;
  PetscCall(VecGetOwnershipRange(like, &begin, &end));
  begin /= 3, end /= 3;
  // Columns A^-1 e of the new DOFs at every held DOF: this rank's entries,
  // then summed over the ranks (one owner per entry).
  Eigen::MatrixXd columns = Eigen::MatrixXd::Zero(old + fresh, fresh);
  Vec unit, x;
  PetscCall(VecDuplicate(like, &unit));
  PetscCall(VecDuplicate(like, &x));
  for (Eigen::Index c = 0; c < fresh; ++c) {
    const PetscInt vertex = vertices[c / 3];
    PetscCall(VecZeroEntries(unit));
    if (vertex >= begin && vertex < end)
      PetscCall(VecSetValue(unit, 3 * vertex + c % 3, 1.0, INSERT_VALUES));
    PetscCall(VecAssemblyBegin(unit));
    PetscCall(VecAssemblyEnd(unit));
    PetscCall(KSPSolve(solver_, unit, x));
    KSPConvergedReason reason;
    PetscCall(KSPGetConvergedReason(solver_, &reason));
    PetscCheck(reason >= 0, PetscObjectComm((PetscObject)like), PETSC_ERR_NOT_CONVERGED,
               "a column of A^-1 for the two-sided contact solve did not converge (%s)",
               KSPConvergedReasons[reason]);
    ++*solves;
    const PetscScalar *values;
    PetscCall(VecGetArrayRead(x, &values));
    for (size_t a = 0; a < all.size(); ++a)
      if (all[a] >= begin && all[a] < end)
        for (int k = 0; k < 3; ++k) columns(3 * a + k, c) = values[3 * (all[a] - begin) + k];
    PetscCall(VecRestoreArrayRead(x, &values));
  }
  PetscCall(VecDestroy(&unit));
  PetscCall(VecDestroy(&x));
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, columns.data(),
                              static_cast<PetscMPIInt>(columns.size()), MPIU_REAL, MPI_SUM,
                              PetscObjectComm((PetscObject)like)));
  block_.conservativeResize(old + fresh, old + fresh);
  block_.topRightCorner(old, fresh) = columns.topRows(old);
  block_.bottomLeftCorner(fresh, old) = columns.topRows(old).transpose();
  const Eigen::MatrixXd corner = columns.bottomRows(fresh);
  block_.bottomRightCorner(fresh, fresh) = 0.5 * (corner + corner.transpose());  // round-off
  for (const PetscInt vertex : vertices) {
    slot_[vertex] = 3 * static_cast<Eigen::Index>(held_.size());
    held_.push_back(vertex);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
