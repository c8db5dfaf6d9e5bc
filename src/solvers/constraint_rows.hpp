// The rows of J, the constraint matrix of a contact step with two-sided
// (free-free) constraints (projected_solve.hpp): each row couples up to four
// vertices (a vertex and the face it touches) along one direction,
//
//     J_j v = n_j . (v_a - sum_k w_k v_{f_k}),
//
// with a right-hand side c_j (m/s) and whether it is an inequality
// (J_j v >= c_j, two-sided contacts) or an equation (a vertex's combined
// one-sided directions). Every rank holds every row (they are few next to the
// vertices) in an order that does not depend on the rank count; products with
// the rows sum over the owned entries and are reduced by the caller. Internal
// to src/solvers (two_sided_solve.cpp, augmented_solve.cpp).
#pragma once

#include <petscksp.h>
#include <petscsf.h>

#include <cstdint>
#include <vector>

#include "solvers/projected_solve.hpp"

namespace softbody {

// One row of J: up to four vertices (PETSc numbers, -1: none) with weights,
// a direction, the right-hand side, and whether it is an inequality; ordered
// by (key, sub): the vertex's order key (VelocityConstraint::order_key) and
// the row's place among the vertex's rows; rank and position: where it was made.
struct Row {
  PetscInt vertex[4];
  double weight[4];
  double direction[3];
  double value;
  PetscInt key;
  int32_t sub;
  int32_t unilateral;
  int32_t rank;
  int32_t position;
};

// Where a rank's rows are made: the communicator, this rank and its owned
// vertex range [begin, end) of a vector laid out as A's (3 DOFs per vertex).
struct RowSite {
  MPI_Comm comm;
  PetscMPIInt rank;
  PetscInt begin, end;
};
PetscErrorCode GetRowSite(Vec layout, RowSite *site);

// This rank's rows: each constrained vertex's combined directions, then the
// two-sided constraints in their order; *slot: the row of each two-sided
// constraint (-1 for the others). first: the first owned vertex's PETSc number.
std::vector<Row> LocalRows(const std::vector<ConstrainedVertex> &vertices,
                           const std::vector<VelocityConstraint> &constraints, PetscInt first,
                           int32_t rank, std::vector<PetscInt> *slot);

// Collective. Every rank's rows in (key, sub) order; *slot (LocalRows') renumbered to it.
PetscErrorCode OrderedRows(MPI_Comm comm, const std::vector<Row> &mine, int32_t rank,
                           std::vector<PetscInt> *slot, std::vector<Row> *rows);

// y[owned] += scale J_row^T (entries of owned vertices only); begin, end: the
// owned PETSc vertex range.
void AddRowTranspose(const Row &row, double scale, PetscInt begin, PetscInt end, PetscScalar *y);

// J_row x over the owned entries.
double RowDot(const Row &row, PetscInt begin, PetscInt end, const PetscScalar *x);

// Not collective. out[i] = J_i x over the owned entries, for every row i.
PetscErrorCode RowDots(const std::vector<Row> &rows, PetscInt begin, PetscInt end, Vec x,
                       double *out);

// Collective. Whether the unconstrained solver is a factorisation applied once
// (KSPPREONLY), whose PC can solve many right-hand sides at once.
PetscErrorCode AppliesFactorOnce(KSP solver, bool *once);

// This rank's rows (LocalRows) with what products with J and J^T need of
// their vertices owned by other ranks: a PetscSF from those vertices (leaves)
// to their owners (roots), so nothing is gathered on every rank and a rank
// exchanges only with the owners of its rows' face vertices. The augmented
// Lagrangian path's (augmented_solve.cpp); vectors laid out as A's (3 DOFs per
// vertex, PETSc numbering).
class LocalRowSet {
 public:
  LocalRowSet() = default;
  LocalRowSet(const LocalRowSet &) = delete;
  LocalRowSet &operator=(const LocalRowSet &) = delete;
  ~LocalRowSet();
  // Collective. layout: a vector laid out as A's.
  PetscErrorCode Setup(Vec layout, std::vector<Row> rows);
  const std::vector<Row> &rows() const { return rows_; }
  // Collective. out[j] = J_j x for this rank's rows.
  PetscErrorCode Dots(Vec x, std::vector<double> *out) const;
  // Collective. y += sum_j coefficients_j J_j^T.
  PetscErrorCode AddTranspose(const std::vector<double> &coefficients, Vec y) const;
  // Collective. `unit` numbers per vertex, owned[unit * local vertex + i], at
  // every vertex of every row: out[(4 j + a) unit + i] (zeros where none).
  PetscErrorCode AtRowVertices(const std::vector<double> &owned, int unit,
                               std::vector<double> *out) const;

 private:
  // Fetches the remote vertices' `unit` numbers per vertex into halo.
  PetscErrorCode FetchRemote(const double *owned, int unit, std::vector<double> *halo) const;
  std::vector<Row> rows_;
  PetscInt begin_ = 0, end_ = 0;  // the owned vertex range
  // Per (row, a): the owned local vertex (>= 0), the halo entry -(1 + h), or
  // kNoVertex (no vertex or weight zero).
  std::vector<PetscInt> where_;
  PetscInt remote_count_ = 0;
  PetscSF sf_ = nullptr;  // leaves: the remote vertices; roots: owned vertices
};

// The augmented Lagrangian path's penalty on this rank's rows: the operator
// term sum_j rho_j J_j^T J_j (rho_j in kg, A's units: A v is a momentum; 0:
// the row is not penalised).
struct RowPenalty {
  const LocalRowSet *rows = nullptr;
  std::vector<double> rho;
  // Collective. y += sum_j rho_j J_j^T (J_j x).
  PetscErrorCode AddTo(Vec x, Vec y) const;
};

}  // namespace softbody
