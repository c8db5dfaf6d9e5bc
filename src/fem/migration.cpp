#include "fem/migration.hpp"

#include <algorithm>
#include <utility>

#include "common/exchange.hpp"

namespace softbody {

namespace {

// One tet on its way to a rank that owns one of its vertices.
struct TetRecord {
  int64_t index;  // among all tets
  int32_t body;
  int32_t unused;  // keeps the record free of padding
  PetscInt vertices[4];
  double rest[12];
};

// Collective. The PETSc vertices and rest positions of the share's tets.
PetscErrorCode FetchTetVertices(MPI_Comm comm, const MeshShare &share,
                                std::vector<std::array<PetscInt, 4>> *petsc,
                                std::vector<std::array<double, 12>> *rest) {
  PetscFunctionBeginUser;
  std::vector<PetscInt> naturals;
  naturals.reserve(4 * share.tets.size());
  for (const auto &tet : share.tets) naturals.insert(naturals.end(), tet.begin(), tet.end());
  PetscSF sf;
  PetscCall(CreateSlabSF(comm, share, naturals, &sf));
  petsc->resize(share.tets.size());
  rest->resize(share.tets.size());
  PetscCall(FetchFromSlabs(sf, MPIU_INT, 1, share.petsc_vertex.data(), petsc->data()));
  PetscCall(FetchFromSlabs(sf, MPI_DOUBLE, 3, share.rest.data(), rest->data()));
  PetscCall(PetscSFDestroy(&sf));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The distinct ranks owning the vertices of a tet, increasing: rank[0 .. count).
struct TetOwners {
  PetscMPIInt rank[4];
  int count = 0;
  const PetscMPIInt *begin() const { return rank; }
  const PetscMPIInt *end() const { return rank + count; }
};

TetOwners Owners(const DofLayout &layout, const std::array<PetscInt, 4> &vertices) {
  TetOwners owners;
  for (PetscInt v : vertices) {
    const auto after = std::upper_bound(layout.vertex_start.begin(), layout.vertex_start.end(), v);
    owners.rank[owners.count++] = static_cast<PetscMPIInt>(after - layout.vertex_start.begin()) - 1;
  }
  std::sort(owners.rank, owners.rank + 4);
  owners.count = static_cast<int>(std::unique(owners.rank, owners.rank + 4) - owners.rank);
  return owners;
}

// The share's free tets as records, grouped by destination rank (counts[q] for
// rank q): counted first, then written in place, so the records are held once.
std::vector<TetRecord> PackByOwner(const MeshShare &share, const DofLayout &layout,
                                   const std::vector<std::array<PetscInt, 4>> &petsc,
                                   const std::vector<std::array<double, 12>> &rest,
                                   std::vector<int> *counts) {
  counts->assign(layout.size, 0);
  for (size_t t = 0; t < share.tets.size(); ++t)
    if (share.TetIsFree(t))
      for (PetscMPIInt q : Owners(layout, petsc[t])) ++(*counts)[q];
  std::vector<size_t> next(layout.size + 1, 0);
  for (PetscMPIInt q = 0; q < layout.size; ++q) next[q + 1] = next[q] + (*counts)[q];
  std::vector<TetRecord> records(next[layout.size]);
  for (size_t t = 0; t < share.tets.size(); ++t) {
    if (!share.TetIsFree(t)) continue;
    for (PetscMPIInt q : Owners(layout, petsc[t])) {
      TetRecord &record = records[next[q]++];
      record = TetRecord{share.first_tet + static_cast<int64_t>(t), share.tet_body[t], 0, {}, {}};
      std::copy(petsc[t].begin(), petsc[t].end(), record.vertices);
      std::copy(rest[t].begin(), rest[t].end(), record.rest);
    }
  }
  return records;
}

// The tet's PETSc vertices, increasing: the key the tets are sorted by for locality.
std::array<PetscInt, 4> SortedVertices(const TetRecord &record) {
  std::array<PetscInt, 4> v{record.vertices[0], record.vertices[1], record.vertices[2],
                            record.vertices[3]};
  std::sort(v.begin(), v.end());
  return v;
}

// In tet index order; unless the vertices keep the natural order, then by their
// sorted PETSc vertices (lexicographic, ties by tet index).
void SortRecords(VertexOrder order, std::vector<TetRecord> *records) {
  if (order == VertexOrder::kNatural) {
    std::sort(records->begin(), records->end(),
              [](const TetRecord &a, const TetRecord &b) { return a.index < b.index; });
    return;
  }
  std::vector<std::pair<std::array<PetscInt, 4>, int64_t>> key(records->size());
  std::vector<size_t> position(records->size());
  for (size_t t = 0; t < records->size(); ++t) {
    key[t] = {SortedVertices((*records)[t]), (*records)[t].index};
    position[t] = t;
  }
  std::sort(position.begin(), position.end(),
            [&key](size_t a, size_t b) { return key[a] < key[b]; });
  std::vector<TetRecord> sorted(records->size());
  for (size_t t = 0; t < position.size(); ++t) sorted[t] = (*records)[position[t]];
  *records = std::move(sorted);
}

}  // namespace

PetscErrorCode MigrateTets(MPI_Comm comm, const MeshShare &share, const DofLayout &layout,
                           LocalTets *tets) {
  PetscFunctionBeginUser;
  std::vector<TetRecord> send, received;
  std::vector<int> counts;
  {
    std::vector<std::array<PetscInt, 4>> petsc;
    std::vector<std::array<double, 12>> rest;
    PetscCall(FetchTetVertices(comm, share, &petsc, &rest));
    send = PackByOwner(share, layout, petsc, rest, &counts);
  }
  PetscCall(ExchangeRecords(comm, send, counts, &received));
  send = std::vector<TetRecord>();
  SortRecords(layout.vertex_order, &received);
  *tets = LocalTets();
  tets->index.reserve(received.size());
  tets->body.reserve(received.size());
  tets->vertices.reserve(received.size());
  tets->rest.reserve(received.size());
  for (const TetRecord &r : received) {
    tets->index.push_back(r.index);
    tets->body.push_back(r.body);
    tets->vertices.push_back({r.vertices[0], r.vertices[1], r.vertices[2], r.vertices[3]});
    tets->rest.push_back(Eigen::Map<const Eigen::Matrix<double, 4, 3, Eigen::RowMajor>>(r.rest));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
