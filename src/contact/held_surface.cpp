#include "contact/held_surface.hpp"

#include <algorithm>
#include <iterator>

namespace softbody {

namespace {

// A primitive's key: its lowest vertex.
int32_t KeyOf(const SurfacePrimitive &p) {
  return std::min(p.vertices[0], p.edge() ? p.vertices[1] : std::min(p.vertices[1], p.vertices[2]));
}

// A primitive with its vertices as whole indices.
template <size_t N>
SurfacePrimitive Whole(const ContactSurface &s, int32_t id, const std::array<int32_t, N> &held) {
  SurfacePrimitive p{id, {kNoSurfaceVertex, kNoSurfaceVertex, kNoSurfaceVertex}};
  for (size_t k = 0; k < N; ++k) p.vertices[k] = s.global[held[k]];
  return p;
}

// Of s's triangles (or edges): those kept (their vertices all static or one
// own) into *kept_items, marking their vertices in *kept; the others keyed at
// a received vertex (received(whole)) into *halo_items; as whole primitives.
template <size_t N, class Received>
void SortPrimitives(const ContactSurface &s, const std::vector<std::array<int32_t, N>> &items,
                    const std::vector<char> &own, const std::vector<char> &moving,
                    Received received, std::vector<char> *kept,
                    std::vector<SurfacePrimitive> *kept_items,
                    std::vector<SurfacePrimitive> *halo_items) {
  for (size_t i = 0; i < items.size(); ++i) {
    bool fixed = true, at_own = false;
    for (const int32_t v : items[i]) fixed = fixed && !moving[v], at_own = at_own || own[v];
    const SurfacePrimitive p = Whole(s, N == 3 ? s.triangle_id[i] : kNoSurfaceVertex, items[i]);
    if (fixed || at_own) {
      for (const int32_t v : items[i]) (*kept)[v] = 1;
      kept_items->push_back(p);
    } else if (received(KeyOf(p))) {
      halo_items->push_back(p);
    }
  }
}

// The whole surface's order: triangles by index, edges by vertices.
bool Before(const SurfacePrimitive &p, const SurfacePrimitive &q) {
  return p.edge() ? p.vertices < q.vertices : p.id < q.id;
}

// a and b (each in the whole order) merged, each primitive once.
std::vector<SurfacePrimitive> Union(const std::vector<SurfacePrimitive> &a,
                                    const std::vector<SurfacePrimitive> &b) {
  std::vector<SurfacePrimitive> all;
  all.reserve(a.size() + b.size());
  std::merge(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(all), Before);
  all.erase(std::unique(all.begin(), all.end(),
                        [](const SurfacePrimitive &p, const SurfacePrimitive &q) {
                          return !Before(p, q) && !Before(q, p);
                        }),
            all.end());
  return all;
}

// Per body, the start of its run in a list grouped by body (size bodies + 1).
std::vector<int32_t> Starts(size_t num_bodies, const std::vector<int32_t> &body_of_item) {
  std::vector<int32_t> start(num_bodies + 1, 0);
  for (const int32_t b : body_of_item) ++start[b + 1];
  for (size_t b = 0; b < num_bodies; ++b) start[b + 1] += start[b];
  return start;
}

// The held vertices: `before`'s kept ones and the received ones, whole increasing.
void AddVertices(const ContactSurface &before, const std::vector<char> &kept,
                 const std::vector<SurfaceVertex> &received, ContactSurface *held) {
  std::vector<SurfaceVertex> mine;
  for (int32_t v = 0; v < before.num_vertices(); ++v)
    if (kept[v]) mine.push_back({before.global[v], before.natural[v], before.body[v]});
  std::vector<SurfaceVertex> all;
  all.reserve(mine.size() + received.size());
  std::merge(mine.begin(), mine.end(), received.begin(), received.end(), std::back_inserter(all),
             [](const SurfaceVertex &a, const SurfaceVertex &b) { return a.whole < b.whole; });
  all.erase(std::unique(
                all.begin(), all.end(),
                [](const SurfaceVertex &a, const SurfaceVertex &b) { return a.whole == b.whole; }),
            all.end());
  for (const SurfaceVertex &v : all) {
    held->global.push_back(v.whole);
    held->natural.push_back(v.natural);
    held->body.push_back(v.body);
  }
}

// The primitives (whole, in the whole order) whose vertices are all held, as
// held indices, into *items, the triangles' ids into *ids, the others into
// *missing; returns each added one's body.
template <size_t N>
std::vector<int32_t> AddPrimitives(const std::vector<SurfacePrimitive> &primitives,
                                   ContactSurface *held, std::vector<std::array<int32_t, N>> *items,
                                   std::vector<int32_t> *ids,
                                   std::vector<SurfacePrimitive> *missing) {
  auto index = [&](int32_t whole) {
    const auto at = std::lower_bound(held->global.begin(), held->global.end(), whole);
    return at != held->global.end() && *at == whole
               ? static_cast<int32_t>(at - held->global.begin())
               : kNoSurfaceVertex;
  };
  std::vector<int32_t> body;
  for (const SurfacePrimitive &p : primitives) {
    std::array<int32_t, N> item;
    for (size_t k = 0; k < N; ++k) item[k] = index(p.vertices[k]);
    if (std::find(item.begin(), item.end(), kNoSurfaceVertex) != item.end()) {
      missing->push_back(p);
      continue;
    }
    items->push_back(item);
    if (ids) ids->push_back(p.id);
    body.push_back(held->body[item[0]]);
  }
  return body;
}

}  // namespace

void AssembleHeldSurface(const ContactSurface &before, const std::vector<char> &own,
                         const std::vector<char> &moving,
                         const std::vector<SurfaceVertex> &received,
                         const std::vector<SurfacePrimitive> &primitives,
                         std::vector<SurfacePrimitive> *pending, ContactSurface *held) {
  auto in_halo = [&](int32_t whole) {
    return std::binary_search(
        received.begin(), received.end(), SurfaceVertex{whole, 0, 0},
        [](const SurfaceVertex &a, const SurfaceVertex &b) { return a.whole < b.whole; });
  };
  std::vector<char> kept(before.num_vertices(), 0);
  for (int32_t v = 0; v < before.num_vertices(); ++v) kept[v] = !moving[v] || own[v];
  std::vector<SurfacePrimitive> triangles, edges, halo_triangles, halo_edges;
  SortPrimitives(before, before.triangles, own, moving, in_halo, &kept, &triangles,
                 &halo_triangles);
  SortPrimitives(before, before.edges, own, moving, in_halo, &kept, &edges, &halo_edges);
  for (const auto *list :
       {static_cast<const std::vector<SurfacePrimitive> *>(pending), &primitives})
    for (const SurfacePrimitive &p : *list)
      if (in_halo(KeyOf(p))) (p.edge() ? halo_edges : halo_triangles).push_back(p);
  std::sort(halo_triangles.begin(), halo_triangles.end(), Before);
  std::sort(halo_edges.begin(), halo_edges.end(), Before);
  ContactSurface &s = *held;
  s = ContactSurface();
  AddVertices(before, kept, received, &s);
  pending->clear();
  const std::vector<int32_t> triangle_body =
      AddPrimitives(Union(triangles, halo_triangles), &s, &s.triangles, &s.triangle_id, pending);
  const std::vector<int32_t> edge_body =
      AddPrimitives<2>(Union(edges, halo_edges), &s, &s.edges, nullptr, pending);
  pending->shrink_to_fit();
  const size_t bodies = before.num_bodies();
  s.vertex_start = Starts(bodies, s.body);
  s.triangle_start = Starts(bodies, triangle_body);
  s.edge_start = Starts(bodies, edge_body);
  // Exact capacity: the run summary counts the bytes a rank holds.
  for (auto *list : {&s.global, &s.natural, &s.body, &s.triangle_id}) list->shrink_to_fit();
  s.triangles.shrink_to_fit();
  s.edges.shrink_to_fit();
}

}  // namespace softbody
