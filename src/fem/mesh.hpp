// Tetrahedral meshes and the geometric queries on them. Not collective.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>

#include "fem/element.hpp"

namespace softbody {

// #V x 3 vertex positions (m) and #T x 4 tets (0-based vertex indices).
struct TetMesh {
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> vertices;
  Eigen::Matrix<int32_t, Eigen::Dynamic, 4, Eigen::RowMajor> tets;

  int32_t num_vertices() const { return static_cast<int32_t>(vertices.rows()); }
  int32_t num_tets() const { return static_cast<int32_t>(tets.rows()); }
};

// Relative volume below which a tet counts as degenerate: |V| <= kDegenerateVolume L^3,
// L its longest edge. A regular tet has |V| / L^3 = 0.118; a sliver of aspect ratio
// 1e3 about 1e-4.
constexpr double kDegenerateVolume = 1e-12;

// The one degeneracy test of every reader: |V| <= kDegenerateVolume L^3.
bool IsDegenerateTet(const TetPositions &X);

// Sum over tets of |volume| x centroid, divided by the total volume (m).
Eigen::Vector3d VolumeWeightedCentroid(const TetMesh &mesh);

// #B x 3 faces that belong to exactly one tet, oriented with outward normals
// ((b - a) x (c - a) points out of the body).
Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor> BoundaryTriangles(const TetMesh &mesh);

}  // namespace softbody
