#include "contact/surface_collisions.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace softbody {

namespace {

// The self-contact candidates' skin, in mean surface edges of the body: a
// vertex may move half of it (relative to the body's mean motion) before the
// list is rebuilt. Measured on the default scene at dt = 0.005 s and 0.02 s
// (docs/contact.md): larger skins list more pairs, smaller ones rebuild more;
// a quarter and a whole edge were slower.
constexpr double kSkinOfEdge = 0.5;
// A cached pair skips CCD when its distance bound exceeds this many times
// separation + band (CCD reports only pairs that come within that; the factor
// keeps the bound clear of the round-off of either computation).
constexpr double kApartMargin = 2.0;

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
using Boxes = PrimitiveBoxes;
Boxes BoxesOf(const CollisionQuery &q, const std::vector<int32_t> &vertices,
              const std::vector<int32_t> &triangles, const std::vector<int32_t> &edges,
              const Point &shift) {
  Boxes boxes;
  boxes.vertices.reserve(vertices.size());
  boxes.triangles.reserve(triangles.size());
  boxes.edges.reserve(edges.size());
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
                      bool upper_only, VisitMarks *marks, Visit visit) {
  for (size_t i = 0; i < a.size(); ++i) {
    marks->Begin(b.size());
    grid.ForEachInBox(a[i], [&](int32_t j) {
      if ((upper_only && j <= static_cast<int32_t>(i)) || !marks->First(j)) return;
      if (a[i].Overlaps(b[j])) visit(static_cast<int32_t>(i), j);
    });
  }
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
           const UniformGrid &grid, bool same_body, bool upper_only, VisitMarks *marks,
           std::vector<SurfaceCollision> *out, CollisionCount *count) {
  const ContactSurface &s = *q.surface;
  ForEachCandidate(a.boxes, grid, b.boxes, upper_only, marks, [&](int32_t i, int32_t j) {
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

// The listed primitives (their boxes `boxes`, their vertices `vertices`) whose
// box meets the box of another body, given per body (`body_boxes`). A pair of
// primitives of two bodies whose boxes meet keeps both, so the pass over the
// kept ones finds every such pair; pairs within one body it would only reject.
template <size_t N>
Side Near(const ContactSurface &s, const std::vector<Box> &body_boxes,
          const std::vector<int32_t> &ids, const std::vector<Box> &boxes,
          const std::vector<std::array<int32_t, N>> &vertices, std::vector<int32_t> *kept_ids,
          std::vector<Box> *kept_boxes) {
  for (size_t i = 0; i < ids.size(); ++i) {
    const int32_t own = s.body[vertices[ids[i]][0]];
    for (size_t b = 0; b < body_boxes.size(); ++b)
      if (static_cast<int32_t>(b) != own && body_boxes[b].Overlaps(boxes[i])) {
        kept_ids->push_back(ids[i]);
        kept_boxes->push_back(boxes[i]);
        break;
      }
  }
  return {*kept_ids, *kept_boxes};
}

// Moving bodies against each other, in the world frame: only the primitives
// near another body are binned.
void BetweenBodies(const CollisionQuery &q, const std::vector<int32_t> &vertices,
                   const std::vector<int32_t> &triangles, const std::vector<int32_t> &edges,
                   Boxes *boxes, const std::vector<std::array<int32_t, 1>> &singles,
                   VisitMarks *marks, std::vector<SurfaceCollision> *out, CollisionCount *count) {
  const ContactSurface &s = *q.surface;
  std::vector<Box> body_boxes(s.num_bodies());
  for (size_t i = 0; i < vertices.size(); ++i)
    body_boxes[s.body[vertices[i]]].Extend(boxes->vertices[i]);
  bool meet = false;
  for (size_t a = 0; a < body_boxes.size() && !meet; ++a)
    for (size_t b = a + 1; b < body_boxes.size() && !meet; ++b)
      meet = body_boxes[a].Overlaps(body_boxes[b]);
  if (!meet) return;
  if (boxes->triangles.size() != triangles.size() || boxes->edges.size() != edges.size())
    *boxes = BoxesOf(q, vertices, triangles, edges, Point::Zero());
  const Boxes &moving = *boxes;
  std::vector<int32_t> v_ids, t_ids, e_ids;
  Boxes near;
  const Side v = Near(s, body_boxes, vertices, moving.vertices, singles, &v_ids, &near.vertices);
  const Side t =
      Near(s, body_boxes, triangles, moving.triangles, s.triangles, &t_ids, &near.triangles);
  const Side e = Near(s, body_boxes, edges, moving.edges, s.edges, &e_ids, &near.edges);
  if (v.ids.empty() && e.ids.empty()) return;
  Pairs(q, Kind::kVertexTriangle, v, t, GridOf(near.triangles), false, false, marks, out, count);
  Pairs(q, Kind::kEdgeEdge, e, e, GridOf(near.edges), false, true, marks, out, count);
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

void SurfaceCollisionFinder::ListPrimitives(const CollisionQuery &q) {
  const ContactSurface &s = *q.surface;
  for (auto *list : {&moving_vertices_, &moving_triangles_, &moving_edges_, &static_.vertices,
                     &static_.triangles, &static_.edges})
    list->clear();
  moving_bodies_.clear();
  for (int32_t v = 0; v < s.num_vertices(); ++v)
    ((*q.moving)[v] ? moving_vertices_ : static_.vertices).push_back(v);
  for (int32_t t = 0; t < static_cast<int32_t>(s.triangles.size()); ++t)
    (AnyMoving(q, s.triangles[t]) ? moving_triangles_ : static_.triangles).push_back(t);
  for (int32_t e = 0; e < static_cast<int32_t>(s.edges.size()); ++e)
    (AnyMoving(q, s.edges[e]) ? moving_edges_ : static_.edges).push_back(e);
  for (size_t b = 0; b < s.num_bodies(); ++b)
    if (s.vertex_start[b] < s.vertex_start[b + 1] && (*q.moving)[s.vertex_start[b]])
      moving_bodies_.push_back(b);
}

void SurfaceCollisionFinder::Renumber(const CollisionQuery &q) {
  const size_t counts[] = {static_.vertices.size(), static_.triangles.size(), static_.edges.size()};
  ListPrimitives(q);
  assert(counts[0] == static_.vertices.size() && counts[1] == static_.triangles.size() &&
         counts[2] == static_.edges.size());
  (void)counts;
  self_.assign(q.surface->num_bodies(), SelfCandidates());
  static_candidates_ = StaticCandidates();
  vertex_box_.assign(q.surface->num_vertices(), Box());
}

std::vector<double> SurfaceCollisionFinder::HalfSkins(const ContactSurface &s,
                                                      const std::vector<Point> &x) {
  std::vector<double> half_skin(s.num_bodies(), 0.0);
  for (size_t b = 0; b < s.num_bodies(); ++b) {
    double length = 0;
    for (int32_t e = s.edge_start[b]; e < s.edge_start[b + 1]; ++e)
      length += (x[s.edges[e][0]] - x[s.edges[e][1]]).norm();
    const int32_t edges = s.edge_start[b + 1] - s.edge_start[b];
    half_skin[b] = edges > 0 ? 0.5 * kSkinOfEdge * length / edges : 0.0;
  }
  return half_skin;
}

void SurfaceCollisionFinder::Setup(const CollisionQuery &q, const std::vector<double> *half_skin) {
  const ContactSurface &s = *q.surface;
  ListPrimitives(q);
  Boxes boxes = BoxesOf(q, static_.vertices, static_.triangles, static_.edges, Point::Zero());
  static_.vertex_boxes = std::move(boxes.vertices);
  static_.triangle_boxes = std::move(boxes.triangles);
  static_.edge_boxes = std::move(boxes.edges);
  static_.vertex_grid.Build(static_.vertex_boxes);
  static_.triangle_grid.Build(static_.triangle_boxes);
  static_.edge_grid.Build(static_.edge_boxes);
  half_skin_ = half_skin ? *half_skin : HalfSkins(s, *q.start);
  self_.assign(s.num_bodies(), SelfCandidates());
  vertex_box_.assign(s.num_vertices(), Box());
}

std::vector<SurfaceCollision> SurfaceCollisionFinder::Find(const CollisionQuery &q,
                                                           CollisionCount *count) const {
  std::vector<SurfaceCollision> out;
  const ContactSurface &s = *q.surface;
  if (q.ground) GroundCollisions(q, &out, count);
  const std::vector<std::array<int32_t, 1>> singles = Singles(s.num_vertices());
  auto vertices_of = [&](const std::vector<int32_t> &ids) {
    return q.usable ? Usable(q, ids, singles) : ids;
  };
  const std::vector<int32_t> vertices = vertices_of(moving_vertices_),
                             triangles = Usable(q, moving_triangles_, s.triangles),
                             edges = Usable(q, moving_edges_, s.edges);
  const bool against_static = !static_.vertices.empty(), between = moving_bodies_.size() > 1;
  // The moving primitives' boxes; between bodies alone, only the vertices'
  // first (BetweenBodies adds the others when two bodies' boxes meet).
  const std::vector<int32_t> none;
  Boxes moving = against_static ? BoxesOf(q, vertices, triangles, edges, Point::Zero())
                 : between      ? BoxesOf(q, vertices, none, none, Point::Zero())
                                : Boxes();
  if (against_static) StaticPass(q, vertices, triangles, edges, moving, &out, count);
  if (between) BetweenBodies(q, vertices, triangles, edges, &moving, singles, &marks_, &out, count);
  // Each moving body against itself, in the frame of its (usable vertices') mean displacement.
  if (q.self_contact)
    for (const size_t b : moving_bodies_) {
      const std::vector<int32_t> body_vertices =
          vertices_of(Range(s.vertex_start[b], s.vertex_start[b + 1]));
      if (!body_vertices.empty()) SelfPass(q, b, body_vertices, &out, count);
    }
  return out;
}

// The moving primitives against the static ones, in the world frame: the
// listed candidates whose boxes meet, as the static grids would give them.
void SurfaceCollisionFinder::StaticPass(const CollisionQuery &q,
                                        const std::vector<int32_t> &vertices,
                                        const std::vector<int32_t> &triangles,
                                        const std::vector<int32_t> &edges, const Boxes &moving,
                                        std::vector<SurfaceCollision> *out,
                                        CollisionCount *count) const {
  if (!StaticCandidatesHold(q, vertices, triangles, edges)) {
    BuildStaticCandidates(q, vertices, triangles, edges);
    ++count->static_rebuilds;
  }
  const ContactSurface &s = *q.surface;
  const StaticCandidates &c = static_candidates_;
  for (const auto &[i, t] : c.vertex_triangle)
    if (moving.vertices[i].Overlaps(static_.triangle_boxes[t])) {
      const auto &w = s.triangles[static_.triangles[t]];
      Test(q, false, {vertices[i], w[0], w[1], w[2]}, true, out, count);
    }
  for (const auto &[i, v] : c.triangle_vertex)
    if (moving.triangles[i].Overlaps(static_.vertex_boxes[v])) {
      const auto &w = s.triangles[triangles[i]];
      Test(q, false, {static_.vertices[v], w[0], w[1], w[2]}, true, out, count);
    }
  for (const auto &[i, f] : c.edge_edge)
    if (moving.edges[i].Overlaps(static_.edge_boxes[f])) {
      const auto &x = s.edges[edges[i]], &y = s.edges[static_.edges[f]];
      Test(q, false, {x[0], x[1], y[0], y[1]}, false, out, count);
    }
}

// Whether the static candidates were built from these moving primitives and
// none of their vertices has left its box at the build by more than half its
// body's skin.
bool SurfaceCollisionFinder::StaticCandidatesHold(const CollisionQuery &q,
                                                  const std::vector<int32_t> &vertices,
                                                  const std::vector<int32_t> &triangles,
                                                  const std::vector<int32_t> &edges) const {
  const StaticCandidates &c = static_candidates_;
  if (!c.valid || c.vertices != vertices || c.triangles != triangles || c.edges != edges)
    return false;
  for (size_t i = 0; i < vertices.size(); ++i) {
    const int32_t v = vertices[i];
    const Point &start = (*q.start)[v], &end = (*q.end)[v];
    // Round-off of the comparison (a few ulps of the coordinates).
    const double reach =
        half_skin_[q.surface->body[v]] -
        1e-12 * (1 + std::max(start.cwiseAbs().maxCoeff(), end.cwiseAbs().maxCoeff()));
    if (!c.vertex_boxes[i].Contains(start, reach) || !c.vertex_boxes[i].Contains(end, reach))
      return false;
  }
  return true;
}

// The static candidates from this step's positions: the pairs whose boxes meet
// when each moving vertex's box is grown by half its body's skin.
void SurfaceCollisionFinder::BuildStaticCandidates(const CollisionQuery &q,
                                                   const std::vector<int32_t> &vertices,
                                                   const std::vector<int32_t> &triangles,
                                                   const std::vector<int32_t> &edges) const {
  const ContactSurface &s = *q.surface;
  StaticCandidates &c = static_candidates_;
  c.valid = true;
  c.vertices = vertices;
  c.triangles = triangles;
  c.edges = edges;
  c.vertex_boxes.assign(vertices.size(), Box());
  const double grow = q.tolerance.separation + q.tolerance.band;
  // Per surface vertex: its box, grown (the self pass's boxes as scratch: it comes later).
  std::vector<Box> &grown = vertex_box_;
  for (size_t i = 0; i < vertices.size(); ++i) {
    const int32_t v = vertices[i];
    c.vertex_boxes[i].Extend((*q.start)[v]);
    c.vertex_boxes[i].Extend((*q.end)[v]);
    grown[v] = c.vertex_boxes[i];
    const double by = grow + half_skin_[s.body[v]];
    grown[v].lower.array() -= by;
    grown[v].upper.array() += by;
  }
  // A static vertex of a moving primitive: its own box, grown as SweptBox's.
  auto box_of = [&](int32_t v) {
    if ((*q.moving)[v]) return grown[v];
    Box box;
    box.Extend((*q.start)[v]);
    box.Extend((*q.end)[v]);
    box.lower.array() -= grow;
    box.upper.array() += grow;
    return box;
  };
  Boxes boxes;
  for (const int32_t v : vertices) boxes.vertices.push_back(grown[v]);
  for (const int32_t t : triangles) {
    Box box;
    for (const int32_t v : s.triangles[t]) box.Extend(box_of(v));
    boxes.triangles.push_back(box);
  }
  for (const int32_t e : edges) {
    Box box;
    for (const int32_t v : s.edges[e]) box.Extend(box_of(v));
    boxes.edges.push_back(box);
  }
  auto list = [&](const std::vector<Box> &a, const UniformGrid &grid, const std::vector<Box> &b,
                  std::vector<std::array<int32_t, 2>> *pairs) {
    pairs->clear();
    ForEachCandidate(a, grid, b, false, &marks_, [&](int32_t i, int32_t j) {
      pairs->push_back({i, j});
    });
  };
  list(boxes.vertices, static_.triangle_grid, static_.triangle_boxes, &c.vertex_triangle);
  list(boxes.triangles, static_.vertex_grid, static_.vertex_boxes, &c.triangle_vertex);
  list(boxes.edges, static_.edge_grid, static_.edge_boxes, &c.edge_edge);
}

// One body against itself, in the frame of its mean displacement `shift`: the
// candidates' pairs whose boxes meet, as a grid over this step's boxes would
// find them.
void SurfaceCollisionFinder::SelfPass(const CollisionQuery &q, size_t b,
                                      const std::vector<int32_t> &vertices,
                                      std::vector<SurfaceCollision> *out,
                                      CollisionCount *count) const {
  Point shift = Point::Zero(), mean = Point::Zero();
  for (const int32_t v : vertices) {
    shift += (*q.end)[v] - (*q.start)[v];
    mean += (*q.start)[v];
  }
  shift /= static_cast<double>(vertices.size());
  mean /= static_cast<double>(vertices.size());
  if (!SelfCandidatesHold(q, self_[b], vertices, shift, mean, half_skin_[b])) {
    BuildSelfCandidates(q, b, vertices, shift, mean);
    ++count->rebuilds;
  }
  SelfStepBoxes(q, b, vertices, shift);
  const ContactSurface &s = *q.surface;
  const int32_t first_triangle = s.triangle_start[b], first_edge = s.edge_start[b];
  const SelfCandidates &c = self_[b];
  const int32_t first_vertex = s.vertex_start[b];
  for (size_t k = 0; k < c.vertex_triangle.size(); ++k) {
    const auto &[v, t] = c.vertex_triangle[k];
    const auto &w = s.triangles[t];
    const std::array<int32_t, 4> pair = {v, w[0], w[1], w[2]};
    if (vertex_box_[v].Overlaps(triangle_box_[t - first_triangle]) &&
        !StaysApart(q, c, first_vertex, pair, 1, c.vertex_triangle_distance[k]))
      Test(q, true, pair, true, out, count);
  }
  for (size_t k = 0; k < c.edge_edge.size(); ++k) {
    const auto &[e, f] = c.edge_edge[k];
    const auto &x = s.edges[e], &y = s.edges[f];
    const std::array<int32_t, 4> pair = {x[0], x[1], y[0], y[1]};
    if (edge_box_[e - first_edge].Overlaps(edge_box_[f - first_edge]) &&
        !StaysApart(q, c, first_vertex, pair, 2, c.edge_edge_distance[k]))
      Test(q, true, pair, false, out, count);
  }
}

// Whether the pair (vertices v[0 .. on_a) against v[on_a .. 4)) stays farther
// than kApartMargin (separation + band) apart over the step, so that CCD
// would find it apart. For points a = sum alpha_i x_i and b = sum beta_j x_j
// of the two primitives, a - b = sum alpha_i beta_j (x_i - x_j): the
// distance is at least its value at the build less the largest change of an
// x_i - x_j since then, and that change is affine in the step's time, so its
// largest norm is at the start or the end.
bool SurfaceCollisionFinder::StaysApart(const CollisionQuery &q, const SelfCandidates &c,
                                        int32_t first_vertex, const std::array<int32_t, 4> &v,
                                        int on_a, double distance) const {
  const double keep = kApartMargin * (q.tolerance.separation + q.tolerance.band);
  if (distance <= keep) return false;
  double change = 0;
  for (int i = 0; i < on_a; ++i)
    for (int j = on_a; j < 4; ++j) {
      const Point built = c.built[v[i] - first_vertex] - c.built[v[j] - first_vertex];
      for (const auto *x : {q.start, q.end})
        change = std::max(change, ((*x)[v[i]] - (*x)[v[j]] - built).squaredNorm());
    }
  return distance - std::sqrt(change) > keep;
}

// This step's boxes of body b, grown as SweptBox's: per vertex (of
// `vertices`), and per triangle and edge of the body (those with a vertex not
// in `vertices` are in no candidate pair).
void SurfaceCollisionFinder::SelfStepBoxes(const CollisionQuery &q, size_t b,
                                           const std::vector<int32_t> &vertices,
                                           const Point &shift) const {
  const ContactSurface &s = *q.surface;
  for (const int32_t v : vertices) {
    vertex_box_[v] = Box();
    vertex_box_[v].Extend((*q.start)[v]);
    vertex_box_[v].Extend((*q.end)[v] - shift);
  }
  const double grow = q.tolerance.separation + q.tolerance.band;
  auto grown = [grow](Box box) {
    box.lower.array() -= grow;
    box.upper.array() += grow;
    return box;
  };
  const int32_t first_triangle = s.triangle_start[b], first_edge = s.edge_start[b];
  triangle_box_.resize(s.triangle_start[b + 1] - first_triangle);
  for (size_t i = 0; i < triangle_box_.size(); ++i) {
    Box box;
    for (const int32_t v : s.triangles[first_triangle + i]) box.Extend(vertex_box_[v]);
    triangle_box_[i] = grown(box);
  }
  edge_box_.resize(s.edge_start[b + 1] - first_edge);
  for (size_t i = 0; i < edge_box_.size(); ++i) {
    Box box;
    for (const int32_t v : s.edges[first_edge + i]) box.Extend(vertex_box_[v]);
    edge_box_[i] = grown(box);
  }
  for (const int32_t v : vertices) vertex_box_[v] = grown(vertex_box_[v]);
}

// Whether body b's candidates were built from these usable vertices and none
// of them has left its box at the build by more than half the skin.
bool SurfaceCollisionFinder::SelfCandidatesHold(const CollisionQuery &q, const SelfCandidates &c,
                                                const std::vector<int32_t> &vertices,
                                                const Point &shift, const Point &mean,
                                                double half_skin) const {
  if (!c.valid || c.vertices != vertices) return false;
  // Round-off of the relative positions (a few ulps of the coordinates).
  const double reach = half_skin - 1e-12 * (1 + mean.cwiseAbs().maxCoeff());
  for (size_t i = 0; i < vertices.size(); ++i) {
    const int32_t v = vertices[i];
    const Box &box = c.vertex_boxes[i];
    for (const Point &p : {Point((*q.start)[v] - mean), Point((*q.end)[v] - shift - mean)})
      if (!box.Contains(p, reach)) return false;
  }
  return true;
}

// Body b's candidates from this step's positions: the pairs whose boxes,
// grown by half the skin each, meet and share no vertex.
void SurfaceCollisionFinder::BuildSelfCandidates(const CollisionQuery &q, size_t b,
                                                 const std::vector<int32_t> &vertices,
                                                 const Point &shift, const Point &mean) const {
  const ContactSurface &s = *q.surface;
  SelfCandidates &c = self_[b];
  c.valid = true;
  c.vertices = vertices;
  c.vertex_boxes.assign(vertices.size(), Box());
  for (size_t i = 0; i < vertices.size(); ++i) {
    c.vertex_boxes[i].Extend((*q.start)[vertices[i]] - mean);
    c.vertex_boxes[i].Extend((*q.end)[vertices[i]] - shift - mean);
  }
  CollisionQuery grown = q;
  grown.tolerance.band += half_skin_[b];
  const std::vector<int32_t> triangles =
      Usable(q, Range(s.triangle_start[b], s.triangle_start[b + 1]), s.triangles);
  const std::vector<int32_t> edges =
      Usable(q, Range(s.edge_start[b], s.edge_start[b + 1]), s.edges);
  const Boxes boxes = BoxesOf(grown, vertices, triangles, edges, shift);
  c.vertex_triangle.clear();
  c.edge_edge.clear();
  ForEachCandidate(boxes.vertices, GridOf(boxes.triangles), boxes.triangles, false, &marks_,
                   [&](int32_t i, int32_t j) {
                     const int32_t v = vertices[i], t = triangles[j];
                     const auto &w = s.triangles[t];
                     if (v != w[0] && v != w[1] && v != w[2]) c.vertex_triangle.push_back({v, t});
                   });
  ForEachCandidate(boxes.edges, GridOf(boxes.edges), boxes.edges, true, &marks_,
                   [&](int32_t i, int32_t j) {
                     const int32_t e = edges[i], f = edges[j];
                     if (!Shares({s.edges[e][0], s.edges[e][1], s.edges[f][0], s.edges[f][1]}))
                       c.edge_edge.push_back({e, f});
                   });
  MeasureSelfCandidates(q, b);
}

// The distances of body b's candidate pairs at the build's start positions.
void SurfaceCollisionFinder::MeasureSelfCandidates(const CollisionQuery &q, size_t b) const {
  const ContactSurface &s = *q.surface;
  SelfCandidates &c = self_[b];
  const std::vector<Point> &x = *q.start;
  c.built.assign(x.begin() + s.vertex_start[b], x.begin() + s.vertex_start[b + 1]);
  c.vertex_triangle_distance.resize(c.vertex_triangle.size());
  for (size_t k = 0; k < c.vertex_triangle.size(); ++k) {
    const auto &[v, t] = c.vertex_triangle[k];
    const auto &w = s.triangles[t];
    c.vertex_triangle_distance[k] =
        std::sqrt(PointTriangleDistanceSquared(x[v], x[w[0]], x[w[1]], x[w[2]]));
  }
  c.edge_edge_distance.resize(c.edge_edge.size());
  for (size_t k = 0; k < c.edge_edge.size(); ++k) {
    const auto &e = s.edges[c.edge_edge[k][0]], &f = s.edges[c.edge_edge[k][1]];
    c.edge_edge_distance[k] =
        std::sqrt(EdgeEdgeDistanceSquared(x[e[0]], x[e[1]], x[f[0]], x[f[1]]));
  }
}

}  // namespace softbody
