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
  share->velocities = scene.initial_velocities.middleRows(begin, end - begin);
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

// Rank 0: every body's placed vertices, natural order.
std::vector<double> AllRestPositions(const Scene &scene) {
  std::vector<double> rest;
  rest.reserve(3 * static_cast<size_t>(scene.num_vertices()));
  for (const Body &body : scene.bodies)
    rest.insert(rest.end(), body.mesh.vertices.data(),
                body.mesh.vertices.data() + body.mesh.vertices.size());
  return rest;
}

// Rank 0: every tet as its natural vertices, and its body.
void AllTets(const Scene &scene, std::vector<std::array<PetscInt, 4>> *tets,
             std::vector<int32_t> *bodies) {
  tets->reserve(scene.num_tets());
  bodies->reserve(scene.num_tets());
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    for (int32_t t = 0; t < body.mesh.num_tets(); ++t) {
      std::array<PetscInt, 4> tet;
      for (int a = 0; a < 4; ++a) tet[a] = body.first_vertex + body.mesh.tets(t, a);
      tets->push_back(tet);
      bodies->push_back(static_cast<int32_t>(b));
    }
  }
}

// Collective. Every rank's shares from rank 0's whole scene.
PetscErrorCode SendSharesFromRankZero(MPI_Comm comm, const Scene &scene, MeshShare *share) {
  PetscFunctionBeginUser;
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  const PetscInt N = scene.num_vertices();
  share->num_vertices = N;
  share->first_vertex = EvenShareBegin(N, size, rank);
  const PetscInt slab = EvenShareBegin(N, size, rank + 1) - share->first_vertex;
  share->rest.resize(slab, 3);
  share->velocities.resize(slab, 3);
  {
    const std::vector<double> rest = rank == 0 ? AllRestPositions(scene) : std::vector<double>();
    PetscCall(FetchRootRows(comm, N, share->first_vertex, slab, MPI_DOUBLE, 3, rest.data(),
                            share->rest.data()));
  }
  PetscCall(FetchRootRows(comm, N, share->first_vertex, slab, MPI_DOUBLE, 3,
                          scene.initial_velocities.data(), share->velocities.data()));
  share->num_all_tets = scene.num_tets();
  PetscCheck(share->num_all_tets <= PETSC_MAX_INT, comm, PETSC_ERR_SUP,
             "%lld tets: more than this PETSc's indices hold; convert the mesh (softbody-convert)",
             static_cast<long long>(share->num_all_tets));
  const PetscInt T = static_cast<PetscInt>(share->num_all_tets);
  share->first_tet = EvenShareBegin(T, size, rank);
  const PetscInt count =
      static_cast<PetscInt>(EvenShareBegin(T, size, rank + 1) - share->first_tet);
  share->tets.resize(count);
  share->tet_body.resize(count);
  std::vector<std::array<PetscInt, 4>> tets;
  std::vector<int32_t> bodies;
  if (rank == 0) AllTets(scene, &tets, &bodies);
  const PetscInt first = static_cast<PetscInt>(share->first_tet);
  PetscCall(FetchRootRows(comm, T, first, count, MPIU_INT, 4, tets.data(), share->tets.data()));
  PetscCall(
      FetchRootRows(comm, T, first, count, MPI_INT32_T, 1, bodies.data(), share->tet_body.data()));
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

PetscErrorCode FetchRootRows(MPI_Comm comm, PetscInt total, PetscInt first, PetscInt rows,
                             MPI_Datatype type, int width, const void *root_rows, void *rows_here) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscLayout root;
  PetscCall(PetscLayoutCreate(comm, &root));
  PetscCall(PetscLayoutSetLocalSize(root, rank == 0 ? total : 0));
  PetscCall(PetscLayoutSetUp(root));
  std::vector<PetscInt> wanted(rows);
  std::iota(wanted.begin(), wanted.end(), first);
  PetscSF sf;
  PetscCall(PetscSFCreate(comm, &sf));
  PetscCall(PetscSFSetGraphLayout(sf, root, rows, nullptr, PETSC_OWN_POINTER, wanted.data()));
  PetscCall(PetscLayoutDestroy(&root));
  PetscCall(FetchFromSlabs(sf, type, width, root_rows, rows_here));
  PetscCall(PetscSFDestroy(&sf));
  PetscFunctionReturn(PETSC_SUCCESS);
}

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
  } else if (deferred && holding == MeshHolding::kSlabs) {
    PetscCall(ReadShareFromMeshFile(comm, *scene, share));
    scene->DropMeshes();
    scene->read_in_slabs = true;
  } else {
    if (deferred) PetscCall(LoadDeferredMeshesOnRankZero(comm, meshing, scene));
    *share = MeshShare();
    PetscCall(SendSharesFromRankZero(comm, *scene, share));
    if (holding == MeshHolding::kSlabs) scene->DropMeshes();
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
