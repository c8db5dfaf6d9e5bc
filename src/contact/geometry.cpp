#include "contact/geometry.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace softbody {

namespace {

// A segment and a triangle count as parallel when the determinant of their
// system is below this fraction of the product of their lengths: round-off level.
constexpr double kParallelTolerance = 1e-12;
// The grid's cell size is at least this fraction of its extent (or of 1 m):
// keeps the cell count finite when every box is a point.
constexpr double kMinCellFraction = 1e-12;
// At most this many cells per item on average (the cell grows until it holds):
// bounds memory for point-like items (a surface's vertices: the mean box edge
// is 0) and for surfaces in a 3D grid, whose cells are mostly empty. 2: the
// guard's static grids over a 960 000-tet fixed slab's surface took about 80
// MB more per rank at 64 (peak 312 -> 234 MB, 2 ranks); the stairway's contact
// time fell from 0.57-0.69 s to 0.40 s, the bunny's and epcot's by up to 10 %,
// the default scene's stayed within its noise (measured 2026-11-25; 8 gave
// 256 MB and 0.43 s). Answers do not depend on it: queries break ties by
// index (LocateInFreeBody's point strictly inside lies in one tet of an
// uninverted mesh); the seed scenes are bit for bit the same.
constexpr double kMaxCellsPerItem = 2.0;

}  // namespace

Eigen::Vector4d Barycentric(const Point &p, const Point &a, const Point &b, const Point &c,
                            const Point &d) {
  // Cramer's rule with triple products: l_b = det[p-a, c-a, d-a] / det[b-a, c-a, d-a], ...
  const Point ab = b - a, ac = c - a, ad = d - a, ap = p - a;
  const Point cd = ac.cross(ad);
  const double volume = ab.dot(cd);
  const double lb = ap.dot(cd) / volume;
  const double lc = ab.dot(ap.cross(ad)) / volume;
  const double ld = ab.dot(ac.cross(ap)) / volume;
  return {1 - lb - lc - ld, lb, lc, ld};
}

Point ClosestPointOnTriangle(const Point &p, const Point &a, const Point &b, const Point &c,
                             Eigen::Vector3d *w) {
  const Point ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return *w = {1, 0, 0}, a;
  const Point bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return *w = {0, 1, 0}, b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return *w = {1 - v, v, 0}, a + v * ab;
  }
  const Point cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return *w = {0, 0, 1}, c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double v = d2 / (d2 - d6);
    return *w = {1 - v, 0, v}, a + v * ac;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double v = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return *w = {0, 1 - v, v}, b + v * (c - b);
  }
  const double denominator = 1 / (va + vb + vc);
  const double v = vb * denominator, u = vc * denominator;
  return *w = {1 - v - u, v, u}, a + v * ab + u * ac;
}

bool SegmentCrossesTriangle(const Point &p, const Point &q, const Point &a, const Point &b,
                            const Point &c, double *t, Eigen::Vector3d *w) {
  // p + t (q - p) = a + u (b - a) + v (c - a), solved by Cramer's rule.
  const Point d = q - p, ab = b - a, ac = c - a;
  const Point h = d.cross(ac);
  const double det = ab.dot(h);
  const double scale = ab.norm() * ac.norm() * d.norm();
  if (!(std::abs(det) > kParallelTolerance * scale)) return false;
  const Point s = p - a;
  const double u = s.dot(h) / det;
  if (u < 0 || u > 1) return false;
  const Point k = s.cross(ab);
  const double v = d.dot(k) / det;
  if (v < 0 || u + v > 1) return false;
  *t = ac.dot(k) / det;
  if (*t < 0 || *t > 1) return false;
  *w = {1 - u - v, u, v};
  return true;
}

std::vector<std::pair<int32_t, int32_t>> BoundaryEdges(const TetMesh &mesh) {
  return BoundaryEdges(BoundaryTriangles(mesh));
}

std::vector<std::pair<int32_t, int32_t>> BoundaryEdges(
    const Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor> &triangles) {
  std::vector<std::pair<int32_t, int32_t>> edges;
  for (Eigen::Index t = 0; t < triangles.rows(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int32_t a = triangles(t, k), b = triangles(t, (k + 1) % 3);
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  return edges;
}

void UniformGrid::Build(const std::vector<Box> &boxes) {
  bounds_ = Box();
  double edge_sum = 0;
  for (const Box &b : boxes) {
    bounds_.Extend(b);
    edge_sum += (b.upper - b.lower).sum() / 3;
  }
  item_start_.clear();  // empty until items are binned
  cell_start_.clear();
  items_.clear();
  if (boxes.empty()) return;
  item_start_.assign(1, 0);
  const Eigen::Array3d extent = (bounds_.upper - bounds_.lower).array();
  h_ = std::max(edge_sum / boxes.size(), kMinCellFraction * std::max(1.0, extent.maxCoeff()));
  const double max_cells = kMaxCellsPerItem * boxes.size() + kMaxCellsPerItem;
  while ((extent / h_ + 1).prod() > max_cells) h_ *= 1.5;
  cells_ = (extent / h_).floor().cast<int>() + 1;
  // Count, then fill (CSR).
  cell_start_.assign(static_cast<size_t>(cells_.prod()) + 1, 0);
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<int64_t> next;
    if (pass == 1) {
      for (size_t n = 1; n < cell_start_.size(); ++n) cell_start_[n] += cell_start_[n - 1];
      items_.resize(cell_start_.back());
      next.assign(cell_start_.begin(), cell_start_.end() - 1);
    }
    for (size_t item = 0; item < boxes.size(); ++item) {
      const Eigen::Array3i lo = CellOf(boxes[item].lower.array()),
                           hi = CellOf(boxes[item].upper.array());
      for (int k = lo[2]; k <= hi[2]; ++k)
        for (int j = lo[1]; j <= hi[1]; ++j)
          for (int i = lo[0]; i <= hi[0]; ++i) {
            const int64_t cell = Index(i, j, k);
            if (pass == 0)
              ++cell_start_[cell + 1];
            else
              items_[next[cell]++] = static_cast<int32_t>(item);
          }
    }
  }
}

}  // namespace softbody
