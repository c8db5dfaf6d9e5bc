// The rows of J (constraint_rows.hpp).
#include "solvers/constraint_rows.hpp"

#include <algorithm>
#include <map>
#include <utility>

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

PetscErrorCode GetRowSite(Vec layout, RowSite *site) {
  PetscFunctionBeginUser;
  site->comm = PetscObjectComm((PetscObject)layout);
  PetscCallMPI(MPI_Comm_rank(site->comm, &site->rank));
  PetscCall(VecGetOwnershipRange(layout, &site->begin, &site->end));
  site->begin /= 3, site->end /= 3;
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

namespace {

// where_'s mark of a row entry without a vertex.
constexpr PetscInt kNoVertex = PETSC_MIN_INT;

// An MPI type of `unit` contiguous reals (committed; the caller frees it).
PetscErrorCode UnitType(int unit, MPI_Datatype *type) {
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Type_contiguous(unit, MPIU_REAL, type));
  PetscCallMPI(MPI_Type_commit(type));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

LocalRowSet::~LocalRowSet() {
  PetscSFDestroy(&sf_);
}

PetscErrorCode LocalRowSet::Setup(Vec layout, std::vector<Row> rows) {
  PetscFunctionBeginUser;
  rows_ = std::move(rows);
  PetscCall(PetscSFDestroy(&sf_));
  PetscCall(VecGetOwnershipRange(layout, &begin_, &end_));
  begin_ /= 3, end_ /= 3;
  std::vector<PetscInt> remote;  // global vertices owned elsewhere, ascending
  for (const Row &row : rows_)
    for (int a = 0; a < 4; ++a)
      if (row.vertex[a] >= 0 && row.weight[a] != 0 &&
          (row.vertex[a] < begin_ || row.vertex[a] >= end_))
        remote.push_back(row.vertex[a]);
  std::sort(remote.begin(), remote.end());
  remote.erase(std::unique(remote.begin(), remote.end()), remote.end());
  remote_count_ = static_cast<PetscInt>(remote.size());
  where_.assign(4 * rows_.size(), kNoVertex);
  for (size_t j = 0; j < rows_.size(); ++j)
    for (int a = 0; a < 4; ++a) {
      const PetscInt p = rows_[j].vertex[a];
      if (p < 0 || rows_[j].weight[a] == 0) continue;
      where_[4 * j + a] =
          p >= begin_ && p < end_
              ? p - begin_
              : -1 - static_cast<PetscInt>(std::lower_bound(remote.begin(), remote.end(), p) -
                                           remote.begin());
    }
  const PetscInt *ranges;  // DOF ownership ranges
  PetscCall(VecGetOwnershipRanges(layout, &ranges));
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(PetscObjectComm((PetscObject)layout), &size));
  std::vector<PetscSFNode> owners(remote.size());
  for (size_t h = 0; h < remote.size(); ++h) {
    const PetscInt dof = 3 * remote[h];
    const PetscInt owner =
        static_cast<PetscInt>(std::upper_bound(ranges, ranges + size + 1, dof) - ranges) - 1;
    owners[h] = {owner, remote[h] - ranges[owner] / 3};
  }
  PetscCall(PetscSFCreate(PetscObjectComm((PetscObject)layout), &sf_));
  PetscCall(PetscSFSetGraph(sf_, end_ - begin_, remote_count_, nullptr, PETSC_COPY_VALUES,
                            owners.data(), PETSC_COPY_VALUES));
  PetscCall(PetscSFSetUp(sf_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode LocalRowSet::FetchRemote(const double *owned, int unit,
                                        std::vector<double> *halo) const {
  PetscFunctionBeginUser;
  halo->assign(static_cast<size_t>(unit) * remote_count_, 0.0);
  MPI_Datatype type;
  PetscCall(UnitType(unit, &type));
  PetscCall(PetscSFBcastBegin(sf_, type, owned, halo->data(), MPI_REPLACE));
  PetscCall(PetscSFBcastEnd(sf_, type, owned, halo->data(), MPI_REPLACE));
  PetscCallMPI(MPI_Type_free(&type));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode LocalRowSet::AtRowVertices(const std::vector<double> &owned, int unit,
                                          std::vector<double> *out) const {
  PetscFunctionBeginUser;
  std::vector<double> halo;
  PetscCall(FetchRemote(owned.data(), unit, &halo));
  out->assign(4 * rows_.size() * unit, 0.0);
  for (size_t e = 0; e < where_.size(); ++e) {
    const PetscInt w = where_[e];
    if (w == kNoVertex) continue;
    const double *from = w >= 0 ? &owned[unit * w] : &halo[unit * (-1 - w)];
    std::copy(from, from + unit, out->begin() + e * unit);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode LocalRowSet::Dots(Vec x, std::vector<double> *out) const {
  PetscFunctionBeginUser;
  const PetscScalar *values;
  PetscCall(VecGetArrayRead(x, &values));
  std::vector<double> halo;
  const PetscErrorCode fetched = FetchRemote(values, 3, &halo);
  out->assign(rows_.size(), 0.0);
  for (size_t j = 0; j < rows_.size() && !fetched; ++j)
    for (int a = 0; a < 4; ++a) {
      const PetscInt w = where_[4 * j + a];
      if (w == kNoVertex) continue;
      const double *v = w >= 0 ? values + 3 * w : &halo[3 * (-1 - w)];
      for (int k = 0; k < 3; ++k) (*out)[j] += rows_[j].weight[a] * rows_[j].direction[k] * v[k];
    }
  PetscCall(VecRestoreArrayRead(x, &values));
  PetscCall(fetched);
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode LocalRowSet::AddTranspose(const std::vector<double> &coefficients, Vec y) const {
  PetscFunctionBeginUser;
  std::vector<double> halo(3 * remote_count_, 0.0);
  PetscScalar *out;
  PetscCall(VecGetArray(y, &out));
  for (size_t j = 0; j < rows_.size(); ++j) {
    if (coefficients[j] == 0) continue;
    for (int a = 0; a < 4; ++a) {
      const PetscInt w = where_[4 * j + a];
      if (w == kNoVertex) continue;
      double *to = w >= 0 ? out + 3 * w : &halo[3 * (-1 - w)];
      for (int k = 0; k < 3; ++k)
        to[k] += coefficients[j] * rows_[j].weight[a] * rows_[j].direction[k];
    }
  }
  MPI_Datatype type;
  PetscCall(UnitType(3, &type));
  PetscCall(PetscSFReduceBegin(sf_, type, halo.data(), out, MPI_SUM));
  PetscCall(PetscSFReduceEnd(sf_, type, halo.data(), out, MPI_SUM));
  PetscCallMPI(MPI_Type_free(&type));
  PetscCall(VecRestoreArray(y, &out));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode RowPenalty::AddTo(Vec x, Vec y) const {
  PetscFunctionBeginUser;
  std::vector<double> dots;
  PetscCall(rows->Dots(x, &dots));
  for (size_t j = 0; j < dots.size(); ++j) dots[j] *= rho[j];
  PetscCall(rows->AddTranspose(dots, y));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
