#include "contact/surface_collisions.hpp"

#include <algorithm>

namespace softbody {

namespace {

// A primitive's box over the step (start and end of its vertices, the end
// shifted by `shift`), grown by the distance CCD reports within. In the pass
// of one body every position is shifted alike (its mean displacement), so two
// primitives that come close meet in these boxes as in world ones, and a
// falling body's boxes stay small.
template <size_t N>
Box SweptBox(const CollisionQuery &q, const std::array<int32_t, N> &vertices, const Point &shift) {
  Box box;
  for (const int32_t v : vertices) {
    box.Extend((*q.start)[v]);
    box.Extend((*q.end)[v] - shift);
  }
  const double grow = q.tolerance.separation + q.tolerance.band;
  box.lower.array() -= grow;
  box.upper.array() += grow;
  return box;
}

// The boxes of the listed primitives.
struct Boxes {
  std::vector<Box> vertices, triangles, edges;
};
Boxes BoxesOf(const CollisionQuery &q, const std::vector<int32_t> &vertices,
              const std::vector<int32_t> &triangles, const std::vector<int32_t> &edges,
              const Point &shift) {
  Boxes boxes;
  for (const int32_t v : vertices)
    boxes.vertices.push_back(SweptBox(q, std::array<int32_t, 1>{v}, shift));
  for (const int32_t t : triangles)
    boxes.triangles.push_back(SweptBox(q, q.surface->triangles[t], shift));
  for (const int32_t e : edges) boxes.edges.push_back(SweptBox(q, q.surface->edges[e], shift));
  return boxes;
}

bool Shares(const std::array<int32_t, 4> &v) {
  return v[0] == v[2] || v[0] == v[3] || v[1] == v[2] || v[1] == v[3];
}

// Whether a pair is guarded in a pass: something moves, a vertex changed
// (later rounds), the bodies are the same in a self pass and differ otherwise,
// and within a body no vertex is shared.
bool Wanted(const CollisionQuery &q, bool same_body, const std::array<int32_t, 4> &v,
            bool vertex_triangle) {
  const auto &moving = *q.moving;
  if (!(moving[v[0]] || moving[v[1]] || moving[v[2]] || moving[v[3]])) return false;
  if (q.changed &&
      !((*q.changed)[v[0]] || (*q.changed)[v[1]] || (*q.changed)[v[2]] || (*q.changed)[v[3]]))
    return false;
  const auto &body = q.surface->body;
  if ((body[v[0]] == body[v[2]]) != same_body) return false;
  if (!same_body) return true;
  return vertex_triangle ? (v[0] != v[1] && v[0] != v[2] && v[0] != v[3]) : !Shares(v);
}

// Whether this rank tests the pair: its lowest moving vertex is owned.
bool Owned(const CollisionQuery &q, const std::array<int32_t, 4> &v) {
  if (!q.owned) return true;
  int32_t lowest = -1;
  for (const int32_t k : v)
    if ((*q.moving)[k] && (lowest < 0 || k < lowest)) lowest = k;
  return lowest >= 0 && (*q.owned)[lowest];
}

void Test(const CollisionQuery &q, bool same_body, const std::array<int32_t, 4> &v,
          bool vertex_triangle, std::vector<SurfaceCollision> *out, CollisionCount *count) {
  if (!Wanted(q, same_body, v, vertex_triangle) || !Owned(q, v)) return;
  ++count->candidates;
  MovingPair pair;
  for (int k = 0; k < 4; ++k) {
    pair.start[k] = (*q.start)[v[k]];
    pair.end[k] = (*q.end)[v[k]];
  }
  const Approach approach =
      vertex_triangle ? PointTriangleCcd(pair, q.tolerance) : EdgeEdgeCcd(pair, q.tolerance);
  if (approach == Approach::kCollides) out->push_back({v, 4});
  if (approach == Approach::kCloseAtStart) ++count->close;
}

// Runs visit(i, j) once for each of a's boxes i and b's boxes j (binned in
// grid) that meet; `upper_only` when a and b are one list: i < j.
template <typename Visit>
void ForEachCandidate(const std::vector<Box> &a, const UniformGrid &grid, const std::vector<Box> &b,
                      bool upper_only, Visit visit) {
  std::vector<int32_t> seen(b.size(), -1);
  for (size_t i = 0; i < a.size(); ++i)
    grid.ForEachInBox(a[i], [&](int32_t j) {
      if (seen[j] == static_cast<int32_t>(i) || (upper_only && j <= static_cast<int32_t>(i)))
        return;
      seen[j] = static_cast<int32_t>(i);
      if (a[i].Overlaps(b[j])) visit(static_cast<int32_t>(i), j);
    });
}

UniformGrid GridOf(const std::vector<Box> &boxes) {
  UniformGrid grid;
  grid.Build(boxes);
  return grid;
}

// Primitives a (ids, boxes) against primitives b (ids, boxes, grid): vertices
// against triangles, triangles against vertices (a_is_triangle), or edges
// against edges.
struct Side {
  const std::vector<int32_t> &ids;
  const std::vector<Box> &boxes;
};
enum class Kind { kVertexTriangle, kTriangleVertex, kEdgeEdge };

void Pairs(const CollisionQuery &q, Kind kind, const Side &a, const Side &b,
           const UniformGrid &grid, bool same_body, bool upper_only,
           std::vector<SurfaceCollision> *out, CollisionCount *count) {
  const ContactSurface &s = *q.surface;
  ForEachCandidate(a.boxes, grid, b.boxes, upper_only, [&](int32_t i, int32_t j) {
    const int32_t x = a.ids[i], y = b.ids[j];
    if (kind == Kind::kVertexTriangle) {
      const auto &t = s.triangles[y];
      Test(q, same_body, {x, t[0], t[1], t[2]}, true, out, count);
    } else if (kind == Kind::kTriangleVertex) {
      const auto &t = s.triangles[x];
      Test(q, same_body, {y, t[0], t[1], t[2]}, true, out, count);
    } else {
      Test(q, same_body, {s.edges[x][0], s.edges[x][1], s.edges[y][0], s.edges[y][1]}, false, out,
           count);
    }
  });
}

// One list of primitives against itself: vertex-triangle and edge-edge pairs.
void Within(const CollisionQuery &q, const std::vector<int32_t> &vertices,
            const std::vector<int32_t> &triangles, const std::vector<int32_t> &edges,
            const Point &shift, bool same_body, std::vector<SurfaceCollision> *out,
            CollisionCount *count) {
  const Boxes boxes = BoxesOf(q, vertices, triangles, edges, shift);
  Pairs(q, Kind::kVertexTriangle, {vertices, boxes.vertices}, {triangles, boxes.triangles},
        GridOf(boxes.triangles), same_body, false, out, count);
  Pairs(q, Kind::kEdgeEdge, {edges, boxes.edges}, {edges, boxes.edges}, GridOf(boxes.edges),
        same_body, true, out, count);
}

void GroundCollisions(const CollisionQuery &q, std::vector<SurfaceCollision> *out,
                      CollisionCount *count) {
  // As ccd.hpp: the height is linear in t, so the end is the step's lowest point.
  const double separation = q.ground_y + q.tolerance.separation;
  for (int32_t v = 0; v < q.surface->num_vertices(); ++v) {
    if (!(*q.moving)[v] || (q.changed && !(*q.changed)[v]) || (q.owned && !(*q.owned)[v])) continue;
    const double start = (*q.start)[v][1], end = (*q.end)[v][1];
    if (start <= separation) {
      if (end < start) ++count->close;
      continue;
    }
    if (end <= separation + std::min(q.tolerance.band, (start - separation) / 2))
      out->push_back({{v, v, v, v}, 1});
  }
}

template <size_t N>
bool AnyMoving(const CollisionQuery &q, const std::array<int32_t, N> &vertices) {
  return std::any_of(vertices.begin(), vertices.end(), [&](int32_t v) { return (*q.moving)[v]; });
}

// The listed primitives whose vertices are all usable (all without q.usable).
template <size_t N>
std::vector<int32_t> Usable(const CollisionQuery &q, const std::vector<int32_t> &ids,
                            const std::vector<std::array<int32_t, N>> &vertices) {
  if (!q.usable) return ids;
  std::vector<int32_t> kept;
  for (const int32_t i : ids)
    if (std::all_of(vertices[i].begin(), vertices[i].end(),
                    [&](int32_t v) { return (*q.usable)[v]; }))
      kept.push_back(i);
  return kept;
}

std::vector<int32_t> Range(int32_t begin, int32_t end) {
  std::vector<int32_t> range(end - begin);
  for (int32_t i = begin; i < end; ++i) range[i - begin] = i;
  return range;
}

std::vector<std::array<int32_t, 1>> Singles(int32_t count) {
  std::vector<std::array<int32_t, 1>> singles(count);
  for (int32_t v = 0; v < count; ++v) singles[v] = {v};
  return singles;
}

}  // namespace

void SurfaceCollisionFinder::Setup(const CollisionQuery &q) {
  const ContactSurface &s = *q.surface;
  for (int32_t v = 0; v < s.num_vertices(); ++v)
    ((*q.moving)[v] ? moving_vertices_ : static_.vertices).push_back(v);
  for (int32_t t = 0; t < static_cast<int32_t>(s.triangles.size()); ++t)
    (AnyMoving(q, s.triangles[t]) ? moving_triangles_ : static_.triangles).push_back(t);
  for (int32_t e = 0; e < static_cast<int32_t>(s.edges.size()); ++e)
    (AnyMoving(q, s.edges[e]) ? moving_edges_ : static_.edges).push_back(e);
  for (size_t b = 0; b < s.num_bodies(); ++b)
    if (s.vertex_start[b] < s.vertex_start[b + 1] && (*q.moving)[s.vertex_start[b]])
      moving_bodies_.push_back(b);
  const Boxes boxes = BoxesOf(q, static_.vertices, static_.triangles, static_.edges, Point::Zero());
  static_.vertex_boxes = boxes.vertices;
  static_.triangle_boxes = boxes.triangles;
  static_.edge_boxes = boxes.edges;
  static_.vertex_grid.Build(static_.vertex_boxes);
  static_.triangle_grid.Build(static_.triangle_boxes);
  static_.edge_grid.Build(static_.edge_boxes);
}

std::vector<SurfaceCollision> SurfaceCollisionFinder::Find(const CollisionQuery &q,
                                                           CollisionCount *count) const {
  std::vector<SurfaceCollision> out;
  const ContactSurface &s = *q.surface;
  if (q.ground) GroundCollisions(q, &out, count);
  const std::vector<std::array<int32_t, 1>> singles =
      q.usable ? Singles(s.num_vertices()) : std::vector<std::array<int32_t, 1>>();
  auto vertices_of = [&](const std::vector<int32_t> &ids) {
    return q.usable ? Usable(q, ids, singles) : ids;
  };
  const std::vector<int32_t> vertices = vertices_of(moving_vertices_),
                             triangles = Usable(q, moving_triangles_, s.triangles),
                             edges = Usable(q, moving_edges_, s.edges);
  // The moving primitives against the static ones, in the world frame.
  const Boxes moving = BoxesOf(q, vertices, triangles, edges, Point::Zero());
  Pairs(q, Kind::kVertexTriangle, {vertices, moving.vertices},
        {static_.triangles, static_.triangle_boxes}, static_.triangle_grid, false, false, &out,
        count);
  Pairs(q, Kind::kTriangleVertex, {triangles, moving.triangles},
        {static_.vertices, static_.vertex_boxes}, static_.vertex_grid, false, false, &out, count);
  Pairs(q, Kind::kEdgeEdge, {edges, moving.edges}, {static_.edges, static_.edge_boxes},
        static_.edge_grid, false, false, &out, count);
  // Moving bodies against each other, in the world frame.
  if (moving_bodies_.size() > 1)
    Within(q, vertices, triangles, edges, Point::Zero(), false, &out, count);
  // Each moving body against itself, in the frame of its (usable vertices') mean displacement.
  if (q.self_contact)
    for (const size_t b : moving_bodies_) {
      const std::vector<int32_t> body_vertices =
          vertices_of(Range(s.vertex_start[b], s.vertex_start[b + 1]));
      if (body_vertices.empty()) continue;
      Point shift = Point::Zero();
      for (const int32_t v : body_vertices) shift += (*q.end)[v] - (*q.start)[v];
      shift /= static_cast<double>(body_vertices.size());
      Within(q, body_vertices,
             Usable(q, Range(s.triangle_start[b], s.triangle_start[b + 1]), s.triangles),
             Usable(q, Range(s.edge_start[b], s.edge_start[b + 1]), s.edges), shift, true, &out,
             count);
    }
  return out;
}

}  // namespace softbody
