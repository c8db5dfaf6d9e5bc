// Unit tests of the collision guard's kernels (contact/ccd.hpp,
// contact/impact_zones.hpp), each against something computed another way:
// - the distances against a brute-force minimum over a fine grid of
//   barycentric / segment parameters;
// - CCD against dense sampling of the distance along the step: whenever a
//   sample comes within the separation the pair must be reported, a pair
//   reported apart must stay beyond it at every sample, and a reported
//   collision must have a sample near separation + band; tunnelling cases
//   (a point or an edge crossing at any speed) by construction;
// - rigid impact zones against the conservation laws: a mobile zone keeps its
//   linear and angular momentum, never gains kinetic energy and keeps its
//   pairwise distances; an immobile one stays where it started.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "contact/ccd.hpp"
#include "contact/impact_zones.hpp"

namespace softbody {
namespace {

Point RandomPoint(std::mt19937 &rng, double scale) {
  std::uniform_real_distribution<double> u(-scale, scale);
  return Point(u(rng), u(rng), u(rng));
}

double BruteForcePointTriangle(const Point &p, const Point &a, const Point &b, const Point &c) {
  constexpr int kSteps = 400;
  double best = INFINITY;
  for (int i = 0; i <= kSteps; ++i)
    for (int j = 0; i + j <= kSteps; ++j) {
      const double u = double(i) / kSteps, v = double(j) / kSteps;
      best = std::min(best, (a + u * (b - a) + v * (c - a) - p).norm());
    }
  return best;
}

double BruteForceEdgeEdge(const Point &a0, const Point &a1, const Point &b0, const Point &b1) {
  constexpr int kSteps = 600;
  double best = INFINITY;
  for (int i = 0; i <= kSteps; ++i)
    for (int j = 0; j <= kSteps; ++j) {
      const double s = double(i) / kSteps, t = double(j) / kSteps;
      best = std::min(best, (a0 + s * (a1 - a0) - b0 - t * (b1 - b0)).norm());
    }
  return best;
}

TEST(Distances, MatchABruteForceMinimum) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 200; ++trial) {
    const Point p = RandomPoint(rng, 1), a = RandomPoint(rng, 1), b = RandomPoint(rng, 1),
                c = RandomPoint(rng, 1);
    // The grids' spacing bounds the brute force's excess: edge / steps.
    const double pt = std::sqrt(PointTriangleDistanceSquared(p, a, b, c));
    const double brute_pt = BruteForcePointTriangle(p, a, b, c);
    EXPECT_LE(pt, brute_pt + 1e-12);
    EXPECT_GE(pt, brute_pt - 2 * 3.5 / 400);
    const double ee = std::sqrt(EdgeEdgeDistanceSquared(p, a, b, c));
    const double brute_ee = BruteForceEdgeEdge(p, a, b, c);
    EXPECT_LE(ee, brute_ee + 1e-12);
    EXPECT_GE(ee, brute_ee - 2 * 3.5 / 600);
  }
}

TEST(Distances, ParallelAndDegenerateEdges) {
  // Parallel segments overlapping in x, 0.25 apart in z: distance 0.25.
  EXPECT_NEAR(std::sqrt(EdgeEdgeDistanceSquared(Point(0, 0, 0), Point(1, 0, 0), Point(0.5, 0, 0.25),
                                                Point(2, 0, 0.25))),
              0.25, 1e-15);
  // Collinear, disjoint: end to end, 0.5.
  EXPECT_NEAR(std::sqrt(EdgeEdgeDistanceSquared(Point(0, 0, 0), Point(1, 0, 0), Point(1.5, 0, 0),
                                                Point(3, 0, 0))),
              0.5, 1e-15);
  // A degenerate edge (a point) against a segment.
  EXPECT_NEAR(std::sqrt(EdgeEdgeDistanceSquared(Point(0.5, 1, 0), Point(0.5, 1, 0), Point(0, 0, 0),
                                                Point(1, 0, 0))),
              1.0, 1e-15);
  // A degenerate triangle (collinear vertices): the distance to its segment.
  EXPECT_NEAR(std::sqrt(PointTriangleDistanceSquared(Point(0.5, 2, 0), Point(0, 0, 0),
                                                     Point(1, 0, 0), Point(2, 0, 0))),
              2.0, 1e-15);
}

