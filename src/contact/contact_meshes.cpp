#include "contact/contact_meshes.hpp"

#include <algorithm>
#include <limits>

#include "common/even_share.hpp"
#include "common/exchange.hpp"
#include "fem/share_boundary.hpp"

namespace softbody {

namespace {

// The rank whose vertex slab holds natural vertex n (of `count`, over `size` ranks).
PetscMPIInt SlabOwner(int64_t count, PetscMPIInt size, int64_t n) {
  PetscMPIInt low = 0, high = size - 1;  // EvenShareBegin(low) <= n < EvenShareBegin(high + 1)
  while (low < high) {
    const PetscMPIInt mid = (low + high + 1) / 2;
    if (EvenShareBegin(count, size, mid) <= n)
      low = mid;
    else
      high = mid - 1;
  }
  return low;
}

// A boundary triangle travelling to every rank: natural vertices.
using TriangleRecord = std::array<int32_t, 3>;
// A request for the tets listed under a key vertex.
struct KeyRequest {
  int32_t key;
  PetscMPIInt rank;  // who asks
};

std::vector<int32_t> SortedUnique(std::vector<int32_t> values) {
  std::sort(values.begin(), values.end());
  values.erase(std::unique(values.begin(), values.end()), values.end());
  return values;
}

}  // namespace

PetscErrorCode ContactMeshes::Build(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                                    const MeshShare &share) {
  PetscFunctionBeginUser;
  comm_ = comm;
  PetscCallMPI(MPI_Comm_size(comm, &size_));
  scene_ = &scene;
  layout_ = &layout;
  share_ = &share;
  PetscCheck(share.num_vertices == scene.num_vertices() && share.num_all_tets == scene.num_tets(),
             comm, PETSC_ERR_PLIB, "contact's set-up needs the ranks' shares of the meshes");
  rest_.setConstant(1, 3, std::numeric_limits<double>::quiet_NaN());
  PetscCall(GatherBoundaries());
  PetscCall(FindLongestEdges());
  PetscCall(FindFixedBoxes());
  PetscCall(SendTetsToKeyOwners());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Every rank's boundary triangles (ShareBoundaryTriangles), gathered: in rank
// order they are each body's BoundaryTriangles rows in turn.
PetscErrorCode ContactMeshes::GatherBoundaries() {
  PetscFunctionBeginUser;
  std::vector<TriangleRecord> all;
  {
    std::vector<std::array<PetscInt, 3>> mine;
    PetscCall(ShareBoundaryTriangles(comm_, *share_, &mine));
    std::vector<TriangleRecord> records(mine.size());
    for (size_t t = 0; t < mine.size(); ++t)
      for (int k = 0; k < 3; ++k) records[t][k] = static_cast<int32_t>(mine[t][k]);
    PetscCall(AllGatherRecords(comm_, records, &all));
  }
  const size_t bodies = scene_->bodies.size();
  std::vector<Eigen::Index> count(bodies, 0);
  for (const TriangleRecord &t : all) ++count[BodyOfNatural(*scene_, t[0])];
  boundary_.resize(bodies);
  for (size_t b = 0; b < bodies; ++b) boundary_[b].resize(count[b], 3);
  std::vector<Eigen::Index> row(bodies, 0);
  for (const TriangleRecord &t : all) {
    const int32_t b = BodyOfNatural(*scene_, t[0]);
    for (int k = 0; k < 3; ++k) boundary_[b](row[b], k) = t[k] - scene_->bodies[b].first_vertex;
    ++row[b];
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Per body, the longest edge of its tets at rest: each rank's share, then a maximum.
PetscErrorCode ContactMeshes::FindLongestEdges() {
  PetscFunctionBeginUser;
  std::vector<PetscInt> naturals;
  naturals.reserve(4 * share_->tets.size());
  for (const auto &tet : share_->tets) naturals.insert(naturals.end(), tet.begin(), tet.end());
  Positions corners(naturals.size(), 3);
  PetscSF sf;
  PetscCall(CreateSlabSF(comm_, *share_, naturals, &sf));
  PetscCall(FetchFromSlabs(sf, MPI_DOUBLE, 3, share_->rest.data(), corners.data()));
  PetscCall(PetscSFDestroy(&sf));
  longest_edge_.assign(scene_->bodies.size(), 0.0);
  for (size_t t = 0; t < share_->tets.size(); ++t) {
    double &longest = longest_edge_[share_->tet_body[t]];
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j)
        longest = std::max(longest, (corners.row(4 * t + i) - corners.row(4 * t + j)).norm());
  }
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, longest_edge_.data(),
                             static_cast<int>(longest_edge_.size()), MPI_DOUBLE, MPI_MAX, comm_));
  KeepFixedShare(corners);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The share's fixed tets with their corners (rows 4 t .. 4 t + 3 of corners),
// named by their index in the scene's list of fixed tets; each corner once.
void ContactMeshes::KeepFixedShare(const Positions &corners) {
  const size_t bodies = scene_->bodies.size();
  std::vector<int64_t> free_before(bodies + 1, 0);  // tets of free bodies before body b
  for (size_t b = 0; b < bodies; ++b)
    free_before[b + 1] =
        free_before[b] + (scene_->bodies[b].fixed ? 0 : scene_->bodies[b].num_tets());
  num_fixed_tets_ = scene_->num_tets() - free_before[bodies];
  std::vector<size_t> rows;  // the share's rows of the fixed tets
  std::vector<int32_t> naturals;
  for (size_t t = 0; t < share_->tets.size(); ++t) {
    const int32_t b = share_->tet_body[t];
    if (!scene_->bodies[b].fixed) continue;
    rows.push_back(t);
    for (int a = 0; a < 4; ++a) naturals.push_back(static_cast<int32_t>(share_->tets[t][a]));
  }
  naturals = SortedUnique(std::move(naturals));
  FixedTetShare &fixed = fixed_share_;
  fixed.rest.resize(naturals.size());
  fixed.tets.reserve(rows.size());
  fixed.corners.reserve(rows.size());
  for (const size_t t : rows) {
    const int32_t b = share_->tet_body[t];
    IndexedItem<FreeTet> tet{
        -1, static_cast<int32_t>(share_->first_tet + static_cast<int64_t>(t) - free_before[b]), {}};
    std::array<int32_t, 4> corner;
    for (int a = 0; a < 4; ++a) {
      tet.item[a] = static_cast<int32_t>(share_->tets[t][a]);
      corner[a] = static_cast<int32_t>(
          std::lower_bound(naturals.begin(), naturals.end(), tet.item[a]) - naturals.begin());
      fixed.rest[corner[a]] = corners.row(4 * t + a).transpose();
    }
    tet.item[4] = b;
    fixed.tets.push_back(tet);
    fixed.corners.push_back(corner);
  }
}

// Per fixed body, the box of its vertices: each rank's slab, then MPI_MAX over
// (-lower, upper).
PetscErrorCode ContactMeshes::FindFixedBoxes() {
  PetscFunctionBeginUser;
  const size_t bodies = scene_->bodies.size();
  std::vector<double> bounds(6 * bodies, -kUnbounded);
  for (PetscInt i = 0; i < share_->slab_size(); ++i) {
    const int32_t b = BodyOfNatural(*scene_, static_cast<int32_t>(share_->first_vertex + i));
    if (!scene_->bodies[b].fixed) continue;
    for (int c = 0; c < 3; ++c) {
      bounds[6 * b + c] = std::max(bounds[6 * b + c], -share_->rest(i, c));
      bounds[6 * b + 3 + c] = std::max(bounds[6 * b + 3 + c], share_->rest(i, c));
    }
  }
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, bounds.data(), static_cast<int>(bounds.size()),
                             MPI_DOUBLE, MPI_MAX, comm_));
  fixed_box_.assign(bodies, Box());
  for (size_t b = 0; b < bodies; ++b)
    if (scene_->bodies[b].fixed) {
      fixed_box_[b].lower = -Point(&bounds[6 * b]);
      fixed_box_[b].upper = Point(&bounds[6 * b + 3]);
    }
  PetscFunctionReturn(PETSC_SUCCESS);
}

