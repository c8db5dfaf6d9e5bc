// Geometric queries for contact: point-in-tet, closest point on a triangle, a
// segment crossing a triangle, a mesh's boundary edges, and a uniform grid that
// bins boxes for fast candidate look-up. Lengths in metres. Not collective.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <utility>
#include <vector>

#include "fem/mesh.hpp"

namespace softbody {

using Point = Eigen::Vector3d;

// Stands for infinity in boxes and nearest-point searches: larger than any
// coordinate or distance of a scene, yet finite, so that sums and differences
// with it stay finite.
constexpr double kUnbounded = 1e300;

// Axis-aligned box; the default one is empty (lower above upper).
struct Box {
  Point lower = Point::Constant(kUnbounded), upper = Point::Constant(-kUnbounded);
  void Extend(const Point &p) {
    lower = lower.cwiseMin(p);
    upper = upper.cwiseMax(p);
  }
  void Extend(const Box &b) {
    lower = lower.cwiseMin(b.lower);
    upper = upper.cwiseMax(b.upper);
  }
  bool Contains(const Point &p, double margin = 0) const {
    return (p.array() >= lower.array() - margin).all() &&
           (p.array() <= upper.array() + margin).all();
  }
  bool Empty() const { return (lower.array() > upper.array()).any(); }
  bool Overlaps(const Box &b) const {
    return (lower.array() <= b.upper.array()).all() && (b.lower.array() <= upper.array()).all();
  }
};

// Barycentric coordinates of p in the tet (a, b, c, d); p is inside (or on the
// boundary, up to -tolerance) when all four are >= -tolerance.
Eigen::Vector4d Barycentric(const Point &p, const Point &a, const Point &b, const Point &c,
                            const Point &d);

// A point counts as inside a tet when all its barycentric coordinates are at
// least -kInsideTolerance: faces count (a point on a face shared by two tets is
// in both), round-off does not decide.
constexpr double kInsideTolerance = 1e-12;
// Margin (m) of the cheap box rejection before a barycentric test, so that the
// box never rejects a point the test would accept.
constexpr double kBoxMargin = 1e-12;

// Whether the tet (a, b, c, d), whose box is `box`, holds p (faces included,
// kInsideTolerance).
inline bool TetHolds(const Point &p, const Box &box, const Point &a, const Point &b, const Point &c,
                     const Point &d) {
  return box.Contains(p, kBoxMargin) && Barycentric(p, a, b, c, d).minCoeff() >= -kInsideTolerance;
}

// Closest point to p on the triangle (a, b, c) (Ericson, Real-Time Collision
// Detection, 5.1.5); also its barycentric coordinates.
Point ClosestPointOnTriangle(const Point &p, const Point &a, const Point &b, const Point &c,
                             Eigen::Vector3d *weights);

// Where the segment p -> q crosses the triangle (a, b, c) (Moeller & Trumbore
// 1997): *t in [0, 1] the fraction of the segment and *weights the barycentric
// coordinates of the crossing. False when it misses or runs parallel to the plane.
bool SegmentCrossesTriangle(const Point &p, const Point &q, const Point &a, const Point &b,
                            const Point &c, double *t, Eigen::Vector3d *weights);

// Edges of the boundary triangles of a mesh, each once, as (smaller, larger)
// local vertex index, sorted.
std::vector<std::pair<int32_t, int32_t>> BoundaryEdges(const TetMesh &mesh);
// The same from the mesh's boundary triangles (#B x 3 vertex indices).
std::vector<std::pair<int32_t, int32_t>> BoundaryEdges(
    const Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor> &triangles);

// Uniform grid over the boxes of a set of items (tets or triangles): each item is
// listed in every cell its box overlaps. Cell size h: the mean box edge, so an
// item overlaps a few cells, grown until the grid has at most about two cells
// per item (point-like items, surfaces: geometry.cpp, kMaxCellsPerItem).
class UniformGrid {
 public:
  void Build(const std::vector<Box> &boxes);
  bool empty() const { return item_start_.empty(); }
  // Items whose cells overlap the box around p of half-width radius (each once
  // per cell: callers may see an item more than once).
  template <typename Visit>
  void ForEachNear(const Point &p, double radius, Visit visit) const {
    if (empty() || !bounds_.Contains(p, radius)) return;
    const Eigen::Array3i lo = CellOf(p.array() - radius), hi = CellOf(p.array() + radius);
    for (int k = lo[2]; k <= hi[2]; ++k)
      for (int j = lo[1]; j <= hi[1]; ++j)
        for (int i = lo[0]; i <= hi[0]; ++i) {
          const int64_t cell = Index(i, j, k);
          for (int64_t n = cell_start_[cell]; n < cell_start_[cell + 1]; ++n) visit(items_[n]);
        }
  }
  // Items whose cells overlap the box (each once per cell, as ForEachNear).
  template <typename Visit>
  void ForEachInBox(const Box &box, Visit visit) const {
    if (empty() || !bounds_.Overlaps(box)) return;
    const Eigen::Array3i lo = CellOf(box.lower.array()), hi = CellOf(box.upper.array());
    for (int k = lo[2]; k <= hi[2]; ++k)
      for (int j = lo[1]; j <= hi[1]; ++j)
        for (int i = lo[0]; i <= hi[0]; ++i) {
          const int64_t cell = Index(i, j, k);
          for (int64_t n = cell_start_[cell]; n < cell_start_[cell + 1]; ++n) visit(items_[n]);
        }
  }
  double cell_size() const { return h_; }
  const Box &bounds() const { return bounds_; }

 private:
  // Inline: the grids' inner loops call them for every box (a call each cost
  // 13 % of a guard-bound run).
  Eigen::Array3i CellOf(const Eigen::Array3d &p) const {
    const Eigen::Array3d relative = (p - bounds_.lower.array()) / h_;
    return relative.floor().max(-1.0).min(cells_.cast<double>()).cast<int>().max(0).min(cells_ - 1);
  }
  int64_t Index(int i, int j, int k) const {
    return i + static_cast<int64_t>(cells_[0]) * (j + static_cast<int64_t>(cells_[1]) * k);
  }

  Box bounds_;
  double h_ = 1;
  Eigen::Array3i cells_ = Eigen::Array3i::Zero();
  std::vector<int64_t> cell_start_;  // CSR over cells
  std::vector<int32_t> items_;
  std::vector<int32_t> item_start_;  // non-empty: the grid holds items
};

}  // namespace softbody
