#include "contact/fixed_tets.hpp"

#include <algorithm>

#include "common/exchange.hpp"
#include "common/held_bytes.hpp"

namespace softbody {

namespace {

// A region box travelling to every rank, with the rank it is for.
struct RegionRecord {
  PetscMPIInt rank;
  double lower[3], upper[3];
};

}  // namespace

void FixedTets::Setup(MPI_Comm comm, FixedTetShare share, int64_t scene_count) {
  comm_ = comm;
  scene_count_ = scene_count;
  share_ = std::move(share);
  std::vector<Box> boxes(share_.tets.size());
  for (size_t t = 0; t < boxes.size(); ++t) boxes[t] = BoxOf(t);
  share_grid_.Build(boxes);
}

FixedTetRecord FixedTets::Record(size_t t) const {
  FixedTetRecord r{share_.tets[t], {}};
  for (int k = 0; k < 4; ++k) {
    const Point &x = share_.rest[share_.corners[t][k]];
    for (int c = 0; c < 3; ++c) r.corners[3 * k + c] = x[c];
  }
  return r;
}

Box FixedTets::BoxOf(size_t t) const {
  Box box;
  for (int k = 0; k < 4; ++k) box.Extend(share_.rest[share_.corners[t][k]]);
  return box;
}

void FixedTets::ReleaseShare() {
  share_ = FixedTetShare();
  share_grid_ = UniformGrid();
}

int64_t FixedTets::HeldBytes() const {
  return softbody::HeldBytes(share_.tets) + softbody::HeldBytes(share_.corners) +
         softbody::HeldBytes(share_.rest) + softbody::HeldBytes(held_) +
         softbody::HeldBytes(region_);
}

bool FixedTets::InRegion(const Point &p) const {
  return std::any_of(region_.begin(), region_.end(), [&](const Box &b) { return b.Contains(p); });
}

// Every rank's region boxes gathered; each rank sends the tets of its share
// that meet a rank's new boxes and none of its previous ones (which it holds)
// to that rank, each once; a rank keeps the held tets that meet its new boxes.
PetscErrorCode FixedTets::Fetch(const std::vector<Box> &region, const HeldBox &held_box,
                                const Place &place, bool *changed) {
  PetscFunctionBeginUser;
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  std::vector<RegionRecord> mine, gathered;
  for (const Box &b : region)
    if (!b.Empty())
      mine.push_back(
          {rank, {b.lower[0], b.lower[1], b.lower[2]}, {b.upper[0], b.upper[1], b.upper[2]}});
  PetscCall(AllGatherRecords(comm_, mine, &gathered));  // ranks in order
  std::vector<RegionBox> all(gathered.size());
  for (size_t i = 0; i < gathered.size(); ++i) {
    all[i].rank = gathered[i].rank;
    all[i].box.lower = Point(gathered[i].lower);
    all[i].box.upper = Point(gathered[i].upper);
  }
  std::vector<FixedTetRecord> send;
  std::vector<size_t> to_self;  // tets of the share for this rank: no record
  std::vector<int> counts(size, 0);
  // The last rank for which a tet was settled: sent, or held by its last region.
  std::vector<PetscMPIInt> settled(share_.tets.size(), -1);
  auto held_by = [&](PetscMPIInt r, const Box &box, bool whole) {  // r's last region holds it
    for (const RegionBox &p : all_regions_)
      if (p.rank == r &&
          (whole ? p.box.Contains(box.lower) && p.box.Contains(box.upper) : p.box.Overlaps(box)))
        return true;
    return false;
  };
  for (const RegionBox &r : all) {
    if (held_by(r.rank, r.box, true)) continue;  // nothing new in it
    share_grid_.ForEachInBox(r.box, [&](int32_t t) {
      if (settled[t] == r.rank) return;
      const Box box = BoxOf(t);
      if (!box.Overlaps(r.box)) return;
      settled[t] = r.rank;
      if (held_by(r.rank, box, false)) return;
      if (r.rank == rank) {
        to_self.push_back(t);
        return;
      }
      send.push_back(Record(t));
      ++counts[r.rank];
    });
  }
  std::vector<FixedTetRecord> received;
  PetscCall(ExchangeRecords(comm_, send, counts, &received));
  const size_t before = held_.size();
  KeepMeeting(region, held_box);
  *changed = held_.size() != before || !received.empty() || !to_self.empty();
  for (const FixedTetRecord &r : received) {
    held_.push_back(r.tet);
    for (int k = 0; k < 4; ++k) place(r.tet.item[k], r.corner(k));
  }
  for (const size_t t : to_self) {
    held_.push_back(share_.tets[t]);
    for (int k = 0; k < 4; ++k) place(share_.tets[t].item[k], share_.rest[share_.corners[t][k]]);
  }
  std::sort(
      held_.begin(), held_.end(),
      [](const IndexedItem<FreeTet> &a, const IndexedItem<FreeTet> &b) { return a.id < b.id; });
  region_ = region;
  all_regions_ = std::move(all);
  ++fetches_;
  PetscFunctionReturn(PETSC_SUCCESS);
}

void FixedTets::KeepMeeting(const std::vector<Box> &region, const HeldBox &held_box) {
  auto inside = [](const Box &a, const Box &b) {  // a within b
    return b.Contains(a.lower) && b.Contains(a.upper);
  };
  if (std::all_of(region_.begin(), region_.end(), [&](const Box &old) {
        return old.Empty() || std::any_of(region.begin(), region.end(),
                                          [&](const Box &b) { return inside(old, b); });
      }))
    return;
  std::vector<IndexedItem<FreeTet>> kept;
  for (const IndexedItem<FreeTet> &tet : held_) {
    const Box box = held_box(tet.item);
    if (std::any_of(region.begin(), region.end(), [&](const Box &b) { return b.Overlaps(box); }))
      kept.push_back(tet);
  }
  held_ = std::move(kept);
}

PetscErrorCode FixedTets::Covered(const std::vector<Point> &points,
                                  const std::vector<int32_t> &bodies,
                                  std::vector<char> *covered) const {
  PetscFunctionBeginUser;
  covered->assign(points.size(), 0);
  for (size_t i = 0; i < points.size(); ++i)
    share_grid_.ForEachNear(points[i], 0.0, [&](int32_t t) {
      if ((*covered)[i] || share_.tets[t].item[4] == bodies[i]) return;
      const auto &corner = share_.corners[t];
      (*covered)[i] = TetHolds(points[i], BoxOf(t), share_.rest[corner[0]], share_.rest[corner[1]],
                               share_.rest[corner[2]], share_.rest[corner[3]]);
    });
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, covered->data(), static_cast<int>(covered->size()),
                             MPI_UNSIGNED_CHAR, MPI_MAX, comm_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
