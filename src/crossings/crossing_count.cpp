#include "crossings/crossing_count.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/box_intersection_d.h>
#include <CGAL/intersections.h>

#include <algorithm>
#include <cmath>
#include <variant>

namespace softbody {

namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Segment = Kernel::Segment_3;
using Triangle = Kernel::Triangle_3;
// A surface triangle as CGAL can test it: degenerate ones become segments or points.
using Shape = std::variant<Triangle, Segment, Point>;
// A triangle's bounding box carrying the triangle's index.
using Box = CGAL::Box_intersection_d::Box_with_info_d<double, 3, uint32_t,
                                                      CGAL::Box_intersection_d::ID_EXPLICIT>;

Point PointAt(const std::vector<double> &positions, int32_t v) {
  return Point(positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]);
}

// Exact: a triangle, or for collinear corners the segment between the extreme
// corners (along a line, lexicographic order is order along the line), or a point.
Shape MakeShape(const std::array<int32_t, 3> &corners, const std::vector<double> &positions,
                int64_t *degenerate) {
  const Point a = PointAt(positions, corners[0]), b = PointAt(positions, corners[1]),
              c = PointAt(positions, corners[2]);
  if (!CGAL::collinear(a, b, c)) return Triangle(a, b, c);
  ++*degenerate;
  const Point points[3] = {a, b, c};
  const auto [low, high] = std::minmax_element(
      points, points + 3,
      [](const Point &p, const Point &q) { return CGAL::lexicographically_xyz_smaller(p, q); });
  if (*low == *high) return *low;
  return Segment(*low, *high);
}

bool Finite(const std::array<int32_t, 3> &corners, const std::vector<double> &positions) {
  for (const int32_t v : corners)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(positions[3 * v + c])) return false;
  return true;
}

// The closed bounding box of a triangle (exact: min and max of its corners).
Box BoxOf(const std::array<int32_t, 3> &corners, const std::vector<double> &positions,
          uint32_t triangle) {
  return Box(PointAt(positions, corners[0]).bbox() + PointAt(positions, corners[1]).bbox() +
                 PointAt(positions, corners[2]).bbox(),
             triangle);
}

bool BoxesMeet(const Box &box, const CGAL::Bbox_3 &region) {
  for (int d = 0; d < 3; ++d)
    if (box.max_coord(d) < region.min(d) || region.max(d) < box.min_coord(d)) return false;
  return true;
}

bool Meets(const Point &p, const Point &q) {
  return p == q;
}
template <typename A, typename B>
bool Meets(const A &a, const B &b) {
  return CGAL::do_intersect(a, b);
}

bool ShapesMeet(const Shape &a, const Shape &b) {
  return std::visit([](const auto &x, const auto &y) { return Meets(x, y); }, a, b);
}

bool ShareVertex(const std::array<int32_t, 3> &s, const std::array<int32_t, 3> &t) {
  for (const int32_t u : s)
    for (const int32_t v : t)
      if (u == v) return true;
  return false;
}

}  // namespace

struct CrossingCounter::Fixed {
  std::vector<Box> boxes;     // one per fixed triangle
  std::vector<Shape> shapes;  // by slot
  int64_t degenerate = 0;     // fixed triangles with collinear corners
};

CrossingCounter::CrossingCounter(const ResultSurface &surface,
                                 const std::vector<double> &fixed_positions)
    : surface_(surface), slot_(surface.triangles.size()), fixed_(std::make_unique<Fixed>()) {
  std::vector<char> on_free_surface(surface.num_vertices(), 0);
  for (uint32_t t = 0; t < surface.triangles.size(); ++t) {
    const auto &corners = surface.triangles[t];
    if (surface.fixed(surface.triangle_body[t])) {
      slot_[t] = static_cast<uint32_t>(fixed_->shapes.size());
      fixed_->shapes.push_back(MakeShape(corners, fixed_positions, &fixed_->degenerate));
      fixed_->boxes.push_back(BoxOf(corners, fixed_positions, t));
      continue;
    }
    slot_[t] = static_cast<uint32_t>(free_triangles_.size());
    free_triangles_.push_back(t);
    for (const int32_t v : corners) on_free_surface[v] = 1;
  }
  for (int32_t v = 0; v < surface.num_vertices(); ++v)
    if (on_free_surface[v]) free_surface_vertices_.push_back(v);
}

CrossingCounter::~CrossingCounter() = default;

CrossingCounts CrossingCounter::Count(const std::vector<double> &positions,
                                      const std::optional<GroundPlane> &ground) const {
  CrossingCounts counts;
  counts.degenerate = fixed_->degenerate;
  std::vector<Shape> shapes;  // the free triangles', by slot
  std::vector<Box> boxes;
  CGAL::Bbox_3 region;  // around every free triangle
  for (const uint32_t t : free_triangles_) {
    const auto &corners = surface_.triangles[t];
    if (!Finite(corners, positions)) {
      ++counts.nonfinite;
      shapes.push_back(Point(0, 0, 0));  // keeps the slots; the triangle gets no box
      continue;
    }
    shapes.push_back(MakeShape(corners, positions, &counts.degenerate));
    boxes.push_back(BoxOf(corners, positions, t));
    region += boxes.back().bbox();
  }
  // Free against free: pairs between two bodies, and self pairs sharing no vertex.
  CGAL::box_self_intersection_d(boxes.begin(), boxes.end(), [&](const Box &a, const Box &b) {
    const uint32_t s = a.info(), t = b.info();
    const bool same_body = surface_.triangle_body[s] == surface_.triangle_body[t];
    if (same_body && ShareVertex(surface_.triangles[s], surface_.triangles[t])) return;
    if (ShapesMeet(shapes[slot_[s]], shapes[slot_[t]]))
      ++(same_body ? counts.self : counts.free_free);
  });
  // Free against the fixed triangles near the free bodies.
  std::vector<Box> near;
  for (const Box &box : fixed_->boxes)
    if (BoxesMeet(box, region)) near.push_back(box);
  CGAL::box_intersection_d(
      boxes.begin(), boxes.end(), near.begin(), near.end(), [&](const Box &a, const Box &b) {
        if (ShapesMeet(shapes[slot_[a.info()]], fixed_->shapes[slot_[b.info()]]))
          ++counts.free_fixed;
      });
  if (ground) {
    for (const int32_t v : free_surface_vertices_) {
      const double y = positions[3 * v + 1];
      if (y < ground->y && ground->y - y > ground->tolerance) {
        ++counts.below_ground;
        counts.ground_depth = std::max(counts.ground_depth, ground->y - y);
      }
    }
  }
  return counts;
}

}  // namespace softbody
