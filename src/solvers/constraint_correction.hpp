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
// CG ends in one iteration. S needs A^-1 only among the constrained DOFs: it
// comes from the block of A^-1 the projected solver keeps while A keeps its
// state (inverse_block.hpp; 3 applications of M^-1 per vertex, once, shared
// with the two-sided solve), so a vertex that stays in contact costs its 3
// applications once, and the memory grows with the constrained vertices
// squared, not with them times the unknowns. U itself is never formed: an
// application is M^-1 (w - C S^-1 C^T M^-1 w), two applications of M^-1. S
// (m^2 numbers) is factorised (dense Cholesky, m^3 / 3) per solve with new
// rows; each CG iteration adds one reduction of m numbers.
//
// The correction stands aside (the plain preconditioner is used) when the
// constrained directions exceed kMaxCorrectedRows on all ranks together, or
// the block would exceed its budget, or S is not numerically positive
// definite.
#pragma once

#include <petscksp.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <vector>

#include "solvers/inverse_block.hpp"
#include "solvers/projected_solve.hpp"

namespace softbody {

class ConstraintCorrection {
 public:
  ConstraintCorrection() = default;
  ConstraintCorrection(const ConstraintCorrection &) = delete;
  ConstraintCorrection &operator=(const ConstraintCorrection &) = delete;
  ~ConstraintCorrection();

  // Collective. For the constrained vertices of every rank (this rank's:
  // `vertices`, local numbers): their block of A^-1 (held or added to
  // `inverse`) and S's factor. solver: the set-up unconstrained KSP of A with
  // KSPPREONLY, pc its preconditioner (M^-1 = A^-1). *active: the correction
  // is ready (false: use the plain preconditioner).
  PetscErrorCode Setup(KSP solver, PC pc, Mat A, InverseBlock *inverse,
                       const std::vector<ConstrainedVertex> &vertices, bool *active);
  // Collective. y = (M^-1 - U S^-1 U^T) w (not yet projected), by two
  // applications of M^-1; after an active Setup.
  PetscErrorCode Apply(Vec w, Vec y);
  // Not collective. Applications of M^-1 spent on the block so far.
  PetscInt column_solves() const { return column_solves_; }

 private:
  // One constrained direction, every rank's, in the order all ranks share.
  struct Row {
    PetscInt vertex;  // PETSc (global) vertex number
    double direction[3];
  };
  PetscErrorCode GatherRows(Vec like, const std::vector<ConstrainedVertex> &vertices);
  PetscErrorCode FactoriseSchurComplement(const InverseBlock &inverse, bool *positive);

  PC pc_ = nullptr;  // not owned
  Mat A_ = nullptr;  // not owned
  PetscObjectState a_state_ = -1;
  std::vector<Row> rows_;
  std::vector<Row> factorised_rows_;  // the rows of schur_ (a solve with the same rows reuses it)
  std::vector<PetscInt> vertices_;    // the rows' distinct vertices, ascending
  Eigen::LLT<Eigen::MatrixXd> schur_;
  Vec residual_ = nullptr;        // Apply's w - C S^-1 C^T M^-1 w
  PetscInt begin_ = 0, end_ = 0;  // owned PETSc vertices
  PetscInt column_solves_ = 0;
};

}  // namespace softbody
