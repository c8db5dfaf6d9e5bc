// Unit tests of the contact kernels, each against a closed form: the segment /
// triangle crossing (geometry.hpp) against the plane intersection computed by
// hand, and the combination of one vertex's velocity constraints
// (projected_solve.hpp) against the exact solution for independent directions
// and the bound |p| <= max |c_k| / cos(angle) for near-parallel ones (the
// least-norm solution of both would prescribe (c_1 - c_2) / sin(angle); see
// docs/design/contact.md).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "contact/geometry.hpp"
#include "solvers/projected_solve.hpp"

namespace softbody {
namespace {

TEST(SegmentCrossesTriangle, HitsThePlaneWhereTheLineSays) {
  // Triangle in the plane z = 1; segment from (0.2, 0.3, 3) to (0.2, 0.3, -1):
  // crosses at t = (3 - 1) / 4 = 0.5, at (0.2, 0.3, 1), weights (0.5, 0.2, 0.3).
  const Point a(0, 0, 1), b(1, 0, 1), c(0, 1, 1);
  double t;
  Eigen::Vector3d w;
  ASSERT_TRUE(SegmentCrossesTriangle(Point(0.2, 0.3, 3), Point(0.2, 0.3, -1), a, b, c, &t, &w));
  EXPECT_NEAR(t, 0.5, 1e-15);
  EXPECT_NEAR(w[0], 0.5, 1e-15);
  EXPECT_NEAR(w[1], 0.2, 1e-15);
  EXPECT_NEAR(w[2], 0.3, 1e-15);
  // A slanted segment: p = (1, 1, 2) -> q = (-1, -1, 0) meets z = 1 at t = 0.5, (0, 0, 1) = a.
  ASSERT_TRUE(SegmentCrossesTriangle(Point(1, 1, 2), Point(-1, -1, 0), a, b, c, &t, &w));
  EXPECT_NEAR(t, 0.5, 1e-15);
  EXPECT_NEAR(w[0], 1.0, 1e-15);
}

TEST(SegmentCrossesTriangle, MissesOutsideTheTriangleOrTheSegment) {
  const Point a(0, 0, 1), b(1, 0, 1), c(0, 1, 1);
  double t;
  Eigen::Vector3d w;
  EXPECT_FALSE(SegmentCrossesTriangle(Point(0.6, 0.6, 3), Point(0.6, 0.6, -1), a, b, c, &t,
                                      &w));  // u + v > 1
  EXPECT_FALSE(SegmentCrossesTriangle(Point(0.2, 0.3, 3), Point(0.2, 0.3, 1.5), a, b, c, &t,
                                      &w));  // stops short
  EXPECT_FALSE(
      SegmentCrossesTriangle(Point(0, 0, 2), Point(1, 0, 2), a, b, c, &t, &w));  // parallel
}

VelocityConstraint Constraint(const Eigen::Vector3d &normal, double velocity,
                              bool immobile = false) {
  return {7, normal.normalized(), velocity, immobile};
}

// n_k . p for every constraint.
std::vector<double> Achieved(const ConstrainedVertex &c,
                             const std::vector<VelocityConstraint> &list) {
  std::vector<double> out;
  for (const VelocityConstraint &k : list) out.push_back(k.normal.dot(c.prescribed));
  return out;
}

TEST(CombineConstraints, OneConstraintIsImposedExactly) {
  const std::vector<VelocityConstraint> list = {Constraint({0, 1, 0}, -0.25)};
  const ConstrainedVertex c = CombineConstraints(7, list);
  EXPECT_EQ(c.vertex, 7);
  EXPECT_EQ(c.rank, 1);
  EXPECT_NEAR((c.prescribed - Eigen::Vector3d(0, -0.25, 0)).norm(), 0, 1e-15);
}

TEST(CombineConstraints, IndependentDirectionsAreAllImposed) {
  // A corner: the ground (y) and a wall at 60 degrees from it; the exact
  // solution of n_1 . p = 1, n_2 . p = 2 in span(n_1, n_2).
  const Eigen::Vector3d n1(0, 1, 0), n2(std::sin(M_PI / 3), std::cos(M_PI / 3), 0);
  const std::vector<VelocityConstraint> list = {Constraint(n1, 1.0, true), Constraint(n2, 2.0)};
  const ConstrainedVertex c = CombineConstraints(7, list);
  EXPECT_EQ(c.rank, 2);
  const std::vector<double> achieved = Achieved(c, list);
  EXPECT_NEAR(achieved[0], 1.0, 1e-13);
  EXPECT_NEAR(achieved[1], 2.0, 1e-13);
  EXPECT_NEAR(c.prescribed[2], 0.0, 1e-15);
  // The basis spans both directions: projecting them changes nothing.
  const auto Q = c.basis.leftCols(c.rank);
  EXPECT_NEAR((Q * (Q.transpose() * n2) - n2).norm(), 0, 1e-14);
}

TEST(CombineConstraints, NearParallelDirectionsStayBounded) {
  // The ground and another body's face 1e-4 rad apart, asking 1 and 3 m/s:
  // imposing both would need (3 - cos(1e-4)) / sin(1e-4) ~ 2e4 m/s along the
  // face. Combined: the faster one alone, |p| = 3 m/s, and the ground's
  // n . p = 3 cos(1e-4) >= 1 still holds.
  const double angle = 1e-4;
  const Eigen::Vector3d ground(0, 1, 0), face(std::sin(angle), std::cos(angle), 0);
  const std::vector<VelocityConstraint> list = {Constraint(ground, 1.0, true),
                                                Constraint(face, 3.0)};
  const ConstrainedVertex c = CombineConstraints(7, list);
  EXPECT_EQ(c.rank, 1);
  EXPECT_NEAR(c.prescribed.norm(), 3.0, 1e-12);
  const std::vector<double> achieved = Achieved(c, list);
  EXPECT_GE(achieved[0], 1.0);
  EXPECT_NEAR(achieved[1], 3.0, 1e-12);
}

TEST(CombineConstraints, TiesGoToTheImmobileObstacle) {
  // Resting on both (targets 0) along directions 3 degrees apart: too close to
  // impose together, either alone (p = 0) satisfies the other; the ground's
  // direction is the one imposed exactly (the other holds up to the free
  // velocity's component along it).
  const double angle = 3 * M_PI / 180;
  const Eigen::Vector3d ground(0, 1, 0), face(std::sin(angle), std::cos(angle), 0);
  const std::vector<VelocityConstraint> list = {Constraint(face, 0.0),
                                                Constraint(ground, 0.0, true)};
  const ConstrainedVertex c = CombineConstraints(7, list);
  ASSERT_EQ(c.rank, 1);
  EXPECT_NEAR(std::abs(c.basis.col(0).dot(ground)), 1.0, 1e-15);
}

TEST(CombineConstraints, ThreeWallsOfACornerAreAllImposed) {
  const std::vector<VelocityConstraint> list = {Constraint({1, 0, 0}, 0.5, true),
                                                Constraint({0, 1, 0}, -1.0, true),
                                                Constraint({0, 0, 1}, 2.0, true)};
  const ConstrainedVertex c = CombineConstraints(7, list);
  EXPECT_EQ(c.rank, 3);
  EXPECT_NEAR((c.prescribed - Eigen::Vector3d(0.5, -1.0, 2.0)).norm(), 0, 1e-14);
}

}  // namespace
}  // namespace softbody
