// The space-filling curves of -vertex_order (fem/vertex_order.hpp), against their
// defining properties:
// - Hilbert, orders 1 to 4: the indices of the 8^bits cells are 0 .. 8^bits - 1,
//   each once, and the cells of consecutive indices share a face (the curve never
//   jumps); it starts in the corner cell (0, 0, 0);
// - Morton: the cell (x, y, z) has the index with x's, y's and z's bits interleaved,
//   x most significant, checked on cells written out by hand;
// - CurveOrder: a permutation; the identity in natural order; points in one cell keep
//   their input order; on a shuffled 16^3 lattice the Hilbert order's consecutive
//   points are lattice neighbours (distance one spacing), and the sum of the steps
//   is the 16^3 - 1 spacings of a walk that never jumps.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <numeric>
#include <random>
#include <vector>

#include "fem/vertex_order.hpp"

using namespace softbody;

namespace {

TEST(HilbertIndex, EveryCellOnceAndConsecutiveCellsShareAFace) {
  for (int bits = 1; bits <= 4; ++bits) {
    const uint32_t side = 1u << bits;
    std::vector<std::array<uint32_t, 3>> cell_of_index(side * side * side, {side, side, side});
    for (uint32_t x = 0; x < side; ++x)
      for (uint32_t y = 0; y < side; ++y)
        for (uint32_t z = 0; z < side; ++z) {
          const uint64_t index = HilbertIndex({x, y, z}, bits);
          ASSERT_LT(index, cell_of_index.size()) << "bits " << bits;
          ASSERT_EQ(cell_of_index[index][0], side) << "index " << index << " repeated";
          cell_of_index[index] = {x, y, z};
        }
    EXPECT_EQ(cell_of_index[0], (std::array<uint32_t, 3>{0, 0, 0}));
    for (size_t i = 1; i < cell_of_index.size(); ++i) {
      int steps = 0;
      for (int c = 0; c < 3; ++c)
        steps += std::abs(static_cast<int>(cell_of_index[i][c]) -
                          static_cast<int>(cell_of_index[i - 1][c]));
      EXPECT_EQ(steps, 1) << "bits " << bits << ", indices " << i - 1 << " and " << i;
    }
  }
}

TEST(MortonIndex, InterleavedBits) {
  EXPECT_EQ(MortonIndex({1, 0, 0}, 2), 0b000100u);
  EXPECT_EQ(MortonIndex({0, 1, 0}, 2), 0b000010u);
  EXPECT_EQ(MortonIndex({0, 0, 1}, 2), 0b000001u);
  EXPECT_EQ(MortonIndex({2, 0, 0}, 2), 0b100000u);
  EXPECT_EQ(MortonIndex({3, 2, 1}, 2), 0b110101u);
}

TEST(CurveOrder, APermutationThatWalksALatticeWithoutJumps) {
  constexpr int kSide = 16;
  constexpr double kSpacing = 0.25;
  std::vector<std::array<double, 3>> points;
  for (int x = 0; x < kSide; ++x)
    for (int y = 0; y < kSide; ++y)
      for (int z = 0; z < kSide; ++z) points.push_back({x * kSpacing, y * kSpacing, z * kSpacing});
  std::mt19937 shuffle(7);
  std::shuffle(points.begin(), points.end(), shuffle);
  std::vector<PetscInt> identity(points.size());
  std::iota(identity.begin(), identity.end(), PetscInt(0));
  EXPECT_EQ(CurveOrder(points, VertexOrder::kNatural), identity);
  for (VertexOrder order : {VertexOrder::kHilbert, VertexOrder::kMorton}) {
    std::vector<PetscInt> permutation = CurveOrder(points, order);
    std::vector<PetscInt> sorted = permutation;
    std::sort(sorted.begin(), sorted.end());
    ASSERT_EQ(sorted, identity) << "not a permutation";
    if (order != VertexOrder::kHilbert) continue;
    double walk = 0;
    for (size_t k = 1; k < permutation.size(); ++k) {
      const auto &a = points[permutation[k - 1]], &b = points[permutation[k]];
      const double step = std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);
      EXPECT_NEAR(step, kSpacing, 1e-12) << "step " << k;
      walk += step;
    }
    EXPECT_NEAR(walk, (points.size() - 1) * kSpacing, 1e-9);
  }
}

TEST(CurveOrder, PointsInOneCellKeepTheirOrder) {
  const std::vector<std::array<double, 3>> points = {
      {1, 1, 1}, {0, 0, 0}, {1, 1, 1}, {0, 0, 0}, {1, 1, 1}};
  EXPECT_EQ(CurveOrder(points, VertexOrder::kHilbert), (std::vector<PetscInt>{1, 3, 0, 2, 4}));
  EXPECT_EQ(CurveOrder({{2, 3, 4}}, VertexOrder::kHilbert), (std::vector<PetscInt>{0}));
}

}  // namespace
