// Unit tests of the linear tetrahedral element kernels (src/fem/element.hpp), each
// compared against something computed independently: closed formulas, the
// literal V B^T C B, rigid-body modes, an affine patch and finite differences.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "fem/element.hpp"

namespace softbody {
namespace {

constexpr double kShearScales[] = {1.0, 0.5, 0.25};

// Random tets in [-1, 1]^3 of both orientations, none flatter than |V| = 0.01 L^3.
std::vector<TetPositions> RandomTets(int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> coordinate(-1.0, 1.0);
  std::vector<TetPositions> tets;
  while (static_cast<int>(tets.size()) < count) {
    TetPositions X;
    for (int a = 0; a < 4; ++a)
      for (int c = 0; c < 3; ++c) X(a, c) = coordinate(rng);
    const double length = LongestEdge(X);
    if (std::abs(SignedVolume(X)) > 0.01 * length * length * length) tets.push_back(X);
  }
  return tets;
}

// Stiffness of one tet as the assembly forms it: volume passed as |V|.
Mat12 StiffnessOf(const TetPositions &X, const Lame &lame, double shear_scale) {
  return ElementStiffness(ComputeShapeGradients(X), std::abs(SignedVolume(X)), lame, shear_scale);
}

// Element vector of the vertex displacements u_a = G X_a + c.
Vec12 AffineDisplacement(const TetPositions &X, const Mat3 &G, const Vec3 &c) {
  Vec12 u;
  for (int a = 0; a < 4; ++a) u.segment<3>(3 * a) = G * X.row(a).transpose() + c;
  return u;
}

// Strain energy density of the displacement gradient G, written out by hand from
// the engineering strain and the isotropic C of element.hpp:
//   W = l/2 tr(e)^2 + m (exx^2 + eyy^2 + ezz^2) + s m/2 (gxy^2 + gyz^2 + gzx^2).
double EnergyDensity(const Mat3 &G, const Lame &lame, double shear_scale) {
  const double exx = G(0, 0), eyy = G(1, 1), ezz = G(2, 2);
  const double gxy = G(0, 1) + G(1, 0), gyz = G(1, 2) + G(2, 1), gzx = G(2, 0) + G(0, 2);
  const double trace = exx + eyy + ezz;
  return 0.5 * lame.lambda * trace * trace + lame.mu * (exx * exx + eyy * eyy + ezz * ezz) +
         0.5 * shear_scale * lame.mu * (gxy * gxy + gyz * gyz + gzx * gzx);
}

Mat3 RandomMatrix(std::mt19937 &rng) {
  std::uniform_real_distribution<double> entry(-1.0, 1.0);
  Mat3 G;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) G(i, j) = entry(rng);
  return G;
}

// The six rigid-body modes of a tet: 3 translations and 3 infinitesimal
// rotations about the centroid, u_a = w x (X_a - centroid).
std::array<Vec12, 6> RigidBodyModes(const TetPositions &X) {
  const Vec3 centroid = X.colwise().mean().transpose();
  std::array<Vec12, 6> modes;
  for (int k = 0; k < 3; ++k) {
    Vec12 translation, rotation;
    for (int a = 0; a < 4; ++a) {
      translation.segment<3>(3 * a) = Vec3::Unit(k);
      rotation.segment<3>(3 * a) = Vec3::Unit(k).cross(X.row(a).transpose() - centroid);
    }
    modes[k] = translation;
    modes[3 + k] = rotation;
  }
  return modes;
}

TEST(LameFromYoungPoisson, MatchesClosedFormulas) {
  // E = 1e6, nu = 0.3: l = 0.3e6 / (1.3 * 0.4) = 7.5e6 / 13, m = 1e6 / 2.6 = 5e6 / 13.
  const Lame steel_like = LameFromYoungPoisson(1e6, 0.3);
  EXPECT_NEAR(steel_like.lambda, 7.5e6 / 13.0, 1e-9 * 7.5e6 / 13.0);
  EXPECT_NEAR(steel_like.mu, 5e6 / 13.0, 1e-9 * 5e6 / 13.0);
  // E = 2e5, nu = 0.25: l = m = E / 2.5 = 8e4.
  const Lame equal = LameFromYoungPoisson(2e5, 0.25);
  EXPECT_NEAR(equal.lambda, 8e4, 1e-9 * 8e4);
  EXPECT_NEAR(equal.mu, 8e4, 1e-9 * 8e4);
  // nu = 0: no lateral coupling, l = 0 and m = E / 2.
  const Lame uncoupled = LameFromYoungPoisson(3e4, 0.0);
  EXPECT_EQ(uncoupled.lambda, 0.0);
  EXPECT_NEAR(uncoupled.mu, 1.5e4, 1e-9 * 1.5e4);
}

TEST(LameFromYoungPoisson, InvertsToYoungAndPoisson) {
  // The inverse relations E = m (3l + 2m) / (l + m), nu = l / (2 (l + m)) recover
  // the inputs, including a negative Poisson ratio and one close to 0.5.
  for (const double young : {1e3, 2.5e7})
    for (const double poisson : {-0.4, 0.1, 0.3, 0.45, 0.499}) {
      const Lame lame = LameFromYoungPoisson(young, poisson);
      const double l = lame.lambda, m = lame.mu;
      EXPECT_NEAR(m * (3 * l + 2 * m) / (l + m), young, 1e-10 * young);
      EXPECT_NEAR(l / (2 * (l + m)), poisson, 1e-10);
    }
}

TEST(SignedVolume, SignConventionAndValue) {
  TetPositions reference;
  reference << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  EXPECT_NEAR(SignedVolume(reference), 1.0 / 6.0, 1e-15);
  TetPositions swapped = reference;
  swapped.row(1).swap(swapped.row(2));
  EXPECT_NEAR(SignedVolume(swapped), -1.0 / 6.0, 1e-15);
  // Against the triple product (X1 - X0) . ((X2 - X0) x (X3 - X0)) / 6.
  for (const TetPositions &X : RandomTets(20, 7)) {
    const Vec3 e1 = (X.row(1) - X.row(0)).transpose(), e2 = (X.row(2) - X.row(0)).transpose(),
               e3 = (X.row(3) - X.row(0)).transpose();
    const double triple = e1.dot(e2.cross(e3)) / 6.0;
    EXPECT_NEAR(SignedVolume(X), triple, 1e-14);
  }
}

TEST(LongestEdge, OfAnAxisAlignedTet) {
  TetPositions X;
  X << 0, 0, 0, 3, 0, 0, 0, 4, 0, 0, 0, 1;
  EXPECT_NEAR(LongestEdge(X), 5.0, 1e-15);  // the edge from (3, 0, 0) to (0, 4, 0)
}

TEST(LumpedVertexMass, IsAQuarterOfTheTetMass) {
  TetPositions X;
  X << 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, 4;  // V = 2 * 3 * 4 / 6 = 4 m^3
  EXPECT_NEAR(LumpedVertexMass(1000.0, std::abs(SignedVolume(X))), 1000.0 * 4.0 / 4.0, 1e-10);
  EXPECT_NEAR(LumpedVertexMass(7.5, 0.2), 0.375, 1e-15);
}

TEST(ShapeGradients, PartitionOfUnityAndLinearReproduction) {
  // sum_i grad N_i = 0 (the N_i sum to one) and sum_i X_i grad N_i^T = I (they
  // reproduce the linear function X exactly); relative to 1/L and 1.
  for (const TetPositions &X : RandomTets(50, 11)) {
    const ShapeGradients grad = ComputeShapeGradients(X);
    const double scale = grad.norm();
    EXPECT_LT(grad.colwise().sum().norm(), 1e-13 * scale);
    Mat3 reproduced = Mat3::Zero();
    for (int i = 0; i < 4; ++i) reproduced += X.row(i).transpose() * grad.row(i);
    EXPECT_LT((reproduced - Mat3::Identity()).norm(), 1e-12);
  }
}

TEST(ShapeGradients, ReferenceTet) {
  TetPositions X;
  X << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  ShapeGradients expected;
  expected << -1, -1, -1, 1, 0, 0, 0, 1, 0, 0, 0, 1;  // N_0 = 1 - x - y - z, N_i = x_i
  EXPECT_LT((ComputeShapeGradients(X) - expected).norm(), 1e-15);
}

TEST(ElementStiffness, EqualsLiteralBtCB) {
  // The block-wise formula against the literal V B^T C B, relative 1e-12.
  for (const double shear_scale : kShearScales)
    for (const double poisson : {-0.3, 0.2, 0.45}) {
      const Lame lame = LameFromYoungPoisson(1e5, poisson);
      for (const TetPositions &X : RandomTets(30, 13)) {
        const ShapeGradients grad = ComputeShapeGradients(X);
        const double volume = std::abs(SignedVolume(X));
        const Mat12 K = ElementStiffness(grad, volume, lame, shear_scale);
        const Mat12 K_reference = ElementStiffnessReference(grad, volume, lame, shear_scale);
        EXPECT_LE((K - K_reference).norm(), 1e-12 * K_reference.norm())
            << "shear scale " << shear_scale << ", nu " << poisson;
      }
    }
}

TEST(ElementStiffness, IsSymmetric) {
  const Lame lame = LameFromYoungPoisson(1e5, 0.3);
  for (const double shear_scale : kShearScales)
    for (const TetPositions &X : RandomTets(30, 17)) {
      const Mat12 K = StiffnessOf(X, lame, shear_scale);
      EXPECT_LE((K - K.transpose()).norm(), 1e-14 * K.norm());
    }
}

TEST(ElementStiffness, RigidBodyModesInNullSpace) {
  // |K r| / (|K| |r|) < 1e-12 for the 3 translations and 3 rotations.
  for (const double shear_scale : kShearScales) {
    const Lame lame = LameFromYoungPoisson(1e5, 0.35);
    for (const TetPositions &X : RandomTets(30, 19)) {
      const Mat12 K = StiffnessOf(X, lame, shear_scale);
      for (const Vec12 &mode : RigidBodyModes(X))
        EXPECT_LT((K * mode).norm() / (K.norm() * mode.norm()), 1e-12);
    }
  }
}

TEST(ElementStiffness, PositiveSemiDefiniteWithSixZeroEigenvalues) {
  // For nu in (0, 0.5) and s = 1, C is positive definite, so K has exactly the six
  // rigid-body modes as its null space: six eigenvalues below 1e-12 of the largest,
  // none negative beyond that, the other six clearly positive.
  for (const double poisson : {0.05, 0.25, 0.4, 0.49}) {
    const Lame lame = LameFromYoungPoisson(1e5, poisson);
    for (const TetPositions &X : RandomTets(30, 23)) {
      const Eigen::SelfAdjointEigenSolver<Mat12> eigen(StiffnessOf(X, lame, 1.0));
      ASSERT_EQ(eigen.info(), Eigen::Success);
      const auto &values = eigen.eigenvalues();  // ascending
      const double largest = values[11];
      ASSERT_GT(largest, 0.0);
      int zeros = 0;
      for (int k = 0; k < 12; ++k) {
        EXPECT_GT(values[k], -1e-12 * largest) << "nu " << poisson;
        if (std::abs(values[k]) < 1e-12 * largest) ++zeros;
      }
      EXPECT_EQ(zeros, 6) << "nu " << poisson;
      EXPECT_GT(values[6], 1e-6 * largest) << "nu " << poisson;
    }
  }
}

TEST(ElementStiffness, AffinePatchOnOneTet) {
  // u(X) = G X + c: the strain from the shape gradients is constant and equals the
  // engineering strain of G, and u^T K u / 2 equals V W(G) computed by hand.
  std::mt19937 rng(29);
  for (const double shear_scale : kShearScales) {
    const Lame lame = LameFromYoungPoisson(2e4, 0.3);
    for (const TetPositions &X : RandomTets(20, 31)) {
      const Mat3 G = RandomMatrix(rng);
      const Vec3 c(0.3, -0.7, 1.1);
      const Vec12 u = AffineDisplacement(X, G, c);
      const ShapeGradients grad = ComputeShapeGradients(X);
      Mat3 displacement_gradient = Mat3::Zero();  // sum_a u_a grad N_a^T
      for (int a = 0; a < 4; ++a) displacement_gradient += u.segment<3>(3 * a) * grad.row(a);
      EXPECT_LT((displacement_gradient - G).norm(), 1e-12 * G.norm());
      const Mat3 strain = 0.5 * (displacement_gradient + displacement_gradient.transpose());
      const Mat3 strain_of_G = 0.5 * (G + G.transpose());
      EXPECT_LT((strain - strain_of_G).norm(), 1e-12 * G.norm());

      const double volume = std::abs(SignedVolume(X));
      const double energy = 0.5 * u.dot(ElementStiffness(grad, volume, lame, shear_scale) * u);
      const double expected = volume * EnergyDensity(G, lame, shear_scale);
      EXPECT_NEAR(energy, expected, 1e-11 * expected) << "shear scale " << shear_scale;
    }
  }
}

// A 2 x 2 x 2 block of unit cubes, each split into the 6 tets around its main
// diagonal (consistent across faces); the centre vertex (1, 1, 1), index 13, is the
// only interior vertex and is moved off the grid so the patch is irregular.
struct Patch {
  std::vector<Vec3> vertices;
  std::vector<std::array<int, 4>> tets;
};

Patch CubeBlockPatch() {
  Patch patch;
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i) patch.vertices.emplace_back(i, j, k);
  patch.vertices[13] = Vec3(1.13, 0.91, 1.07);
  const auto index = [](int i, int j, int k) { return i + 3 * j + 9 * k; };
  const int permutations[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i)
        for (const auto &p : permutations) {
          std::array<int, 3> corner = {i, j, k};
          std::array<int, 4> tet;
          tet[0] = index(corner[0], corner[1], corner[2]);
          for (int step = 0; step < 3; ++step) {
            ++corner[p[step]];
            tet[step + 1] = index(corner[0], corner[1], corner[2]);
          }
          patch.tets.push_back(tet);
        }
  return patch;
}

