// Continuous collision detection of surface primitives moving linearly over a
// step: a point against a triangle and an edge against an edge, each vertex
// going from its start to its end position as t runs from 0 to 1.
//
// The test is additive CCD (Li, Kaufman, Jiang, "Codimensional Incremental
// Potential Contact", SIGGRAPH 2021, section 5): conservative advancement on the
// distance. With the vertices' displacements taken relative to their mean, the
// distance between the primitives cannot fall faster than l_p, the largest
// displacement of one side plus that of the other; so from a time t with
// distance d, the pair stays farther apart than `separation` until
// t + (d - separation) / l_p. Advancing by a fraction of that bound either
// passes t = 1 (the pair stayed apart: never closer than `separation`, so it
// starts the next step guarded) or creeps up to the first time the distance
// comes within `band` of `separation` (reported as a collision; a pair that
// starts within the band, once it closes half of its gap). It never misses a
// collision, at any speed; it may report a pair that only came within the band.
//
// Lengths in metres; t is the fraction of the step. Not collective.
#pragma once

#include <array>

#include "contact/geometry.hpp"

namespace softbody {

// Squared distance between the point p and the triangle (a, b, c).
double PointTriangleDistanceSquared(const Point &p, const Point &a, const Point &b, const Point &c);
// Squared distance between the segments (a0, a1) and (b0, b1); parallel and
// degenerate segments included.
double EdgeEdgeDistanceSquared(const Point &a0, const Point &a1, const Point &b0, const Point &b1);

// What a CCD query tells.
enum class Approach {
  kApart,         // farther than `separation` throughout the step
  kCollides,      // comes within separation + band at some time in [0, 1]
  kCloseAtStart,  // within separation already at t = 0: cannot be guarded
};

// A primitive pair's vertices at the start and the end of the step: for a
// point and a triangle (p, a, b, c), for two edges (a0, a1, b0, b1).
struct MovingPair {
  std::array<Point, 4> start, end;
};

struct CcdTolerance {
  double separation = 0;  // the distance the pair must keep (m), > 0
  double band = 0;        // reported closer than separation + band (m), > 0
};

// Point (vertex 0) against triangle (vertices 1, 2, 3).
Approach PointTriangleCcd(const MovingPair &pair, const CcdTolerance &tolerance);
// Edge (vertices 0, 1) against edge (vertices 2, 3).
Approach EdgeEdgeCcd(const MovingPair &pair, const CcdTolerance &tolerance);

}  // namespace softbody
