// Unit tests of Coulomb friction's decisions over the solve rounds
// (contact/friction.hpp), one contact on the ground (normal +y, immobile,
// vertex mass 1 kg, mu = 0.5), each decision against the impulse it must put
// into the right-hand side by hand: an undecided sliding contact slips with
// mu lambda against its sliding; a slip that the next solve shows reversed by
// less than 2 mu lambda / m sticks (its impulse taken back out, two tangent
// constraints holding the obstacle's velocity); a reversal faster than that
// keeps slipping, its impulse flipped, and a slip turns with its sliding; a sticking contact whose
// tangential reaction exceeds mu lambda slips along that reaction; a slip's magnitude follows
// lambda.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "contact/friction.hpp"

namespace softbody {
namespace {

constexpr double kMu = 0.5;
constexpr double kLambda = 2.0;  // normal impulse (N s): mu lambda = 1 N s

class OneContact : public ::testing::Test {
 protected:
  void SetUp() override {
    friction_.Setup(kMu, [](int32_t) { return 1.0; });
    friction_.Clear();
    normals_ = {{0, Point(0, 1, 0), 0.0, true}};
    contacts_ = {Contact{0, -1, 0.0, false}};
  }
  // Observes velocity v of the vertex, then Update with `reactions`.
  PetscInt Round(const Point &v, const std::vector<PetscReal> &reactions) {
    friction_.Observe(normals_, contacts_, v.data());
    return friction_.Update(reactions, 1, rhs_.data());
  }
  Point Rhs() const { return Point(rhs_.data()); }

  Friction friction_;
  std::vector<VelocityConstraint> normals_;
  std::vector<Contact> contacts_;
  std::vector<PetscScalar> rhs_ = std::vector<PetscScalar>(3, 0.0);
};

TEST_F(OneContact, SlidingContactSlipsAgainstItsSliding) {
  EXPECT_EQ(Round(Point(3, -0.1, 4), {kLambda}), 1);
  // mu lambda = 1 N s along -(3, 0, 4) / 5.
  EXPECT_NEAR((Rhs() - Point(-0.6, 0, -0.8)).norm(), 0, 1e-15);
  EXPECT_TRUE(friction_.tangents().empty());
  EXPECT_EQ(friction_.InSolve(1)[0], 1);
}

TEST_F(OneContact, SlipReversedSlowlySticks) {
  Round(Point(1, 0, 0), {kLambda});
  // The next solve: the slip drove it back at 0.5 m/s < 2 mu lambda / m = 2 m/s.
  EXPECT_EQ(Round(Point(-0.5, 0, 0), {kLambda}), 1);
  EXPECT_NEAR(Rhs().norm(), 0, 1e-15);
  ASSERT_EQ(friction_.tangents().size(), 2u);
  for (const VelocityConstraint &t : friction_.tangents()) {
    EXPECT_NEAR(t.normal.dot(Point(0, 1, 0)), 0, 1e-15);
    EXPECT_EQ(t.velocity, 0.0);
    EXPECT_TRUE(t.immobile);
  }
}

TEST_F(OneContact, SlipReversedFastKeepsSlippingTurned) {
  Round(Point(1, 0, 0), {kLambda});
  // Still sliding along +x, faster: trial r - m v = (-1 - 3, 0, 0), the impulse stays.
  EXPECT_EQ(Round(Point(3, 0, 0), {kLambda}), 0);
  EXPECT_NEAR((Rhs() - Point(-1, 0, 0)).norm(), 0, 1e-15);
  // Reversed at 3 m/s > 2 mu lambda / m: trial (-1 + 3, 0, 0), the impulse flips.
  EXPECT_EQ(Round(Point(-3, 0, 0), {kLambda}), 1);
  EXPECT_NEAR((Rhs() - Point(1, 0, 0)).norm(), 0, 1e-15);
  // Sliding along +z now: the trial (1, 0, -2) turns the impulse towards it.
  EXPECT_EQ(Round(Point(0, 0, 2), {kLambda}), 1);
  EXPECT_NEAR((Rhs() - Point(1, 0, -2) / std::sqrt(5.0)).norm(), 0, 1e-15);
  EXPECT_TRUE(friction_.tangents().empty());
}

TEST_F(OneContact, StickingBeyondTheConeSlipsAlongItsReaction) {
  Round(Point(0, 0, 0), {kLambda});  // at rest: sticks
  ASSERT_EQ(friction_.tangents().size(), 2u);
  EXPECT_NEAR(Rhs().norm(), 0, 1e-15);
  // Tangential reactions 1.2 and 1.6 N s: |r| = 2 > mu lambda = 1.
  const auto &t = friction_.tangents();
  const Point reaction = 1.2 * t[0].normal + 1.6 * t[1].normal;
  EXPECT_EQ(Round(Point(0, 0, 0), {kLambda, 1.2, 1.6}), 1);
  EXPECT_TRUE(friction_.tangents().empty());
  EXPECT_NEAR((Rhs() - reaction / reaction.norm()).norm(), 0, 1e-15);
}

TEST_F(OneContact, StickingWithinTheConeHolds) {
  Round(Point(0, 0, 0), {kLambda});
  EXPECT_EQ(Round(Point(0, 0, 0), {kLambda, 0.6, 0.8}), 0);  // |r| = 1 = mu lambda
  EXPECT_EQ(friction_.tangents().size(), 2u);
}

TEST_F(OneContact, SlipFollowsTheNormalReaction) {
  Round(Point(1, 0, 0), {kLambda});
  EXPECT_EQ(Round(Point(1, 0, 0), {3.0}), 1);  // mu lambda 1 -> 1.5
  EXPECT_NEAR((Rhs() - Point(-1.5, 0, 0)).norm(), 0, 1e-15);
  EXPECT_EQ(Round(Point(1, 0, 0), {-1.0}), 1);  // pulls: no friction
  EXPECT_NEAR(Rhs().norm(), 0, 1e-15);
}

}  // namespace
}  // namespace softbody