TEST(ElementStiffness, AffinePatchOnAssembledCubeBlock) {
  // Assembled K of the irregular patch under u = G X + c: the internal force at the
  // interior vertex and the total force vanish, and the energy equals the total
  // volume (8 m^3) times the energy density W(G).
  const Patch patch = CubeBlockPatch();
  const int num_dofs = 3 * static_cast<int>(patch.vertices.size());
  std::mt19937 rng(37);
  for (const double shear_scale : kShearScales) {
    const Lame lame = LameFromYoungPoisson(1e4, 0.3);
    Eigen::MatrixXd K = Eigen::MatrixXd::Zero(num_dofs, num_dofs);
    double total_volume = 0;
    for (const auto &tet : patch.tets) {
      TetPositions X;
      for (int a = 0; a < 4; ++a) X.row(a) = patch.vertices[tet[a]].transpose();
      const double volume = std::abs(SignedVolume(X));
      ASSERT_GT(volume, 0.05);
      total_volume += volume;
      const Mat12 K_e = ElementStiffness(ComputeShapeGradients(X), volume, lame, shear_scale);
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
          K.block<3, 3>(3 * tet[a], 3 * tet[b]) += K_e.block<3, 3>(3 * a, 3 * b);
    }
    EXPECT_NEAR(total_volume, 8.0, 1e-12);

    const Mat3 G = RandomMatrix(rng);
    const Vec3 c(-0.2, 0.5, 0.9);
    Eigen::VectorXd u(num_dofs);
    for (size_t v = 0; v < patch.vertices.size(); ++v)
      u.segment<3>(3 * v) = G * patch.vertices[v] + c;
    const Eigen::VectorXd force = -K * u;
    const double force_scale = K.norm() * u.norm();
    EXPECT_LT(force.segment<3>(3 * 13).norm(), 1e-12 * force_scale);
    Vec3 total_force = Vec3::Zero();
    for (size_t v = 0; v < patch.vertices.size(); ++v) total_force += force.segment<3>(3 * v);
    EXPECT_LT(total_force.norm(), 1e-12 * force_scale);
    const double energy = 0.5 * u.dot(K * u);
    const double expected = total_volume * EnergyDensity(G, lame, shear_scale);
    EXPECT_NEAR(energy, expected, 1e-11 * expected) << "shear scale " << shear_scale;
  }
}

TEST(ElementStiffness, ForceIsMinusEnergyGradient) {
  // f = -K u against minus the central-difference gradient of E(u) = u^T K u / 2.
  std::mt19937 rng(41);
  std::uniform_real_distribution<double> entry(-0.1, 0.1);
  const double h = 1e-5;
  for (const double shear_scale : kShearScales) {
    const Lame lame = LameFromYoungPoisson(5e4, 0.4);
    for (const TetPositions &X : RandomTets(10, 43)) {
      const Mat12 K = StiffnessOf(X, lame, shear_scale);
      const auto energy = [&K](const Vec12 &u) { return 0.5 * u.dot(K * u); };
      Vec12 u;
      for (int k = 0; k < 12; ++k) u[k] = entry(rng);
      const Vec12 force = -K * u;
      Vec12 finite_difference;
      for (int k = 0; k < 12; ++k) {
        Vec12 plus = u, minus = u;
        plus[k] += h;
        minus[k] -= h;
        finite_difference[k] = -(energy(plus) - energy(minus)) / (2 * h);
      }
      EXPECT_LE((force - finite_difference).norm(), 1e-6 * force.norm());
    }
  }
}

}  // namespace
}  // namespace softbody
