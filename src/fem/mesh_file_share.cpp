#include "fem/mesh_file_share.hpp"

#include <limits>
#include <string>
#include <vector>

#include "common/errors.hpp"
#include "fem/mesh.hpp"
#include "io/mesh_h5.hpp"

namespace softbody {

namespace {

// A tag for the running sum's messages (any tag would do: only these travel
// between MPI_Send and MPI_Recv on the duplicated communicator).
constexpr int kRunningSumTag = 1;

using Rows3 = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

// Collective. The corners of the share's tets (4 rows per tet) from the slabs.
PetscErrorCode TetCornersFromSlabs(MPI_Comm comm, const MeshShare &share, Rows3 *corners) {
  PetscFunctionBeginUser;
  std::vector<PetscInt> naturals;
  naturals.reserve(4 * share.tets.size());
  for (const auto &tet : share.tets) naturals.insert(naturals.end(), tet.begin(), tet.end());
  corners->resize(naturals.size(), 3);
  PetscSF sf;
  PetscCall(CreateSlabSF(comm, share, naturals, &sf));
  PetscCall(FetchFromSlabs(sf, MPI_DOUBLE, 3, share.rest.data(), corners->data()));
  PetscCall(PetscSFDestroy(&sf));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. VolumeWeightedCentroid of the whole mesh with its sums formed in
// file order: rank r continues the running sums of ranks 0 .. r-1 (point-to-point
// on a duplicate of comm, O(P) latency once at set-up), the last rank divides and
// broadcasts. Written by hand because a reduction would sum in another order.
PetscErrorCode OrderedCentroid(MPI_Comm comm, const Rows3 &corners, Eigen::Vector3d *centroid) {
  PetscFunctionBeginUser;
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  MPI_Comm ordered;
  PetscCallMPI(MPI_Comm_dup(comm, &ordered));
  double sums[4] = {0, 0, 0, 0};  // weighted centroid (3), total volume
  if (rank > 0)
    PetscCallMPI(
        MPI_Recv(sums, 4, MPI_DOUBLE, rank - 1, kRunningSumTag, ordered, MPI_STATUS_IGNORE));
  Eigen::Vector3d weighted(sums[0], sums[1], sums[2]);
  double total = sums[3];
  for (Eigen::Index t = 0; t < corners.rows() / 4; ++t) {  // as VolumeWeightedCentroid
    const TetPositions X = corners.middleRows<4>(4 * t);
    const double volume = std::abs(SignedVolume(X));
    weighted += volume * X.colwise().mean().transpose();
    total += volume;
  }
  double result[3];
  for (int c = 0; c < 3; ++c) result[c] = weighted[c] / total;
  if (rank + 1 < size) {
    const double running[4] = {weighted[0], weighted[1], weighted[2], total};
    PetscCallMPI(MPI_Send(running, 4, MPI_DOUBLE, rank + 1, kRunningSumTag, ordered));
  }
  PetscCallMPI(MPI_Bcast(result, 3, MPI_DOUBLE, size - 1, ordered));
  PetscCallMPI(MPI_Comm_free(&ordered));
  *centroid = Eigen::Vector3d(result[0], result[1], result[2]);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. The placed tets' checks of the serial reader (LoadPlacedMesh):
// finite positions, no tet degenerate once placed; the first failure (lowest tet)
// on every rank as one message.
PetscErrorCode CheckPlaced(MPI_Comm comm, const Scene &scene, const Body &body,
                           const MeshShare &share) {
  PetscFunctionBeginUser;
  const std::string &path = body.mesh_path;
  int finite = share.rest.allFinite();
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &finite, 1, MPI_INT, MPI_LAND, comm));
  PetscCheck(finite, comm, PETSC_ERR_USER_INPUT, "%s",
             Where(scene.path, 0,
                   "mesh " + path + ": placing it overflows (position or coordinates too large)")
                 .c_str());
  Rows3 corners;
  PetscCall(TetCornersFromSlabs(comm, share, &corners));
  int64_t first_bad = std::numeric_limits<int64_t>::max();
  for (Eigen::Index t = 0;
       first_bad == std::numeric_limits<int64_t>::max() && t < corners.rows() / 4; ++t)
    if (IsDegenerateTet(corners.middleRows<4>(4 * t))) first_bad = share.first_tet + t;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &first_bad, 1, MPI_INT64_T, MPI_MIN, comm));
  PetscCheck(first_bad == std::numeric_limits<int64_t>::max(), comm, PETSC_ERR_USER_INPUT, "%s",
             Where(scene.path, 0,
                   "mesh " + path + ": tetrahedron " + std::to_string(first_bad + 1) +
                       " is degenerate once placed (position too far from the origin for the "
                       "mesh's size)")
                 .c_str());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The body's share from its file's slabs, in the file's numbering (no initial
// velocities: the scene's share fetches them).
PetscErrorCode ShareOfSlabs(MPI_Comm comm, const Body &body, const MeshSlabs &slabs,
                            MeshShare *share) {
  PetscFunctionBeginUser;
  PetscCheck(slabs.num_tets <= PETSC_MAX_INT, comm, PETSC_ERR_SUP,
             "mesh %s: %lld tets: more than this PETSc's indices hold", body.mesh_path.c_str(),
             static_cast<long long>(slabs.num_tets));
  share->num_vertices = static_cast<PetscInt>(slabs.num_vertices);
  share->first_vertex = static_cast<PetscInt>(slabs.first_vertex);
  share->rest = slabs.vertices;
  share->num_all_tets = slabs.num_tets;
  share->first_tet = slabs.first_tet;
  share->tets.resize(slabs.tets.rows());
  for (Eigen::Index t = 0; t < slabs.tets.rows(); ++t)
    for (int a = 0; a < 4; ++a) share->tets[t][a] = static_cast<PetscInt>(slabs.tets(t, a));
  share->tet_body.assign(share->tets.size(), 0);
  share->body_fixed.assign(1, body.fixed);
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode ReadBodyShareFromFile(MPI_Comm comm, const Scene &scene, size_t b,
                                     MeshShare *share) {
  PetscFunctionBeginUser;
  const Body &body = scene.bodies[b];
  PetscCheck(body.mesh_deferred, comm, PETSC_ERR_PLIB, "mesh %s: not a deferred .h5 mesh",
             body.mesh_path.c_str());
  *share = MeshShare();
  {
    MeshSlabs slabs;
    PetscCall(ReadMeshSlabs(comm, body.mesh_path, &slabs));
    PetscCall(ShareOfSlabs(comm, body, slabs, share));
  }
  Rows3 corners;
  PetscCall(TetCornersFromSlabs(comm, *share, &corners));
  PetscCall(CheckTetVolumes(comm, body.mesh_path, share->first_tet, corners));
  Eigen::Vector3d centroid;
  PetscCall(OrderedCentroid(comm, corners, &centroid));
  PlaceVertices(centroid, body.position, body.quaternion, &share->rest);
  PetscCall(CheckPlaced(comm, scene, body, *share));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
