#include "contact/ccd.hpp"

#include <algorithm>
#include <cmath>

namespace softbody {

namespace {

// Each advancement covers this fraction of the time the pair provably stays
// apart: below 1 so that the distance at the new time stays above the
// separation by a tenth of the gap (Li et al. 2021 use 0.9 too).
constexpr double kAdvanceFraction = 0.9;
// Advancements before a pair that neither collides nor clears is reported as
// colliding (conservative). A pair sliding at gap g with displacement l_p per
// step needs about l_p / (0.9 g) of them: 1e4 covers a displacement of 9 000
// gaps in one step.
constexpr int kMaxAdvancements = 10000;
// A triangle is treated as its three edges when twice its squared area is
// below this fraction of its longest squared edge to the fourth power
// (round-off level: the closest-point regions are not defined).
constexpr double kDegenerateTriangle = 1e-24;

double PointSegmentDistanceSquared(const Point &p, const Point &a, const Point &b) {
  const Point ab = b - a;
  const double length2 = ab.squaredNorm();
  const double t = length2 > 0 ? std::clamp((p - a).dot(ab) / length2, 0.0, 1.0) : 0.0;
  return (a + t * ab - p).squaredNorm();
}

// The segments' closest interior points when they are not parallel, else +inf.
double InteriorDistanceSquared(const Point &a0, const Point &a1, const Point &b0, const Point &b1) {
  const Point d1 = a1 - a0, d2 = b1 - b0, r = a0 - b0;
  const double a = d1.squaredNorm(), b = d1.dot(d2), e = d2.squaredNorm();
  const double c = d1.dot(r), f = d2.dot(r);
  const double denominator = a * e - b * b;
  if (!(denominator > 0)) return INFINITY;
  const double s = (b * f - c * e) / denominator, t = (a * f - b * c) / denominator;
  if (s <= 0 || s >= 1 || t <= 0 || t >= 1) return INFINITY;
  return (a0 + s * d1 - b0 - t * d2).squaredNorm();
}

// Displacements relative to their mean: the distance does not change under a
// common translation, so only these move the pair apart or together.
std::array<Point, 4> RelativeDisplacements(const MovingPair &pair) {
  std::array<Point, 4> p;
  Point mean = Point::Zero();
  for (int i = 0; i < 4; ++i) mean += (p[i] = pair.end[i] - pair.start[i]);
  mean /= 4;
  for (Point &d : p) d -= mean;
  return p;
}

// The vertices at time t of the step.
std::array<Point, 4> At(const MovingPair &pair, double t) {
  std::array<Point, 4> x;
  for (int i = 0; i < 4; ++i) x[i] = pair.start[i] + t * (pair.end[i] - pair.start[i]);
  return x;
}

// Conservative advancement (ccd.hpp): `first` vertices on one side, the rest
// on the other; distance(x) the distance between the sides.
template <typename Distance>
Approach Advance(const MovingPair &pair, int first, const CcdTolerance &tolerance,
                 Distance distance) {
  double d = distance(pair.start);
  if (d <= tolerance.separation) return Approach::kCloseAtStart;
  // A pair that starts within the band is reported once it closes half its gap.
  const double reported =
      tolerance.separation + std::min(tolerance.band, (d - tolerance.separation) / 2);
  const std::array<Point, 4> p = RelativeDisplacements(pair);
  double max_a = 0, max_b = 0;
  for (int i = 0; i < 4; ++i) {
    double &side = i < first ? max_a : max_b;
    side = std::max(side, p[i].norm());
  }
  const double bound = max_a + max_b;  // the distance changes at most this fast
  if (bound == 0) return Approach::kApart;
  double t = 0;
  for (int advancement = 0; advancement < kMaxAdvancements; ++advancement) {
    t += kAdvanceFraction * (d - tolerance.separation) / bound;
    if (t >= 1) return Approach::kApart;
    d = distance(At(pair, t));
    if (d <= reported) return Approach::kCollides;
  }
  return Approach::kCollides;
}

}  // namespace

double PointTriangleDistanceSquared(const Point &p, const Point &a, const Point &b,
                                    const Point &c) {
  const double longest =
      std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  if ((b - a).cross(c - a).squaredNorm() <= kDegenerateTriangle * longest * longest)
    return std::min({PointSegmentDistanceSquared(p, a, b), PointSegmentDistanceSquared(p, b, c),
                     PointSegmentDistanceSquared(p, c, a)});
  Eigen::Vector3d weights;
  return (ClosestPointOnTriangle(p, a, b, c, &weights) - p).squaredNorm();
}

// The closest pair is interior to both segments or has an end point in it:
// the minimum over the interior solution and the four end points' distances
// stays right for parallel and degenerate segments.
double EdgeEdgeDistanceSquared(const Point &a0, const Point &a1, const Point &b0, const Point &b1) {
  return std::min({InteriorDistanceSquared(a0, a1, b0, b1), PointSegmentDistanceSquared(a0, b0, b1),
                   PointSegmentDistanceSquared(a1, b0, b1), PointSegmentDistanceSquared(b0, a0, a1),
                   PointSegmentDistanceSquared(b1, a0, a1)});
}

Approach PointTriangleCcd(const MovingPair &pair, const CcdTolerance &tolerance) {
  return Advance(pair, 1, tolerance, [](const std::array<Point, 4> &x) {
    return std::sqrt(PointTriangleDistanceSquared(x[0], x[1], x[2], x[3]));
  });
}

Approach EdgeEdgeCcd(const MovingPair &pair, const CcdTolerance &tolerance) {
  return Advance(pair, 2, tolerance, [](const std::array<Point, 4> &x) {
    return std::sqrt(EdgeEdgeDistanceSquared(x[0], x[1], x[2], x[3]));
  });
}

}  // namespace softbody
