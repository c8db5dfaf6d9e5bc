#include "fem/vertex_order.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace softbody {

const char *const kVertexOrderNames[] = {"natural",     "hilbert", "morton",
                                         "VertexOrder", "",        nullptr};

namespace {

// The transposed coordinates' bits interleaved into one index, the first
// coordinate's bit first at each level, most significant level first.
uint64_t Interleave(const std::array<uint32_t, 3> &x, int bits) {
  uint64_t index = 0;
  for (int b = bits - 1; b >= 0; --b)
    for (int i = 0; i < 3; ++i) index = (index << 1) | ((x[i] >> b) & 1u);
  return index;
}

}  // namespace

uint64_t HilbertIndex(std::array<uint32_t, 3> x, int bits) {
  // Skilling's AxestoTranspose: undo the curve's rotations and reflections level
  // by level, then Gray-encode; the result is the index in transposed form.
  const uint32_t top = 1u << (bits - 1);
  for (uint32_t q = top; q > 1; q >>= 1) {
    const uint32_t below = q - 1;
    for (int i = 0; i < 3; ++i) {
      if (x[i] & q) {
        x[0] ^= below;  // invert
      } else {
        const uint32_t swap = (x[0] ^ x[i]) & below;  // exchange
        x[0] ^= swap;
        x[i] ^= swap;
      }
    }
  }
  for (int i = 1; i < 3; ++i) x[i] ^= x[i - 1];
  uint32_t flip = 0;
  for (uint32_t q = top; q > 1; q >>= 1)
    if (x[2] & q) flip ^= q - 1;
  for (int i = 0; i < 3; ++i) x[i] ^= flip;
  return Interleave(x, bits);
}

uint64_t MortonIndex(const std::array<uint32_t, 3> &cell, int bits) {
  return Interleave(cell, bits);
}

std::vector<PetscInt> CurveOrder(const std::vector<std::array<double, 3>> &points,
                                 VertexOrder order) {
  std::vector<PetscInt> permutation(points.size());
  std::iota(permutation.begin(), permutation.end(), PetscInt(0));
  if (order == VertexOrder::kNatural || points.empty()) return permutation;
  std::array<double, 3> lo, hi;
  lo.fill(std::numeric_limits<double>::infinity());
  hi.fill(-std::numeric_limits<double>::infinity());
  for (const auto &p : points)
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], p[c]);
      hi[c] = std::max(hi[c], p[c]);
    }
  // One scale on every axis: the curve runs through the bounding cube.
  const double side = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  const uint32_t last_cell = (1u << kCurveBits) - 1;
  const double cells_per_metre = side > 0 ? last_cell / side : 0;
  std::vector<uint64_t> key(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    std::array<uint32_t, 3> cell;
    for (int c = 0; c < 3; ++c)
      cell[c] = std::min(
          last_cell, static_cast<uint32_t>(std::floor((points[i][c] - lo[c]) * cells_per_metre)));
    key[i] = order == VertexOrder::kHilbert ? HilbertIndex(cell, kCurveBits)
                                            : MortonIndex(cell, kCurveBits);
  }
  std::stable_sort(permutation.begin(), permutation.end(),
                   [&key](PetscInt a, PetscInt b) { return key[a] < key[b]; });
  return permutation;
}

}  // namespace softbody