int32_t ContactMeshes::KeyOf(const FreeTet &tet) const {
  for (int a = 0; a < 4; ++a)
    if (layout_->PetscVertexOfNatural(tet[a]) >= 0) return tet[a];
  return -1;
}

// The share's free tets, each to the slab owner of its key (keyed_, sorted by
// key and index); those without a key to every rank (static_).
PetscErrorCode ContactMeshes::SendTetsToKeyOwners() {
  PetscFunctionBeginUser;
  const size_t bodies = scene_->bodies.size();
  std::vector<int64_t> fixed_before(bodies + 1, 0);  // tets of fixed bodies before body b
  for (size_t b = 0; b < bodies; ++b)
    fixed_before[b + 1] =
        fixed_before[b] + (scene_->bodies[b].fixed ? scene_->bodies[b].num_tets() : 0);
  num_free_tets_ = scene_->num_tets() - fixed_before[bodies];
  PetscCheck(num_free_tets_ <= std::numeric_limits<int32_t>::max(), comm_, PETSC_ERR_SUP,
             "%lld free tets: more than contact's 32-bit indices hold",
             static_cast<long long>(num_free_tets_));
  std::vector<IndexedItem<FreeTet>> sent, keyless;
  for (size_t t = 0; t < share_->tets.size(); ++t) {
    const int32_t b = share_->tet_body[t];
    if (scene_->bodies[b].fixed) continue;
    FreeTet tet;
    for (int a = 0; a < 4; ++a) tet[a] = static_cast<int32_t>(share_->tets[t][a]);
    tet[4] = b;
    const int32_t id =
        static_cast<int32_t>(share_->first_tet + static_cast<int64_t>(t) - fixed_before[b]);
    const int32_t key = KeyOf(tet);
    (key < 0 ? keyless : sent).push_back({key, id, tet});
  }
  std::sort(sent.begin(), sent.end());  // by key, so by slab owner
  std::vector<int> counts(size_, 0);
  for (const auto &item : sent) ++counts[SlabOwner(share_->num_vertices, size_, item.key)];
  PetscCall(ExchangeRecords(comm_, sent, counts, &keyed_));
  std::sort(keyed_.begin(), keyed_.end());
  PetscCall(AllGatherRecords(comm_, keyless, &static_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactMeshes::FetchRest(const std::vector<int32_t> &naturals) {
  PetscFunctionBeginUser;
  std::vector<int32_t> wanted;
  for (const int32_t n : SortedUnique(naturals))
    if (!std::binary_search(rest_natural_.begin(), rest_natural_.end(), n)) wanted.push_back(n);
  Positions fetched(wanted.size(), 3);
  PetscSF sf;
  PetscCall(CreateSlabSF(comm_, *share_, std::vector<PetscInt>(wanted.begin(), wanted.end()), &sf));
  PetscCall(FetchFromSlabs(sf, MPI_DOUBLE, 3, share_->rest.data(), fetched.data()));
  PetscCall(PetscSFDestroy(&sf));
  // Merge with what was fetched before; the NaN row stays last.
  std::vector<int32_t> merged;
  merged.reserve(rest_natural_.size() + wanted.size());
  std::merge(rest_natural_.begin(), rest_natural_.end(), wanted.begin(), wanted.end(),
             std::back_inserter(merged));
  Positions rest(merged.size() + 1, 3);
  for (size_t k = 0, i = 0, j = 0; k < merged.size(); ++k)
    if (i < rest_natural_.size() && rest_natural_[i] == merged[k])
      rest.row(k) = rest_.row(i++);
    else
      rest.row(k) = fetched.row(j++);
  rest.row(merged.size()) = rest_.row(rest_.rows() - 1);
  rest_natural_ = std::move(merged);
  rest_ = std::move(rest);
  PetscFunctionReturn(PETSC_SUCCESS);
}

ContactMeshes::Positions::ConstRowXpr ContactMeshes::rest_row(int32_t natural) const {
  const Body &body = scene_->bodies[BodyOfNatural(*scene_, natural)];
  if (body.mesh.num_vertices() == body.num_vertices() && body.mesh.num_vertices() > 0)
    return body.mesh.vertices.row(natural - body.first_vertex);
  const auto at = std::lower_bound(rest_natural_.begin(), rest_natural_.end(), natural);
  const bool found = at != rest_natural_.end() && *at == natural;
  return rest_.row(found ? at - rest_natural_.begin() : rest_.rows() - 1);
}

PetscErrorCode ContactMeshes::FetchFreeTets(const std::vector<int32_t> &keys) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  std::vector<KeyRequest> requests, asked;
  std::vector<int> counts(size_, 0);
  for (const int32_t key : SortedUnique(keys)) {
    if (key < 0) continue;
    requests.push_back({key, rank});
    ++counts[SlabOwner(share_->num_vertices, size_, key)];
  }
  PetscCall(ExchangeRecords(comm_, requests, counts, &asked));  // askers in rank order
  std::vector<IndexedItem<FreeTet>> replies;
  counts.assign(size_, 0);
  for (const KeyRequest &request : asked) {
    auto at = std::lower_bound(
        keyed_.begin(), keyed_.end(), request.key,
        [](const IndexedItem<FreeTet> &item, int32_t key) { return item.key < key; });
    for (; at != keyed_.end() && at->key == request.key; ++at) {
      replies.push_back(*at);
      ++counts[request.rank];
    }
  }
  std::vector<IndexedItem<FreeTet>>().swap(keyed_);
  PetscCall(ExchangeRecords(comm_, replies, counts, &free_tets_));
  free_tets_.insert(free_tets_.end(), static_.begin(), static_.end());
  std::vector<IndexedItem<FreeTet>>().swap(static_);
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
