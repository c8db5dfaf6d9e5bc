#include "contact/surface_collisions.hpp"

#include <algorithm>

namespace softbody {

namespace {

// A primitive's box over the step (start and end of its vertices), grown by
// the distance CCD reports within.
template <size_t N>
Box SweptBox(const CollisionQuery &q, const std::array<int32_t, N> &vertices) {
  Box box;
  for (const int32_t v : vertices) {
    box.Extend((*q.start)[v]);
    box.Extend((*q.end)[v]);
  }
  const double grow = q.tolerance.separation + q.tolerance.band;
  box.lower.array() -= grow;
  box.upper.array() += grow;
  return box;
}

bool Shares(const std::array<int32_t, 4> &v) {
  return v[0] == v[2] || v[0] == v[3] || v[1] == v[2] || v[1] == v[3];
}

// Whether the pair is guarded at all: something moves, the bodies differ (or
// self-contact), and (self-contact) no vertex is shared.
bool Wanted(const CollisionQuery &q, const std::array<int32_t, 4> &v, bool vertex_triangle) {
  const auto &moving = *q.moving;
  if (!(moving[v[0]] || moving[v[1]] || moving[v[2]] || moving[v[3]])) return false;
  if (q.changed && !((*q.changed)[v[0]] || (*q.changed)[v[1]] || (*q.changed)[v[2]] ||
                     (*q.changed)[v[3]]))
    return false;
  const auto &body = q.surface->body;
  if (body[v[0]] != body[v[2]]) return true;
  if (!q.self_contact) return false;
  return vertex_triangle ? (v[0] != v[1] && v[0] != v[2] && v[0] != v[3]) : !Shares(v);
}

MovingPair PairOf(const CollisionQuery &q, const std::array<int32_t, 4> &v) {
  MovingPair pair;
  for (int k = 0; k < 4; ++k) {
    pair.start[k] = (*q.start)[v[k]];
    pair.end[k] = (*q.end)[v[k]];
  }
  return pair;
}

// Runs visit(a, b) once for each pair of a's primitives and b's whose swept
// boxes' cubes meet (b's binned in a grid; `upper_only` with a == b: a < b).
template <typename Visit>
void ForEachCandidate(const std::vector<Box> &a, const std::vector<Box> &b, bool upper_only,
                      Visit visit) {
  UniformGrid grid;
  grid.Build(b);
  std::vector<int32_t> seen(b.size(), -1);
  for (size_t i = 0; i < a.size(); ++i) {
    const Point centre = (a[i].lower + a[i].upper) / 2;
    const double radius = (a[i].upper - a[i].lower).maxCoeff() / 2;
    grid.ForEachNear(centre, radius, [&](int32_t j) {
      if (seen[j] == static_cast<int32_t>(i) || (upper_only && j <= static_cast<int32_t>(i)))
        return;
      seen[j] = static_cast<int32_t>(i);
      if (a[i].Overlaps(b[j])) visit(static_cast<int32_t>(i), j);
    });
  }
}

void GroundCollisions(const CollisionQuery &q, std::vector<SurfaceCollision> *out,
                      CollisionCount *count) {
  const double near = q.ground_y + q.tolerance.separation + q.tolerance.band;
  for (int32_t v = 0; v < q.surface->num_vertices(); ++v) {
    if (!(*q.moving)[v] || (q.changed && !(*q.changed)[v]) || (*q.end)[v][1] > near) continue;
    // The height is linear in t: the end is the lowest point of the step.
    if ((*q.start)[v][1] <= near)
      ++count->close;
    else
      out->push_back({{v, v, v, v}, 1});
  }
}

void Test(const CollisionQuery &q, const std::array<int32_t, 4> &v, bool vertex_triangle,
          std::vector<SurfaceCollision> *out, CollisionCount *count) {
  if (!Wanted(q, v, vertex_triangle)) return;
  ++count->candidates;
  const MovingPair pair = PairOf(q, v);
  const Approach approach =
      vertex_triangle ? PointTriangleCcd(pair, q.tolerance) : EdgeEdgeCcd(pair, q.tolerance);
  if (approach == Approach::kCollides) out->push_back({v, 4});
  if (approach == Approach::kCloseAtStart) ++count->close;
}

}  // namespace

std::vector<SurfaceCollision> FindSurfaceCollisions(const CollisionQuery &q,
                                                    CollisionCount *count) {
  std::vector<SurfaceCollision> out;
  const ContactSurface &s = *q.surface;
  if (q.ground) GroundCollisions(q, &out, count);
  std::vector<Box> vertex_boxes, triangle_boxes, edge_boxes;
  for (int32_t v = 0; v < s.num_vertices(); ++v)
    vertex_boxes.push_back(SweptBox<1>(q, std::array<int32_t, 1>{v}));
  for (const auto &t : s.triangles) triangle_boxes.push_back(SweptBox(q, t));
  for (const auto &e : s.edges) edge_boxes.push_back(SweptBox(q, e));
  ForEachCandidate(vertex_boxes, triangle_boxes, false, [&](int32_t v, int32_t t) {
    const auto &tri = s.triangles[t];
    Test(q, {v, tri[0], tri[1], tri[2]}, true, &out, count);
  });
  ForEachCandidate(edge_boxes, edge_boxes, true, [&](int32_t i, int32_t j) {
    Test(q, {s.edges[i][0], s.edges[i][1], s.edges[j][0], s.edges[j][1]}, false, &out, count);
  });
  return out;
}

}  // namespace softbody

