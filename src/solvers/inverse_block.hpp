// The entries of A^-1 among the DOFs of a set of vertices, kept while A keeps
// its values: the Delassus path's back-solves for rows that recur
// (two_sided_solve.cpp).
//
// The Delassus operator D = J A^-1 J^T needs A^-1 only between the DOFs its
// rows touch (a row: a direction on a vertex and, when two-sided, on the three
// vertices of a face). With B = (A^-1)_{II}, I the DOFs of the held vertices
// (3 per vertex), a row's D entries follow from B without a solve:
// D_ij = r_i^T B r_j, r_i row i's (at most 12) weights at I. A vertex costs 3
// back-solves (A^-1 e for its three DOFs), once while A keeps its state; a
// resting contact of hundreds of rows then costs no back-solve per solve
// instead of one per row. B is dense (3N x 3N for N vertices), replicated on
// every rank (each entry summed from its owning rank alone, so every rank has
// the same numbers), and capped at kBlockBudgetBytes (inverse_block.cpp).
//
// Which vertices are held is the caller's choice (Add); Refresh forgets them
// when A or the solver changed.
#pragma once

#include <petscksp.h>

#include <Eigen/Core>
#include <unordered_map>
#include <vector>

namespace softbody {

class InverseBlock {
 public:
  // Collective. Forgets every vertex when the solver or A (its values) changed
  // since the last call.
  PetscErrorCode Refresh(KSP solver);
  // Collective (the same `vertices` on every rank: PETSc vertex numbers, not
  // yet held). Holds them, with 3 back-solves each, and first lets go of the
  // held vertices outside `keep` when the block would exceed its budget.
  // *added: false when even then it would (nothing added). `like`: a vector
  // of A's layout; *solves: back-solves spent.
  PetscErrorCode Add(Vec like, const std::vector<PetscInt> &vertices,
                     const std::vector<PetscInt> &keep, bool *added, PetscInt *solves);
  bool holds(PetscInt vertex) const { return slot_.count(vertex) > 0; }
  // The first row of the vertex's 3 DOFs in block(); the vertex is held.
  Eigen::Index slot(PetscInt vertex) const { return slot_.at(vertex); }
  // (A^-1)_{II}, symmetric, 3 rows per held vertex.
  const Eigen::MatrixXd &block() const { return block_; }

 private:
  // Keeps only the held vertices in `keep` (block compacted).
  void Retain(const std::vector<PetscInt> &keep);
  // Collective. Add's solves and block growth for some of its vertices.
  PetscErrorCode AddChunk(Vec like, const std::vector<PetscInt> &vertices, PetscInt *solves);

  KSP solver_ = nullptr;  // not owned
  Mat A_ = nullptr;       // not owned
  PetscObjectState a_state_ = -1;
  std::unordered_map<PetscInt, Eigen::Index> slot_;
  std::vector<PetscInt> held_;  // in slot order
  Eigen::MatrixXd block_;
};

}  // namespace softbody
