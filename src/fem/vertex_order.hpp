// Orders of a rank's vertices for cache locality (-vertex_order).
//
// Meshes as users bring them (TetGen's, for one) list vertices and tets in an
// order unrelated to space: the neighbours of a vertex are scattered over the
// whole vertex list, so every element loop and every matrix row jumps through
// memory. Each rank therefore renumbers the vertices it owns along a
// space-filling curve through their rest positions (partition.hpp), inside its
// own block of PETSc vertices, and sorts its tets by their vertices
// (migration.hpp). Only the PETSc numbering changes: the output, checkpoints and
// every natural-order lookup go through natural_of_owned. The choice and its
// measured effect are in docs/performance.md ("Locality").
#pragma once

#include <petscsys.h>

#include <array>
#include <cstdint>
#include <vector>

namespace softbody {

enum class VertexOrder {
  kNatural,  // the scene's natural order inside each rank's part
  kHilbert,  // the Hilbert curve through the rest positions inside each rank's part
  kMorton,   // the Morton (Z-order) curve through the rest positions
};

// Names as -vertex_order spells them, in enum order, then PETSc's enum-list tail.
extern const char *const kVertexOrderNames[];

// Bits per coordinate of the curves' keys: 3 x 21 = 63 bits fill one 64-bit key,
// a grid of 2^21 cells per side (a 1 m body into cells of 0.5 um, far below any
// tet's size, so distinct vertices rarely share a cell; ties keep their order).
constexpr int kCurveBits = 21;

// Not collective. The index of grid cell `cell` (each coordinate in [0, 2^bits))
// along the 3D Hilbert curve of order `bits` (Skilling, "Programming the Hilbert
// curve", AIP Conf. Proc. 707, 2004): consecutive indices are face-adjacent cells.
// 1 <= bits <= kCurveBits.
uint64_t HilbertIndex(std::array<uint32_t, 3> cell, int bits);

// Not collective. The index of `cell` along the Morton (Z-order) curve: the
// coordinates' bits interleaved, x most significant. 1 <= bits <= kCurveBits.
uint64_t MortonIndex(const std::array<uint32_t, 3> &cell, int bits);

// Not collective. The permutation that lists `points` (m) along the curve of
// `order` through their bounding cube: result[k] is the index of the k-th point.
// Points in one cell keep their input order; kNatural gives the identity.
std::vector<PetscInt> CurveOrder(const std::vector<std::array<double, 3>> &points,
                                 VertexOrder order);

}  // namespace softbody
