// RotationOfDeformation (element.hpp): the Newton iteration that serves nearly
// every tet, one or four at a time, agrees with the SVD-based rotation (Irving
// et al.'s flip included) on random, stretched, near-singular and inverted
// deformation gradients, and is faster (timing printed, not asserted).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <chrono>
#include <random>

#include "fem/element.hpp"

using namespace softbody;

namespace {

std::mt19937 rng(11);

Mat3 RandomRotation() {
  std::normal_distribution<double> n;
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  return q.normalized().toRotationMatrix();
}

// F = U diag(s) V^T with random rotations U, V.
Mat3 WithSingularValues(double s0, double s1, double s2) {
  return RandomRotation() * Eigen::Vector3d(s0, s1, s2).asDiagonal() * RandomRotation().transpose();
}

void ExpectProperRotation(const Mat3 &R) {
  EXPECT_LT((R.transpose() * R - Mat3::Identity()).norm(), 1e-13);
  EXPECT_NEAR(R.determinant(), 1.0, 1e-13);
}

}  // namespace

// Random F with independent normal entries (either sign of det F).
TEST(RotationOfDeformation, AgreesWithSvdOnRandomF) {
  std::normal_distribution<double> n;
  int newton = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    Mat3 F;
    for (int i = 0; i < 9; ++i) F.data()[i] = n(rng);
    const Mat3 R = RotationOfDeformation(F), reference = RotationOfDeformationSvd(F);
    ExpectProperRotation(R);
    // The rotation's sensitivity to F is 1 / (s1 + s2) (the two smallest).
    const Eigen::Vector3d s = Eigen::JacobiSVD<Mat3>(F).singularValues();
    EXPECT_LT((R - reference).norm(), 1e-13 * F.norm() / (s[1] + s[2])) << F;
    Mat3 unused;
    newton += RotationOfDeformationNewton(F, &unused);
  }
  // About half have det F > 0, most of those are well conditioned.
  EXPECT_GT(newton, 6000);
}

// Rotations, small and large stretches: always the Newton path, equal to the SVD.
TEST(RotationOfDeformation, NewtonAgreesWithSvdOnStretches) {
  std::uniform_real_distribution<double> u(-1, 1);
  for (double scale : {0.0, 1e-8, 1e-4, 1e-2, 0.1, 0.5, 0.9}) {
    for (int trial = 0; trial < 500; ++trial) {
      const Mat3 F = WithSingularValues(1 + scale * u(rng), 1 + scale * u(rng), 1 + scale * u(rng));
      Mat3 R;
      ASSERT_TRUE(RotationOfDeformationNewton(F, &R)) << F;
      ExpectProperRotation(R);
      EXPECT_LT((R - RotationOfDeformationSvd(F)).norm(), 1e-13) << "scale " << scale;
    }
  }
  // Large, anisotropic stretches (condition numbers up to 100).
  for (int trial = 0; trial < 500; ++trial) {
    std::uniform_real_distribution<double> log_s(-1, 1);
    const Mat3 F = WithSingularValues(std::pow(10, log_s(rng)), std::pow(10, log_s(rng)),
                                      std::pow(10, log_s(rng)));
    const Mat3 R = RotationOfDeformation(F);
    ExpectProperRotation(R);
    EXPECT_LT((R - RotationOfDeformationSvd(F)).norm(), 1e-12);
  }
}

// Nearly singular F with det F > 0: the Newton iteration refuses below its
// conditioning bound and the SVD takes over; either way the result is the SVD's.
TEST(RotationOfDeformation, NearlySingular) {
  for (double smallest : {1e-2, 1e-3, 1e-4, 1e-6, 1e-10, 1e-14}) {
    for (int trial = 0; trial < 200; ++trial) {
      const Mat3 F = WithSingularValues(1.3, 0.8, smallest);
      const Mat3 R = RotationOfDeformation(F);
      ExpectProperRotation(R);
      EXPECT_LT((R - RotationOfDeformationSvd(F)).norm(), 1e-12) << "smallest " << smallest;
    }
  }
  Mat3 unused;
  EXPECT_FALSE(RotationOfDeformationNewton(WithSingularValues(1.0, 1.0, 1e-6), &unused));
  EXPECT_FALSE(RotationOfDeformationNewton(Mat3::Zero(), &unused));
}

