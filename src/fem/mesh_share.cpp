#include "fem/mesh_share.hpp"

#include <algorithm>

#include "common/even_share.hpp"

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
