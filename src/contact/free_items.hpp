// The free bodies' tets and boundary triangles that one rank holds for the
// obstacles' free grids (obstacles.hpp): O(local + halo) tets, not the scene's.
//
// An item is listed under its key, its first corner with unknowns; an item
// without one is static and kept on every rank. A rank keeps for good the tets
// listed under its own vertices and under the fixed and ring sets'
// (free_state.hpp), and the tets listed under its halo's vertices while they
// stay in its halo: the halo exchange calls Exchange, in which the owner of a
// vertex sends the tets listed under it to a rank whose halo the vertex enters
// (it was not sent there at the previous halo exchange), and a rank keeps a
// received vertex's tets until a halo exchange no longer brings the vertex.
// The boundary triangles travel the same way, so no rank holds the scene's
// surface. The free grids bin the items whose corners are all current, found
// under the current vertices: an item whose corners are all current has its
// key current, so every rank finds the same items as if it held the whole
// scene's. An item may be held twice (kept for good under a ring-set vertex
// and received with it in the halo); the grids list each id once.
//
// Items are named by their index in the scene's list (bodies in order, each
// body's tets or boundary triangles in mesh order), the same on every rank, so
// queries can break ties by it.
#pragma once

#include <petscsys.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "common/neighbour_exchange.hpp"
#include "io/scene.hpp"

namespace softbody {

class ContactMeshes;

// A free body's tet: 4 natural vertices, its body.
using FreeTet = std::array<int32_t, 5>;
// A free body's boundary triangle (outward by the right-hand rule): 3 natural
// vertices, its body.
using FreeTriangle = std::array<int32_t, 4>;

// A tet or triangle with its key vertex (-1: none, static) and its index in
// the scene's list.
template <class Item>
struct IndexedItem {
  int32_t key, id;
  Item item;
  bool operator<(const IndexedItem &o) const { return key < o.key || (key == o.key && id < o.id); }
};

class FreeItems {
 public:
  // Not collective. From what contact's set-up fetched of the meshes (set-up
  // only; again replaces all): of meshes.free_tets() and the free bodies'
  // boundary triangles, those listed under the vertices for which
  // kept(natural) holds (this rank's own, the fixed and ring sets') and the
  // static ones; is_free(natural): the vertex has unknowns.
  void Setup(const Scene &scene, const ContactMeshes &meshes,
             const std::function<bool(int32_t)> &is_free, const std::function<bool(int32_t)> &kept);

  // Collective (the free state's halo exchange). to_ranks / to_counts /
  // sent: the natural vertices this rank sent in the halo, grouped by rank as
  // NeighbourExchange takes them; received: the vertices it received. Sends
  // the items of the vertices new to a rank's halo, keeps those of the
  // received vertices. *bytes_sent: the payload sent.
  PetscErrorCode Exchange(const NeighbourExchange &neighbours,
                          const std::vector<PetscMPIInt> &to_ranks,
                          const std::vector<PetscMPIInt> &to_counts,
                          const std::vector<int32_t> &sent, const std::vector<int32_t> &received,
                          PetscInt64 *bytes_sent);

  // Not collective. visit(indexed item) for the items listed under vertex n
  // that this rank holds (each once); the static items. The references stay
  // valid until the next Exchange (generation() tells).
  template <class Visit>
  void ForEachTetOf(int32_t n, Visit visit) const {
    ForEachOf(own_tets_, n, visit);
    ForEachOf(halo_tets_, n, visit);
  }
  template <class Visit>
  void ForEachTriangleOf(int32_t n, Visit visit) const {
    ForEachOf(own_triangles_, n, visit);
    ForEachOf(halo_triangles_, n, visit);
  }
  const std::vector<IndexedItem<FreeTet>> &static_tets() const { return static_tets_; }
  const std::vector<IndexedItem<FreeTriangle>> &static_triangles() const {
    return static_triangles_;
  }
  // How many Exchanges changed the lists.
  uint64_t generation() const { return generation_; }

  // The scene's free tets (all ranks).
  int64_t num_tets() const { return num_tets_; }
  // Bytes of the lists this rank holds.
  int64_t HeldBytes() const;

 private:
  template <class Item>
  using List = std::vector<IndexedItem<Item>>;  // sorted by (key, id)

  template <class Item, class Visit>
  static void ForEachOf(const List<Item> &list, int32_t n, Visit visit) {
    auto at = std::lower_bound(list.begin(), list.end(), n,
                               [](const IndexedItem<Item> &k, int32_t key) { return k.key < key; });
    for (; at != list.end() && at->key == n; ++at) visit(*at);
  }
  // The records for the vertices of `sent` new to their rank's halo; fills
  // *counts per rank of to_ranks.
  struct Record;
  void Pack(const std::vector<PetscMPIInt> &to_ranks, const std::vector<PetscMPIInt> &to_counts,
            const std::vector<int32_t> &sent, std::vector<Record> *records,
            std::vector<PetscMPIInt> *counts);
  // The halo lists: the received vertices' items, kept ones and new ones.
  void Unpack(const std::vector<int32_t> &received, const std::vector<Record> &records);
  // One halo list: of *list, the items of the vertices received before and
  // now (sorted `now`), and the new records' items (make(record)).
  template <class Item, class Make>
  void RebuildHalo(const std::vector<int32_t> &now, const std::vector<Record> &records, Make make,
                   List<Item> *list) const;

  int64_t num_tets_ = 0;
  List<FreeTet> own_tets_, halo_tets_;
  List<FreeTriangle> own_triangles_, halo_triangles_;
  List<FreeTet> static_tets_;  // key -1, id increasing
  List<FreeTriangle> static_triangles_;
  uint64_t generation_ = 0;
  // The previous halo exchange: (rank, vertex) sent, and the vertices received; sorted.
  std::vector<std::pair<PetscMPIInt, int32_t>> sent_;
  std::vector<int32_t> received_;
};

}  // namespace softbody
