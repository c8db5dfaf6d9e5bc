#include "crossings/crossing_count.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/box_intersection_d.h>
#include <CGAL/intersections.h>

#include <algorithm>
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

// Exact: a triangle, or for collinear corners the segment between the extreme
// corners (along a line, lexicographic order is order along the line), or a point.
Shape MakeShape(const Point &a, const Point &b, const Point &c, int64_t *degenerate) {
  if (!CGAL::collinear(a, b, c)) return Triangle(a, b, c);
  ++*degenerate;
  const Point corners[3] = {a, b, c};
  const auto [low, high] = std::minmax_element(
      corners, corners + 3,
      [](const Point &p, const Point &q) { return CGAL::lexicographically_xyz_smaller(p, q); });
  if (*low == *high) return *low;
  return Segment(*low, *high);
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

CrossingCounter::CrossingCounter(const ResultSurface &surface) : surface_(surface) {
  std::vector<char> on_free_surface(surface.num_vertices(), 0);
  for (uint32_t t = 0; t < surface.triangles.size(); ++t) {
    const bool fixed = surface.fixed(surface.triangle_body[t]);
    (fixed ? fixed_triangles_ : free_triangles_).push_back(t);
    if (!fixed)
      for (const int32_t v : surface.triangles[t]) on_free_surface[v] = 1;
  }
  for (int32_t v = 0; v < surface.num_vertices(); ++v)
    if (on_free_surface[v]) free_surface_vertices_.push_back(v);
}

CrossingCounts CrossingCounter::Count(const std::vector<double> &positions,
                                      const std::optional<GroundPlane> &ground) const {
  CrossingCounts counts;
  const auto point = [&](int32_t v) {
    return Point(positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]);
  };
  std::vector<Shape> shapes;
  shapes.reserve(surface_.triangles.size());
  for (const auto &triangle : surface_.triangles)
    shapes.push_back(
        MakeShape(point(triangle[0]), point(triangle[1]), point(triangle[2]), &counts.degenerate));
  const auto boxes_of = [&](const std::vector<uint32_t> &triangles) {
    std::vector<Box> boxes;
    boxes.reserve(triangles.size());
    for (const uint32_t t : triangles) {
      const auto &corners = surface_.triangles[t];
      boxes.emplace_back(
          point(corners[0]).bbox() + point(corners[1]).bbox() + point(corners[2]).bbox(), t);
    }
    return boxes;
  };
  std::vector<Box> free_boxes = boxes_of(free_triangles_), fixed_boxes = boxes_of(fixed_triangles_);
  // Free against free: pairs between two bodies, and self pairs sharing no vertex.
  CGAL::box_self_intersection_d(
      free_boxes.begin(), free_boxes.end(), [&](const Box &a, const Box &b) {
        const uint32_t s = a.info(), t = b.info();
        const bool same_body = surface_.triangle_body[s] == surface_.triangle_body[t];
        if (same_body && ShareVertex(surface_.triangles[s], surface_.triangles[t])) return;
        if (ShapesMeet(shapes[s], shapes[t])) ++(same_body ? counts.self : counts.free_free);
      });
  CGAL::box_intersection_d(free_boxes.begin(), free_boxes.end(), fixed_boxes.begin(),
                           fixed_boxes.end(), [&](const Box &a, const Box &b) {
                             if (ShapesMeet(shapes[a.info()], shapes[b.info()]))
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
