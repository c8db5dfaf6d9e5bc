#include "fem/mesh_share.hpp"

#include <algorithm>
#include <numeric>

#include "common/errors.hpp"
#include "common/even_share.hpp"
#include "fem/mesh_file_share.hpp"

namespace softbody {

namespace {

// The rest positions and initial velocities of the natural vertices [begin, end).
void CopyVertexSlab(const Scene &scene, PetscInt begin, PetscInt end, MeshShare *share) {
  share->rest.resize(end - begin, 3);
  share->velocities.setZero(end - begin, 3);
  for (const InitialVelocity &entry : scene.initial_velocities)
    if (entry.vertex >= begin && entry.vertex < end)
      for (int c = 0; c < 3; ++c) share->velocities(entry.vertex - begin, c) = entry.velocity[c];
  for (const Body &body : scene.bodies) {
    const PetscInt first = std::max<PetscInt>(begin, body.first_vertex);
    const PetscInt last = std::min<PetscInt>(end, body.first_vertex + body.mesh.num_vertices());
    if (first < last)
      share->rest.middleRows(first - begin, last - first) =
          body.mesh.vertices.middleRows(first - body.first_vertex, last - first);
  }
}

// The tets [begin, end) (bodies in scene order, tets in file order).
void CopyTetShare(const Scene &scene, int64_t begin, int64_t end, MeshShare *share) {
  share->tets.reserve(end - begin);
  share->tet_body.reserve(end - begin);
  int64_t first = 0;  // index of the body's tet 0
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    const int64_t last = first + body.mesh.num_tets();
    for (int64_t t = std::max(begin, first); t < std::min(end, last); ++t) {
      std::array<PetscInt, 4> natural;
      for (int a = 0; a < 4; ++a) natural[a] = body.first_vertex + body.mesh.tets(t - first, a);
      share->tets.push_back(natural);
      share->tet_body.push_back(static_cast<int32_t>(b));
    }
    first = last;
  }
}

}  // namespace

MeshShare ShareScene(const Scene &scene, PetscMPIInt rank, PetscMPIInt size) {
  MeshShare share;
  share.num_vertices = scene.num_vertices();
  share.first_vertex = EvenShareBegin(share.num_vertices, size, rank);
  CopyVertexSlab(scene, share.first_vertex, EvenShareBegin(share.num_vertices, size, rank + 1),
                 &share);
  share.num_all_tets = scene.num_tets();
  share.first_tet = EvenShareBegin(share.num_all_tets, size, rank);
  CopyTetShare(scene, share.first_tet, EvenShareBegin(share.num_all_tets, size, rank + 1), &share);
  for (const Body &body : scene.bodies) share.body_fixed.push_back(body.fixed);
  return share;
}

namespace {

// Where the scene's rows (its natural vertices, or its tets) are before
// DistributeScene moves them to the scene's even shares: a body read by rank 0
// (text formats) lies whole on rank 0, a deferred body's file slabs on every
// rank (ReadBodyShareFromFile). A rank's source rows are, in this order: on
// rank 0 the rank-0 bodies' rows (bodies in scene order), then its slab of each
// deferred body (bodies in scene order).
class SourceLayout {
 public:
  // rows[b]: body b's rows; deferred[b]: whether body b is read in slabs.
  SourceLayout(const std::vector<int64_t> &rows, const std::vector<char> &deferred, int size)
      : rows_(rows), deferred_(deferred), size_(size), first_(rows.size() + 1, 0) {
    rank0_before_.resize(rows.size());
    for (size_t b = 0; b < rows.size(); ++b) {
      first_[b + 1] = first_[b] + rows[b];
      rank0_before_[b] = rank0_rows_;
      if (!deferred[b]) rank0_rows_ += rows[b];
    }
  }

  // Source rows on `rank`.
  int64_t RowsOn(int rank) const { return OffsetOn(rank, rows_.size()); }