// Distance along the step at n + 1 samples: min and whether any is within `below`.
template <typename Distance>
double SampledMinimum(const MovingPair &pair, Distance distance, int n) {
  double best = INFINITY;
  for (int i = 0; i <= n; ++i) {
    const double t = double(i) / n;
    std::array<Point, 4> x;
    for (int k = 0; k < 4; ++k) x[k] = pair.start[k] + t * (pair.end[k] - pair.start[k]);
    best = std::min(best, distance(x));
  }
  return best;
}

double PointTriangleAt(const std::array<Point, 4> &x) {
  return std::sqrt(PointTriangleDistanceSquared(x[0], x[1], x[2], x[3]));
}
double EdgeEdgeAt(const std::array<Point, 4> &x) {
  return std::sqrt(EdgeEdgeDistanceSquared(x[0], x[1], x[2], x[3]));
}

// The fastest change of the distance per unit t (bounds sampling's miss).
double Speed(const MovingPair &pair) {
  double fastest = 0;
  for (int k = 0; k < 4; ++k) fastest = std::max(fastest, (pair.end[k] - pair.start[k]).norm());
  return 2 * fastest;
}

TEST(Ccd, AgreesWithDenseSampling) {
  std::mt19937 rng(11);
  const CcdTolerance tolerance{0.02, 0.002};
  constexpr int kSamples = 20000;
  int collided = 0, apart = 0;
  for (int trial = 0; trial < 400; ++trial) {
    MovingPair pair;
    for (int k = 0; k < 4; ++k) {
      pair.start[k] = RandomPoint(rng, 1) +
                      (k == 0 || (trial % 2 && k == 1) ? Point(0, 0, 1.2) : Point::Zero());
      pair.end[k] = pair.start[k] + RandomPoint(rng, 1.5);
    }
    const bool vertex_triangle = trial % 2 == 0;
    const Approach approach =
        vertex_triangle ? PointTriangleCcd(pair, tolerance) : EdgeEdgeCcd(pair, tolerance);
    const double sampled = vertex_triangle ? SampledMinimum(pair, PointTriangleAt, kSamples)
                                           : SampledMinimum(pair, EdgeEdgeAt, kSamples);
    const double start = vertex_triangle ? PointTriangleAt(pair.start) : EdgeEdgeAt(pair.start);
    if (start <= tolerance.separation) {
      EXPECT_EQ(approach, Approach::kCloseAtStart);
      continue;
    }
    if (approach == Approach::kApart) {
      ++apart;
      EXPECT_GT(sampled, tolerance.separation) << "trial " << trial;
    } else {
      ++collided;
      ASSERT_EQ(approach, Approach::kCollides);
      EXPECT_LE(sampled, tolerance.separation + tolerance.band + Speed(pair) / kSamples)
          << "trial " << trial;
    }
  }
  // Both verdicts occur, so both branches were checked.
  EXPECT_GT(collided, 20);
  EXPECT_GT(apart, 20);
}

TEST(Ccd, NothingTunnelsAtAnySpeed) {
  const CcdTolerance tolerance{1e-4, 1e-5};
  for (const double speed : {1.0, 1e3, 1e6}) {
    // A point through the triangle z = 0 from z = +speed to z = -speed.
    MovingPair pt;
    pt.start = {Point(0.2, 0.2, speed), Point(0, 0, 0), Point(1, 0, 0), Point(0, 1, 0)};
    pt.end = {Point(0.2, 0.2, -speed), Point(0, 0, 0), Point(1, 0, 0), Point(0, 1, 0)};
    EXPECT_EQ(PointTriangleCcd(pt, tolerance), Approach::kCollides) << speed;
    // Two crossing edges, one swept through the other.
    MovingPair ee;
    ee.start = {Point(-1, 0, speed), Point(1, 0, speed), Point(0, -1, 0), Point(0, 1, 0)};
    ee.end = {Point(-1, 0, -speed), Point(1, 0, -speed), Point(0, -1, 0), Point(0, 1, 0)};
    EXPECT_EQ(EdgeEdgeCcd(ee, tolerance), Approach::kCollides) << speed;
    // The same edge passing beside the other (x from 2 to 4): apart.
    for (int k = 0; k < 2; ++k) {
      ee.start[k].x() += 3;
      ee.end[k].x() += 3;
    }
    EXPECT_EQ(EdgeEdgeCcd(ee, tolerance), Approach::kApart) << speed;
  }
}

