// The rows of J (constraint_rows.hpp).
#include "solvers/constraint_rows.hpp"

#include <algorithm>
#include <map>

#include "common/exchange.hpp"

namespace softbody {

std::vector<Row> LocalRows(const std::vector<ConstrainedVertex> &vertices,
                           const std::vector<VelocityConstraint> &constraints, PetscInt first,
                           int32_t rank, std::vector<PetscInt> *slot) {
  std::map<PetscInt, PetscInt> key;  // local vertex -> order key
  std::map<PetscInt, int32_t> subs;  // local vertex -> rows so far
  for (const VelocityConstraint &c : constraints)
    key[c.vertex] = c.order_key >= 0 ? c.order_key : first + c.vertex;
  std::vector<Row> rows;
  auto add = [&](Row row, PetscInt local) {
    row.key = key[local];
    row.sub = subs[local]++;
    row.rank = rank;
    row.position = static_cast<int32_t>(rows.size());
    rows.push_back(row);
  };
  for (const ConstrainedVertex &c : vertices)
    for (int j = 0; j < c.rank; ++j) {
      const Eigen::Vector3d q = c.basis.col(j);
      add({{first + c.vertex, -1, -1, -1},
           {1, 0, 0, 0},
           {q[0], q[1], q[2]},
           q.dot(c.prescribed),
           -1,
           0,
           0,
           0,
           0},
          c.vertex);
    }
  slot->assign(constraints.size(), -1);
  for (size_t i = 0; i < constraints.size(); ++i) {
    const VelocityConstraint &c = constraints[i];
    if (!c.two_sided) continue;
    (*slot)[i] = static_cast<PetscInt>(rows.size());
    add({{first + c.vertex, c.face[0], c.face[1], c.face[2]},
         {1, -c.weights[0], -c.weights[1], -c.weights[2]},
         {c.normal[0], c.normal[1], c.normal[2]},
         c.velocity,
         -1,
         0,
         1,
         0,
         0},
        c.vertex);
  }
  return rows;
}

PetscErrorCode OrderedRows(MPI_Comm comm, const std::vector<Row> &mine, int32_t rank,
                           std::vector<PetscInt> *slot, std::vector<Row> *rows) {
  PetscFunctionBeginUser;
  PetscCall(AllGatherRecords(comm, mine, rows));
  std::sort(rows->begin(), rows->end(), [](const Row &a, const Row &b) {
    return a.key != b.key ? a.key < b.key : a.sub < b.sub;
  });
  std::vector<PetscInt> row_of_position(mine.size(), -1);
  for (size_t i = 0; i < rows->size(); ++i)
    if ((*rows)[i].rank == rank) row_of_position[(*rows)[i].position] = static_cast<PetscInt>(i);
  for (PetscInt &s : *slot)
    if (s >= 0) s = row_of_position[s];
  PetscFunctionReturn(PETSC_SUCCESS);
}

void AddRowTranspose(const Row &row, double scale, PetscInt begin, PetscInt end, PetscScalar *y) {
  for (int a = 0; a < 4; ++a) {
    const PetscInt p = row.vertex[a];
    if (p < begin || p >= end) continue;
    for (int k = 0; k < 3; ++k) y[3 * (p - begin) + k] += scale * row.weight[a] * row.direction[k];
  }
}

double RowDot(const Row &row, PetscInt begin, PetscInt end, const PetscScalar *x) {
  double sum = 0;
  for (int a = 0; a < 4; ++a) {
    const PetscInt p = row.vertex[a];
    if (p < begin || p >= end) continue;
    for (int k = 0; k < 3; ++k) sum += row.weight[a] * row.direction[k] * x[3 * (p - begin) + k];
  }
  return sum;
}

PetscErrorCode RowDots(const std::vector<Row> &rows, PetscInt begin, PetscInt end, Vec x,
                       double *out) {
  PetscFunctionBeginUser;
  const PetscScalar *values;
  PetscCall(VecGetArrayRead(x, &values));
  for (size_t i = 0; i < rows.size(); ++i) out[i] = RowDot(rows[i], begin, end, values);
  PetscCall(VecRestoreArrayRead(x, &values));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode AppliesFactorOnce(KSP solver, bool *once) {
  PetscFunctionBeginUser;
  KSPType type;
  PetscCall(KSPGetType(solver, &type));
  PetscBool preonly;
  PetscCall(PetscStrcmp(type, KSPPREONLY, &preonly));
  *once = preonly;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode RowPenalty::AddTo(Vec x, Vec y) const {
  PetscFunctionBeginUser;
  const size_t m = rows.size();
  std::vector<double> dots(m, 0.0);
  const PetscScalar *values;
  PetscCall(VecGetArrayRead(x, &values));
  for (size_t j = 0; j < m; ++j)
    if (rho[j] > 0) dots[j] = RowDot(rows[j], begin, end, values);
  PetscCall(VecRestoreArrayRead(x, &values));
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, dots.data(), static_cast<PetscMPIInt>(m), MPIU_REAL,
                              MPI_SUM, PetscObjectComm((PetscObject)x)));
  PetscScalar *out;
  PetscCall(VecGetArray(y, &out));
  for (size_t j = 0; j < m; ++j)
    if (rho[j] > 0) AddRowTranspose(rows[j], rho[j] * dots[j], begin, end, out);
  PetscCall(VecRestoreArray(y, &out));
  PetscFunctionReturn(PETSC_SUCCESS);
}
}  // namespace softbody