  // Rank and index among its source rows of scene row `row`. Rows asked in
  // increasing order cost O(1) each, amortised (the last body's offset is kept).
  PetscSFNode Locate(int64_t row) {
    const size_t b = std::upper_bound(first_.begin(), first_.end(), row) - first_.begin() - 1;
    const int64_t local = row - first_[b];
    if (!deferred_[b]) return {0, static_cast<PetscInt>(rank0_before_[b] + local)};
    int lo = 0, hi = size_ - 1;  // the slab holding `local`: EvenShareBegin is monotone
    while (lo < hi) {
      const int mid = (lo + hi + 1) / 2;
      if (EvenShareBegin(rows_[b], size_, mid) <= local)
        lo = mid;
      else
        hi = mid - 1;
    }
    if (b != cached_body_ || lo != cached_rank_) {
      cached_body_ = b;
      cached_rank_ = lo;
      cached_offset_ = OffsetOn(lo, b);
    }
    return {lo,
            static_cast<PetscInt>(cached_offset_ + local - EvenShareBegin(rows_[b], size_, lo))};
  }

 private:
  // Source rows on `rank` before those of body `body`.
  int64_t OffsetOn(int rank, size_t body) const {
    int64_t offset = rank == 0 ? rank0_rows_ : 0;
    for (size_t b = 0; b < body; ++b)
      if (deferred_[b])
        offset += EvenShareBegin(rows_[b], size_, rank + 1) - EvenShareBegin(rows_[b], size_, rank);
    return offset;
  }

  std::vector<int64_t> rows_;
  std::vector<char> deferred_;
  int size_;
  std::vector<int64_t> first_;         // scene row of body b's row 0; last: all rows
  std::vector<int64_t> rank0_before_;  // rank-0 bodies' rows before body b
  int64_t rank0_rows_ = 0;
  size_t cached_body_ = SIZE_MAX;
  int cached_rank_ = -1;
  int64_t cached_offset_ = 0;
};

// Collective. A star forest whose leaves are the scene rows [first, first + count)
// and whose roots are the source rows (SourceLayout).
PetscErrorCode CreateSourceSF(MPI_Comm comm, SourceLayout *layout, int64_t first, int64_t count,
                              PetscSF *sf) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscSFNode *remote;
  PetscCall(PetscMalloc1(count, &remote));
  for (int64_t i = 0; i < count; ++i) remote[i] = layout->Locate(first + i);
  PetscCall(PetscSFCreate(comm, sf));
  PetscCall(PetscSFSetGraph(*sf, static_cast<PetscInt>(layout->RowsOn(rank)),
                            static_cast<PetscInt>(count), nullptr, PETSC_OWN_POINTER, remote,
                            PETSC_OWN_POINTER));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// This rank's source rows of the vertices (placed rest positions) and of the
// tets (natural vertices), as SourceLayout orders them.
void SourceRows(const Scene &scene, const std::vector<MeshShare> &file_shares, PetscMPIInt rank,
                std::vector<double> *rest, std::vector<std::array<PetscInt, 4>> *tets) {
  if (rank == 0)
    for (const Body &body : scene.bodies) {
      if (body.mesh_deferred) continue;
      rest->insert(rest->end(), body.mesh.vertices.data(),
                   body.mesh.vertices.data() + body.mesh.vertices.size());
      for (int32_t t = 0; t < body.mesh.num_tets(); ++t) {
        std::array<PetscInt, 4> tet;
        for (int a = 0; a < 4; ++a) tet[a] = body.first_vertex + body.mesh.tets(t, a);
        tets->push_back(tet);
      }
    }
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    if (!scene.bodies[b].mesh_deferred) continue;
    const MeshShare &file = file_shares[b];
    rest->insert(rest->end(), file.rest.data(), file.rest.data() + file.rest.size());
    for (std::array<PetscInt, 4> tet : file.tets) {
      for (PetscInt &vertex : tet) vertex += scene.bodies[b].first_vertex;
      tets->push_back(tet);
    }
  }
}

