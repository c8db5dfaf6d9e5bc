// Exact counts of crossing surface triangles in one frame of a result file.
//
// Two surface triangles cross when they intersect as closed point sets (their
// boundaries included), decided by CGAL's exact predicates
// (Exact_predicates_inexact_constructions_kernel, CGAL::do_intersect): two
// triangles that only touch at a point or along an edge count as crossing.
// Candidate pairs come from CGAL::box_intersection_d on the triangles'
// bounding boxes (closed boxes, exact: a box is the min/max of the corners).
// Kinds of pairs:
//   free-free   a triangle of one free body and one of another free body;
//   free-fixed  a free body's triangle and a fixed body's (obstacles);
//   self        two triangles of one free body that share no vertex (triangles
//               sharing a vertex or an edge touch by construction and are
//               never counted);
// fixed bodies never move, so pairs of two fixed triangles are not counted.
// A triangle whose corners are collinear (exactly) is tested as the segment
// between its extreme corners, or as a point when they coincide. A free triangle
// with a non-finite corner (a run that blew up) is counted apart and not tested.
// Ground: the free bodies' surface vertices strictly below y = y0 - tolerance.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "crossings/result_file.hpp"

namespace softbody {

struct GroundPlane {
  double y = 0;          // height y0 of the plane (m); bodies belong above it
  double tolerance = 0;  // depth below y0 that is not counted (m; 0: exact)
};

struct CrossingCounts {
  int64_t free_free = 0;     // intersecting triangle pairs between two free bodies
  int64_t free_fixed = 0;    // between a free body and a fixed one
  int64_t self = 0;          // within one free body, sharing no vertex
  int64_t below_ground = 0;  // free bodies' surface vertices with y < y0 - tolerance
  double ground_depth = 0;   // the deepest of them below the ground (m; 0 when none)
  int64_t degenerate = 0;    // triangles with collinear corners (tested as segments or points)
  int64_t nonfinite = 0;     // free triangles with a NaN or infinite corner (not tested)
  // A crossing of any kind, or a frame that could not be checked whole.
  bool any() const {
    return free_free > 0 || free_fixed > 0 || self > 0 || below_ground > 0 || nonfinite > 0;
  }
};

class CrossingCounter {
 public:
  // Not collective. Keeps a reference to `surface`, which must outlive the
  // counter. The fixed bodies' triangles, boxes and shapes are made once, from
  // `fixed_positions` ([V][3] flattened, m; only the fixed bodies' rows are read):
  // fixed bodies never move.
  CrossingCounter(const ResultSurface &surface, const std::vector<double> &fixed_positions);
  ~CrossingCounter();
  CrossingCounter(const CrossingCounter &) = delete;
  CrossingCounter &operator=(const CrossingCounter &) = delete;
  // Not collective. `positions` [V][3] flattened (m; only the free bodies' rows
  // are read); no ground count without `ground`.
  CrossingCounts Count(const std::vector<double> &positions,
                       const std::optional<GroundPlane> &ground) const;

 private:
  struct Fixed;  // the fixed triangles' shapes and boxes (CGAL types)

  const ResultSurface &surface_;
  std::vector<uint32_t> free_triangles_;
  std::vector<uint32_t> slot_;  // triangle -> its index among the free or the fixed ones
  std::vector<int32_t> free_surface_vertices_;  // vertices of the free bodies' triangles
  std::unique_ptr<Fixed> fixed_;
};

}  // namespace softbody
