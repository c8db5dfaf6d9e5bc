// Corotational element kernels (element.hpp): checked against the linear element
// stiffness, against exact rigid motions, and against the properties a rotation
// must have.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

#include "fem/element.hpp"

using namespace softbody;

namespace {

std::mt19937 rng(7);

Mat3 RandomRotation() {
  std::normal_distribution<double> n;
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  return q.normalized().toRotationMatrix();
}

TetPositions RandomTet() {
  std::uniform_real_distribution<double> u(-1, 1);
  TetPositions X;
  do {
    for (int a = 0; a < 4; ++a)
      for (int c = 0; c < 3; ++c) X(a, c) = u(rng);
  } while (std::abs(SignedVolume(X)) < 0.02);
  return X;
}

Vec12 Flatten(const TetPositions &P) {
  Vec12 v;
  for (int a = 0; a < 4; ++a) v.segment<3>(3 * a) = P.row(a).transpose();
  return v;
}

const Lame kLame = LameFromYoungPoisson(1e5, 0.35);

}  // namespace

// f = K_e u and E = u^T K_e u / 2, computed without K_e, equal the matrix forms.
TEST(ElasticForceAndEnergy, EqualsStiffnessTimesDisplacement) {
  std::normal_distribution<double> n;
  for (double s : {1.0, 0.25}) {
    for (int trial = 0; trial < 20; ++trial) {
      const TetPositions X = RandomTet();
      const ShapeGradients g = ComputeShapeGradients(X);
      const double V = std::abs(SignedVolume(X));
      TetPositions u;
      for (int a = 0; a < 4; ++a)
        for (int c = 0; c < 3; ++c) u(a, c) = n(rng);
      TetPositions f;
      double energy;
      ElasticForceAndEnergy(g, V, kLame, s, u, &f, &energy);
      const Mat12 K = ElementStiffness(g, V, kLame, s);
      const Vec12 Ku = K * Flatten(u);
      EXPECT_LT((Flatten(f) - Ku).norm(), 1e-12 * Ku.norm());
      EXPECT_NEAR(energy, 0.5 * Flatten(u).dot(Ku), 1e-12 * std::abs(energy));
    }
  }
}

// F = R0 S with S symmetric positive definite: the polar rotation is R0.
TEST(RotationOfDeformation, RecoversTheRotationOfAStretch) {
  for (int trial = 0; trial < 50; ++trial) {
    const Mat3 R0 = RandomRotation();
    const Mat3 Q = RandomRotation();
    const Mat3 S = Q * Eigen::Vector3d(0.5, 1.0, 3.0).asDiagonal() * Q.transpose();
    EXPECT_LT((RotationOfDeformation(R0 * S) - R0).norm(), 1e-12);
  }
}

// Inverted, flat and zero deformation gradients still give proper rotations.
TEST(RotationOfDeformation, ProperRotationForInvertedAndDegenerateF) {
  const Mat3 reflection = Eigen::Vector3d(1, 1, -1).asDiagonal();
  const Mat3 flat = Eigen::Vector3d(1, 1, 0).asDiagonal();
  for (const Mat3 &F : {Mat3(RandomRotation() * reflection), Mat3(RandomRotation() * flat),
                        Mat3(Mat3::Zero()), Mat3(-Mat3::Identity())}) {
    const Mat3 R = RotationOfDeformation(F);
    EXPECT_LT((R.transpose() * R - Mat3::Identity()).norm(), 1e-12);
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
  }
  // One mirrored axis: the proper rotation closest to F flips the axis of the
  // smallest singular value (Irving et al. 2004): for diag(3, 2, -1) that is z,
  // which gives the identity.
  const Mat3 F = Eigen::Vector3d(3, 2, -1).asDiagonal();
  EXPECT_LT((RotationOfDeformation(F) - Mat3::Identity()).norm(), 1e-12);
}

// A rigidly rotated and translated tet has no elastic force or energy in the
// corotated element, while the linear element sees a large spurious force.
TEST(CorotatedElement, RigidMotionIsForceFree) {
  for (int trial = 0; trial < 20; ++trial) {
    const TetPositions X = RandomTet();
    const ShapeGradients g = ComputeShapeGradients(X);
    const double V = std::abs(SignedVolume(X));
    const Mat3 R0 = RandomRotation();
    const Eigen::RowVector3d t(0.3, -2.0, 5.0);
    TetPositions x = X * R0.transpose();
    x.rowwise() += t;
    TetPositions force;
    double energy;
    Mat12 K;
    const Mat3 R = CorotatedElement(g, V, kLame, 1.0, x, X, &force, &energy, &K);
    EXPECT_LT((R - R0).norm(), 1e-12);
    const Mat12 K0 = ElementStiffness(g, V, kLame, 1.0);
    const double scale = K0.norm() * Flatten(X).norm();
    EXPECT_LT(Flatten(force).norm(), 1e-12 * scale);
    EXPECT_LT(std::abs(energy), 1e-12 * scale * Flatten(X).norm());
    EXPECT_GT((K0 * (Flatten(x) - Flatten(X))).norm(), 1e-3 * scale);
    for (int a = 0; a < 4; ++a)  // rotated stiffness: blocks R K_ab R^T
      for (int b = 0; b < 4; ++b)
        EXPECT_LT((K.block<3, 3>(3 * a, 3 * b) - R0 * K0.block<3, 3>(3 * a, 3 * b) * R0.transpose())
                      .norm(),
                  1e-12 * K0.norm());
  }
}

// Small deformations: corotated and linear forces agree to the order of the
// strain, and the difference falls linearly with it.
TEST(CorotatedElement, SmallStrainMatchesLinear) {
  const TetPositions X = RandomTet();
  const ShapeGradients g = ComputeShapeGradients(X);
  const double V = std::abs(SignedVolume(X));
  std::normal_distribution<double> n;
  TetPositions direction;
  for (int a = 0; a < 4; ++a)
    for (int c = 0; c < 3; ++c) direction(a, c) = n(rng);
  double previous_ratio = 0;
  for (double eps : {1e-2, 1e-3, 1e-4}) {
    const TetPositions x = X + eps * direction;
    TetPositions force;
    double energy;
    CorotatedElement(g, V, kLame, 1.0, x, X, &force, &energy, nullptr);
    const Vec12 linear = ElementStiffness(g, V, kLame, 1.0) * Flatten(x - X);
    const double ratio = (Flatten(force) - linear).norm() / linear.norm();
    EXPECT_LT(ratio, 100 * eps);
    if (previous_ratio > 0) EXPECT_LT(ratio, 0.2 * previous_ratio);
    previous_ratio = ratio;
  }
}

// An inverted tet (vertex 3 pushed through the face z = 0) is pushed back: the
// physical force -f_3 on that vertex points up, through the face again.
TEST(CorotatedElement, InvertedTetPushesBack) {
  TetPositions X;
  X << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  const ShapeGradients g = ComputeShapeGradients(X);
  const double V = SignedVolume(X);
  TetPositions x = X;
  x(3, 2) = -0.5;
  ASSERT_LT(SignedVolume(x), 0);
  TetPositions force;
  double energy;
  CorotatedElement(g, V, kLame, 1.0, x, X, &force, &energy, nullptr);
  EXPECT_TRUE(force.allFinite());
  EXPECT_LT(force(3, 2), 0);
  EXPECT_GT(energy, 0);
}
