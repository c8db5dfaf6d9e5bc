#include "contact/free_items.hpp"

#include <type_traits>

#include "common/held_bytes.hpp"
#include "contact/contact_meshes.hpp"

namespace softbody {

namespace {

// An item's key: its first corner with unknowns (-1: none, a static item).
template <class Item>
int32_t KeyOf(const Item &item, const std::function<bool(int32_t)> &is_free) {
  const auto corner = std::find_if(item.begin(), item.end() - 1, is_free);
  return corner == item.end() - 1 ? -1 : *corner;
}

// Exact capacity: the lists' bytes are what the run summary counts.
template <class T>
void Fit(std::vector<T> *v) {
  v->shrink_to_fit();
}

}  // namespace

// A tet or a triangle travelling with its key vertex (a triangle's fourth
// corner is kNoCorner).
struct FreeItems::Record {
  static constexpr int32_t kNoCorner = -1;
  int32_t key, id, corner[4], body;
  bool triangle() const { return corner[3] == kNoCorner; }
};

void FreeItems::Setup(const Scene &scene, const ContactMeshes &meshes,
                      const std::function<bool(int32_t)> &is_free,
                      const std::function<bool(int32_t)> &kept) {
  const uint64_t generation = generation_ + 1;  // grids of the lists before are stale
  *this = FreeItems();
  generation_ = generation;
  // The tets counted first, so that their lists are allocated once at their size.
  size_t own = 0, stat = 0;
  for (const IndexedItem<FreeTet> &tet : meshes.free_tets()) {
    const int32_t key = KeyOf(tet.item, is_free);
    own += key >= 0 && kept(key);
    stat += key < 0;
  }
  own_tets_.reserve(own);
  static_tets_.reserve(stat);
  for (const IndexedItem<FreeTet> &tet : meshes.free_tets()) {
    const int32_t key = KeyOf(tet.item, is_free);
    if (key < 0)
      static_tets_.push_back({key, tet.id, tet.item});
    else if (kept(key))
      own_tets_.push_back({key, tet.id, tet.item});
  }
  int32_t triangle_id = 0;
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    if (body.fixed) continue;
    const int32_t first = body.first_vertex, body_id = static_cast<int32_t>(b);
    const auto &boundary = meshes.boundary(b);
    for (Eigen::Index f = 0; f < boundary.rows(); ++f) {
      const FreeTriangle item{first + boundary(f, 0), first + boundary(f, 1),
                              first + boundary(f, 2), body_id};
      const int32_t key = KeyOf(item, is_free), id = triangle_id++;
      if (key < 0)
        static_triangles_.push_back({key, id, item});
      else if (kept(key))
        own_triangles_.push_back({key, id, item});
    }
  }
  num_tets_ = meshes.num_free_tets();
  std::sort(own_tets_.begin(), own_tets_.end());
  std::sort(static_tets_.begin(), static_tets_.end());
  std::sort(own_triangles_.begin(), own_triangles_.end());
  Fit(&own_triangles_);
  Fit(&static_triangles_);
}

int64_t FreeItems::HeldBytes() const {
  using softbody::HeldBytes;
  return HeldBytes(own_tets_) + HeldBytes(halo_tets_) + HeldBytes(own_triangles_) +
         HeldBytes(halo_triangles_) + HeldBytes(static_tets_) + HeldBytes(static_triangles_) +
         HeldBytes(sent_) + HeldBytes(received_);
}

void FreeItems::Pack(const std::vector<PetscMPIInt> &to_ranks,
                     const std::vector<PetscMPIInt> &to_counts, const std::vector<int32_t> &sent,
                     std::vector<Record> *records, std::vector<PetscMPIInt> *counts) {
  std::vector<std::pair<PetscMPIInt, int32_t>> now;
  now.reserve(sent.size());
  for (size_t i = 0, k = 0; i < to_ranks.size(); ++i) {
    const size_t before = records->size();
    for (PetscMPIInt c = 0; c < to_counts[i]; ++c, ++k) {
      const std::pair<PetscMPIInt, int32_t> pair(to_ranks[i], sent[k]);
      now.push_back(pair);
      if (std::binary_search(sent_.begin(), sent_.end(), pair)) continue;
      ForEachOf(own_tets_, sent[k], [&](const IndexedItem<FreeTet> &i) {
        const FreeTet &t = i.item;
        records->push_back({sent[k], i.id, {t[0], t[1], t[2], t[3]}, t[4]});
      });
      ForEachOf(own_triangles_, sent[k], [&](const IndexedItem<FreeTriangle> &i) {
        const FreeTriangle &t = i.item;
        records->push_back({sent[k], i.id, {t[0], t[1], t[2], Record::kNoCorner}, t[3]});
      });
    }
    counts->push_back(static_cast<PetscMPIInt>(records->size() - before));
  }
  std::sort(now.begin(), now.end());
  sent_ = std::move(now);
}

template <class Item, class Make>
void FreeItems::RebuildHalo(const std::vector<int32_t> &now, const std::vector<Record> &records,
                            Make make, List<Item> *list) const {
  auto kept = [&](int32_t n) { return std::binary_search(received_.begin(), received_.end(), n); };
  // Counted first, so that the list is allocated once at its size.
  size_t count = 0;
  for (const Record &r : records) count += r.triangle() == std::is_same_v<Item, FreeTriangle>;
  for (const int32_t n : now)
    if (kept(n)) ForEachOf(*list, n, [&](const IndexedItem<Item> &) { ++count; });
  List<Item> halo;
  halo.reserve(count);
  for (const int32_t n : now)
    if (kept(n)) ForEachOf(*list, n, [&](const IndexedItem<Item> &i) { halo.push_back(i); });
  for (const Record &r : records)
    if (r.triangle() == std::is_same_v<Item, FreeTriangle>) halo.push_back({r.key, r.id, make(r)});
  std::sort(halo.begin(), halo.end());
  *list = std::move(halo);
}

void FreeItems::Unpack(const std::vector<int32_t> &received, const std::vector<Record> &records) {
  std::vector<int32_t> now(received);
  std::sort(now.begin(), now.end());
  RebuildHalo(
      now, records,
      [](const Record &r) {
        return FreeTet{r.corner[0], r.corner[1], r.corner[2], r.corner[3], r.body};
      },
      &halo_tets_);
  RebuildHalo(
      now, records,
      [](const Record &r) {
        return FreeTriangle{r.corner[0], r.corner[1], r.corner[2], r.body};
      },
      &halo_triangles_);
  received_ = std::move(now);
  ++generation_;
}

PetscErrorCode FreeItems::Exchange(const NeighbourExchange &neighbours,
                                   const std::vector<PetscMPIInt> &to_ranks,
                                   const std::vector<PetscMPIInt> &to_counts,
                                   const std::vector<int32_t> &sent,
                                   const std::vector<int32_t> &received, PetscInt64 *bytes_sent) {
  PetscFunctionBeginUser;
  std::vector<Record> records, arrived;
  std::vector<PetscMPIInt> ranks, counts;
  Pack(to_ranks, to_counts, sent, &records, &counts);
  for (size_t i = 0; i < to_ranks.size(); ++i)
    if (counts[i] > 0) ranks.push_back(to_ranks[i]);
  counts.erase(std::remove(counts.begin(), counts.end(), 0), counts.end());
  PetscCall(neighbours.Exchange(ranks, counts, records, &arrived, bytes_sent));
  Unpack(received, arrived);
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