TEST(Ccd, SlidingAtTheGapIsApart) {
  // A point sliding 0.5 m over a face at 2 separations: never reported.
  const CcdTolerance tolerance{1e-4, 1e-5};
  MovingPair pt;
  pt.start = {Point(0.1, 0.1, 2e-4), Point(0, 0, 0), Point(1, 0, 0), Point(0, 1, 0)};
  pt.end = {Point(0.4, 0.4, 2e-4), Point(0, 0, 0), Point(1, 0, 0), Point(0, 1, 0)};
  EXPECT_EQ(PointTriangleCcd(pt, tolerance), Approach::kApart);
  // Starting within the separation: cannot be guarded.
  pt.start[0].z() = pt.end[0].z() = 5e-5;
  EXPECT_EQ(PointTriangleCcd(pt, tolerance), Approach::kCloseAtStart);
}

struct Motion {
  Point momentum, angular;
  double kinetic;
};

Motion MotionOf(const std::vector<int32_t> &zone, const std::vector<Point> &start,
                const std::vector<Point> &end, const std::vector<double> &mass) {
  Motion m{Point::Zero(), Point::Zero(), 0};
  for (const int32_t v : zone) {
    const Point u = end[v] - start[v];
    m.momentum += mass[v] * u;
    m.angular += mass[v] * start[v].cross(u);
    m.kinetic += 0.5 * mass[v] * u.squaredNorm();
  }
  return m;
}

TEST(ImpactZones, MobileZonesMoveRigidlyAndConserveMomentum) {
  std::mt19937 rng(3);
  const int n = 6;
  std::vector<Point> start(n), end(n);
  std::vector<double> mass(n);
  std::uniform_real_distribution<double> m(0.5, 2);
  for (int v = 0; v < n; ++v) {
    start[v] = RandomPoint(rng, 1);
    end[v] = start[v] + RandomPoint(rng, 0.1);
    mass[v] = m(rng);
  }
  ImpactZones zones;
  zones.Reset(n);
  const int32_t pair[4] = {0, 1, 2, 3};
  zones.Merge(pair, 4, false);
  const std::vector<int32_t> zone = {0, 1, 2, 3};
  const Motion before = MotionOf(zone, start, end, mass);
  const std::vector<Point> untouched = {end[4], end[5]};
  const std::vector<int32_t> changed = zones.Move(start, mass, &end);
  EXPECT_EQ(changed.size(), 4u);
  const Motion after = MotionOf(zone, start, end, mass);
  // Linear momentum exactly; angular momentum to the rotation's second order
  // (|theta| ~ 0.1: the exact rotation differs from the linear one by
  // theta^2 / 2 of the lever arm).
  EXPECT_LT((after.momentum - before.momentum).norm(), 1e-14);
  EXPECT_LT((after.angular - before.angular).norm(), 0.05 * before.angular.norm() + 1e-3);
  EXPECT_LE(after.kinetic, before.kinetic * (1 + 1e-12));
  for (int a : zone)
    for (int b : zone) EXPECT_NEAR((end[a] - end[b]).norm(), (start[a] - start[b]).norm(), 1e-14);
  EXPECT_EQ(end[4], untouched[0]);
  EXPECT_EQ(end[5], untouched[1]);
}

TEST(ImpactZones, ImmobileAndSelfCollidingZonesStayPut) {
  std::vector<Point> start = {Point(0, 0, 0), Point(1, 0, 0), Point(0, 1, 0)};
  std::vector<Point> end = {Point(0, 0, -1), Point(1, 0, -1), Point(0, 1, -1)};
  const std::vector<double> mass = {1, 1, 1};
  ImpactZones zones;
  zones.Reset(3);
  const int32_t a[2] = {0, 1};
  zones.Merge(a, 2, true);  // meets something immobile
  zones.Move(start, mass, &end);
  EXPECT_EQ(end[0], start[0]);
  EXPECT_EQ(end[1], start[1]);
  EXPECT_EQ(end[2], Point(0, 1, -1));
  // A pair inside one mobile zone collides again: the zone freezes.
  zones.Reset(3);
  end = {Point(0, 0, -1), Point(1, 0, -1), Point(0, 1, -1)};
  const int32_t b[2] = {1, 2};
  zones.Merge(b, 2, false);
  zones.Move(start, mass, &end);
  EXPECT_FALSE(zones.immobile(1));
  ASSERT_TRUE(zones.InOneMobileZone(b, 2));
  EXPECT_FALSE(zones.InOneMobileZone(a, 2));
  zones.Merge(b, 2, true);
  zones.Move(start, mass, &end);
  EXPECT_TRUE(zones.immobile(2));
  EXPECT_EQ(end[2], start[2]);
}

}  // namespace
}  // namespace softbody
