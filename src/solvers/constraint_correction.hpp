// The constraint correction of the projected CG's preconditioner
// (projected_solve.hpp): a preconditioner that sees the constraints.
//
// The projected CG solves (P A P + I - P) w = r, P = I - C C^T removing the
// constrained directions C (n x m, orthonormal: each constrained vertex's basis
// of its constraint directions, ConstrainedVertex). Its plain preconditioner
// P M^-1 P + I - P, M^-1 the unconstrained solver's, needs about one CG
// iteration per constraint even when M = A (a rank-m perturbation of the
// exact inverse). The corrected one uses the inverse of A restricted to the
// free directions, written with M^-1 (Schur complement on the constraints):
//
//     G = M^-1 - U S^-1 U^T,   U = M^-1 C (n x m),   S = C^T M^-1 C (m x m),
//
// C^T G = 0 and G P = G, and the preconditioner is P G P + I - P. When M = A
// (a factorisation of A), it is the exact inverse of the projected operator:
// CG ends in one iteration. The columns U come from M^-1 applied to the unit
// vectors of the constrained vertices' three DOFs (3 per vertex, whatever its
// directions): they are kept, per vertex, while A and the preconditioner keep
// their state (linear mode: the whole run), so a vertex that stays in contact
// costs its 3 applications of M^-1 once. S is formed from them (m^2 numbers
// summed over the ranks) and factorised (dense Cholesky, m^3 / 3) per solve;
// each CG iteration adds one reduction of m numbers and 3 axpys per
// constrained vertex.
//
// The correction stands aside (the plain preconditioner is used) when the
// constrained directions exceed kMaxCorrectedRows on all ranks together, or
// the columns would exceed kColumnBudgetBytes on some rank, or S is not
// numerically positive definite.
#pragma once

#include <petscksp.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <array>
#include <map>
#include <vector>

#include "solvers/projected_solve.hpp"

namespace softbody {

class ConstraintCorrection {
 public:
  ConstraintCorrection() = default;
  ConstraintCorrection(const ConstraintCorrection &) = delete;
  ConstraintCorrection &operator=(const ConstraintCorrection &) = delete;
  ~ConstraintCorrection();

  // Collective. For the constrained vertices of every rank (this rank's:
  // `vertices`, local numbers): the columns (cached or new) and S's factor.
  // pc: the set-up unconstrained preconditioner (M^-1) of A. *active: the
  // correction is ready (false: use the plain preconditioner).
  PetscErrorCode Setup(PC pc, Mat A, const std::vector<ConstrainedVertex> &vertices, bool *active);
  // Collective. y = (M^-1 - U S^-1 U^T) w (not yet projected), by two
  // applications of M^-1; after an active Setup.
  PetscErrorCode Apply(Vec w, Vec y);
  // Not collective. Applications of M^-1 spent on columns so far.
  PetscInt column_solves() const { return column_solves_; }

 private:
  // One constrained direction, every rank's, in the order all ranks share.
  struct Row {
    PetscInt vertex;  // PETSc (global) vertex number
    double direction[3];
  };
  PetscErrorCode GatherRows(Vec like, const std::vector<ConstrainedVertex> &vertices);
  PetscErrorCode ComputeColumns(Vec like, bool *within_budget);
  PetscErrorCode FactoriseSchurComplement(bool *positive);
  void Clear();

  PC pc_ = nullptr;  // not owned
  Mat A_ = nullptr;  // not owned
  PetscObjectState a_state_ = -1;
  // Per PETSc vertex: M^-1 e_{3 vertex + k}, k = 0..2.
  std::map<PetscInt, std::array<Vec, 3>> columns_;
  std::vector<Row> rows_;
  std::vector<Row> factorised_rows_;  // the rows of schur_ (a solve with the same rows reuses it)
  std::vector<PetscInt> vertices_;    // the rows' distinct vertices, ascending
  Eigen::LLT<Eigen::MatrixXd> schur_;
  Vec residual_ = nullptr;        // Apply's w - C S^-1 C^T M^-1 w
  PetscInt begin_ = 0, end_ = 0;  // owned PETSc vertices
  PetscInt column_solves_ = 0;
};

}  // namespace softbody