// Collective. share->velocities: zero, but the velocity section's entries (on
// rank 0, by natural vertex) sent to their slabs.
PetscErrorCode SpreadInitialVelocities(MPI_Comm comm, const Scene &scene, MeshShare *share) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  share->velocities.setZero(share->slab_size(), 3);
  std::vector<PetscInt> naturals;
  std::vector<double> velocities;
  if (rank == 0)
    for (const InitialVelocity &entry : scene.initial_velocities) {
      naturals.push_back(static_cast<PetscInt>(entry.vertex));
      velocities.insert(velocities.end(), entry.velocity.begin(), entry.velocity.end());
    }
  PetscSF sf;
  PetscCall(CreateSlabSF(comm, *share, naturals, &sf));
  MPI_Datatype unit;
  PetscCallMPI(MPI_Type_contiguous(3, MPI_DOUBLE, &unit));
  PetscCallMPI(MPI_Type_commit(&unit));
  // One entry per vertex (ReadScene), so REPLACE has no order to depend on.
  PetscCall(PetscSFReduceBegin(sf, unit, velocities.data(), share->velocities.data(), MPI_REPLACE));
  PetscCall(PetscSFReduceEnd(sf, unit, velocities.data(), share->velocities.data(), MPI_REPLACE));
  PetscCallMPI(MPI_Type_free(&unit));
  PetscCall(PetscSFDestroy(&sf));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Every rank's shares of the scene: the rank-0 bodies from rank 0's
// meshes, the deferred ones from every rank's file slabs (file_shares[b], empty
// for the others), the initial velocities from rank 0.
PetscErrorCode GatherShares(MPI_Comm comm, const Scene &scene,
                            const std::vector<MeshShare> &file_shares, MeshShare *share) {
  PetscFunctionBeginUser;
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  std::vector<int64_t> vertex_rows, tet_rows;
  std::vector<char> deferred;
  for (const Body &body : scene.bodies) {
    vertex_rows.push_back(body.num_vertices());
    tet_rows.push_back(body.num_tets());
    deferred.push_back(body.mesh_deferred);
  }
  *share = MeshShare();
  const PetscInt N = scene.num_vertices();
  share->num_vertices = N;
  share->first_vertex = EvenShareBegin(N, size, rank);
  const PetscInt slab = EvenShareBegin(N, size, rank + 1) - share->first_vertex;
  share->num_all_tets = scene.num_tets();
  PetscCheck(share->num_all_tets <= PETSC_MAX_INT, comm, PETSC_ERR_SUP,
             "%lld tets: more than this PETSc's indices hold",
             static_cast<long long>(share->num_all_tets));
  share->first_tet = EvenShareBegin(share->num_all_tets, size, rank);
  const int64_t count = EvenShareBegin(share->num_all_tets, size, rank + 1) - share->first_tet;
  share->rest.resize(slab, 3);
  share->tets.resize(count);
  {
    std::vector<double> rest;
    std::vector<std::array<PetscInt, 4>> tets;
    SourceRows(scene, file_shares, rank, &rest, &tets);
    SourceLayout vertices(vertex_rows, deferred, size), all_tets(tet_rows, deferred, size);
    PetscSF sf;
    PetscCall(CreateSourceSF(comm, &vertices, share->first_vertex, slab, &sf));
    PetscCall(FetchFromSlabs(sf, MPI_DOUBLE, 3, rest.data(), share->rest.data()));
    PetscCall(PetscSFDestroy(&sf));
    PetscCall(CreateSourceSF(comm, &all_tets, share->first_tet, count, &sf));
    PetscCall(FetchFromSlabs(sf, MPIU_INT, 4, tets.data(), share->tets.data()));
    PetscCall(PetscSFDestroy(&sf));
  }
  PetscCall(SpreadInitialVelocities(comm, scene, share));
  int64_t body_first = 0;  // scene tet of the body's tet 0
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const int64_t begin = std::max(body_first, share->first_tet);
    const int64_t end = std::min(body_first + tet_rows[b], share->first_tet + count);
    for (int64_t t = begin; t < end; ++t) share->tet_body.push_back(static_cast<int32_t>(b));
    body_first += tet_rows[b];
  }
  for (const Body &body : scene.bodies) share->body_fixed.push_back(body.fixed);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Rank 0 reads and places the deferred meshes; its input error, if