// Inverted F (det F < 0, e.g. a tet pushed through itself): Irving's flip of
// the smallest singular direction, as the SVD gives it.
TEST(RotationOfDeformation, InvertedFlipsTheSmallestSingularDirection) {
  for (double smallest : {0.9, 0.5, 0.1, 1e-3, 1e-8}) {
    for (int trial = 0; trial < 200; ++trial) {
      const Mat3 F = WithSingularValues(1.2, 1.0, -smallest);
      Mat3 unused;
      EXPECT_FALSE(RotationOfDeformationNewton(F, &unused));
      const Mat3 R = RotationOfDeformation(F);
      ExpectProperRotation(R);
      EXPECT_LT((R - RotationOfDeformationSvd(F)).norm(), 1e-12);
      // The closest proper rotation: R^T F is symmetric with trace s0 + s1 - s2.
      const Mat3 S = R.transpose() * F;
      EXPECT_LT((S - S.transpose()).norm(), 1e-12);
      EXPECT_NEAR(S.trace(), 1.2 + 1.0 - smallest, 1e-12);
    }
  }
}

// Non-finite input goes to the SVD (as before) instead of looping.
TEST(RotationOfDeformation, NonFiniteInputTakesTheSvdPath) {
  Mat3 F = Mat3::Identity();
  F(0, 1) = std::numeric_limits<double>::quiet_NaN();
  Mat3 unused;
  EXPECT_FALSE(RotationOfDeformationNewton(F, &unused));
}

// Four at a time: the same rotations as one at a time, whatever mix of nearly
// orthogonal, stretched, inverted and singular F shares the four lanes.
TEST(RotationOfDeformation4, EqualsOneAtATime) {
  std::uniform_real_distribution<double> u(-1, 1);
  const auto kind = [&](int k) -> Mat3 {
    switch (k % 5) {
      case 0:
        return WithSingularValues(1 + 0.01 * u(rng), 1 + 0.01 * u(rng), 1 + 0.01 * u(rng));
      case 1:
        return WithSingularValues(1 + 0.09 * u(rng), 1 + 0.05 * u(rng), 1 - 0.05 * u(rng));
      case 2:
        return WithSingularValues(3.0, 0.5, 0.2);
      case 3:
        return WithSingularValues(1.0, 1.0, -0.9);
      default:
        return WithSingularValues(1.0, 1e-9, 0.0);
    }
  };
  for (int trial = 0; trial < 2000; ++trial) {
    Mat3 F[4], R[4];
    for (int l = 0; l < 4; ++l) F[l] = kind(trial / 7 + 3 * l + (trial % 5) * l);
    RotationOfDeformation4(F, R);
    for (int l = 0; l < 4; ++l) {
      ExpectProperRotation(R[l]);
      EXPECT_LT((R[l] - RotationOfDeformationSvd(F[l])).norm(), 1e-12) << F[l];
    }
  }
}

// Typical simulation input (strains of about 1 %): Newton against JacobiSVD.
TEST(RotationOfDeformation, Speed) {
  std::vector<Mat3> samples;
  std::uniform_real_distribution<double> u(-0.01, 0.01);
  for (int i = 0; i < 20000; ++i)
    samples.push_back(WithSingularValues(1 + u(rng), 1 + u(rng), 1 + u(rng)));
  auto time = [&](auto &&rotation) {
    Mat3 sum = Mat3::Zero();
    const auto start = std::chrono::steady_clock::now();
    for (const Mat3 &F : samples) sum += rotation(F);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_TRUE(sum.allFinite());
    return 1e9 * seconds / samples.size();
  };
  const double newton = time([](const Mat3 &F) { return RotationOfDeformation(F); });
  double batched;
  {
    std::vector<Mat3> rotations(samples.size());
    const auto start = std::chrono::steady_clock::now();
    for (size_t i = 0; i + 4 <= samples.size(); i += 4)
      RotationOfDeformation4(&samples[i], &rotations[i]);
    batched = 1e9 *
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() /
              samples.size();
    for (size_t i = 0; i < samples.size(); i += 997)
      EXPECT_LT((rotations[i] - RotationOfDeformationSvd(samples[i])).norm(), 1e-12);
  }
  const double svd = time([](const Mat3 &F) { return RotationOfDeformationSvd(F); });
  std::printf(
      "rotation of F: Newton %.0f ns, four at a time %.0f ns each, JacobiSVD %.0f ns (x %.1f)\n",
      newton, batched, svd, svd / newton);
}