// any, on every rank.
PetscErrorCode LoadDeferredMeshesOnRankZero(MPI_Comm comm, const MeshingOptions &meshing,
                                            Scene *scene) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  int failed = 0;
  std::string error;
  if (rank == 0) {
    try {
      LoadDeferredMeshes(meshing, scene);
    } catch (const InputError &input_error) {
      error = input_error.what();
      failed = 1;
    }
  }
  PetscCallMPI(MPI_Bcast(&failed, 1, MPI_INT, 0, comm));
  if (failed) {
    int length = static_cast<int>(error.size());
    PetscCallMPI(MPI_Bcast(&length, 1, MPI_INT, 0, comm));
    error.resize(length);
    PetscCallMPI(MPI_Bcast(error.data(), length, MPI_CHAR, 0, comm));
  }
  PetscCheck(!failed, comm, PETSC_ERR_USER_INPUT, "%s", error.c_str());
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode DistributeScene(MPI_Comm comm, const MeshingOptions &meshing, MeshHolding holding,
                               Scene *scene, MeshShare *share) {
  PetscFunctionBeginUser;
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  const bool deferred = std::any_of(scene->bodies.begin(), scene->bodies.end(),
                                    [](const Body &body) { return body.mesh_deferred; });
  if (holding == MeshHolding::kWhole) {
    if (deferred) PetscCall(LoadDeferredMeshesOnRankZero(comm, meshing, scene));
    PetscCall(BroadcastMeshes(comm, scene));
    *share = ShareScene(*scene, rank, size);
  } else {
    std::vector<MeshShare> file_shares(scene->bodies.size());
    for (size_t b = 0; b < scene->bodies.size(); ++b)
      if (scene->bodies[b].mesh_deferred)
        PetscCall(ReadBodyShareFromFile(comm, *scene, b, &file_shares[b]));
    PetscCall(GatherShares(comm, *scene, file_shares, share));
    scene->meshes_read_in_slabs =
        static_cast<int>(std::count_if(scene->bodies.begin(), scene->bodies.end(),
                                       [](const Body &body) { return body.mesh_deferred; }));
    scene->DropMeshes();
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CreateSlabSF(MPI_Comm comm, const MeshShare &share,
                            const std::vector<PetscInt> &naturals, PetscSF *sf) {
  PetscFunctionBeginUser;
  for (PetscInt natural : naturals)
    PetscCheck(natural >= 0 && natural < share.num_vertices, PETSC_COMM_SELF,
               PETSC_ERR_ARG_OUTOFRANGE,
               "natural vertex %" PetscInt_FMT " outside the %" PetscInt_FMT " of the slabs",
               natural, share.num_vertices);
  PetscLayout slabs;
  PetscCall(PetscLayoutCreate(comm, &slabs));
  PetscCall(PetscLayoutSetLocalSize(slabs, share.slab_size()));
  PetscCall(PetscLayoutSetUp(slabs));
  PetscCall(PetscSFCreate(comm, sf));
  PetscCall(PetscSFSetGraphLayout(*sf, slabs, static_cast<PetscInt>(naturals.size()), nullptr,
                                  PETSC_OWN_POINTER, naturals.data()));
  PetscCall(PetscLayoutDestroy(&slabs));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode FetchFromSlabs(PetscSF sf, MPI_Datatype type, int width, const void *per_vertex,
                              void *values) {
  PetscFunctionBeginUser;
  MPI_Datatype unit;
  PetscCallMPI(MPI_Type_contiguous(width, type, &unit));
  PetscCallMPI(MPI_Type_commit(&unit));
  PetscCall(PetscSFBcastBegin(sf, unit, per_vertex, values, MPI_REPLACE));
  PetscCall(PetscSFBcastEnd(sf, unit, per_vertex, values, MPI_REPLACE));
  PetscCallMPI(MPI_Type_free(&unit));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
