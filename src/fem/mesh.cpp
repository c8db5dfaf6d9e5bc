#include "fem/mesh.hpp"

#include <algorithm>
#include <array>
#include <vector>

#include "fem/element.hpp"

namespace softbody {

static TetPositions TetCorners(const TetMesh &mesh, int32_t t) {
  TetPositions X;
  for (int a = 0; a < 4; ++a) X.row(a) = mesh.vertices.row(mesh.tets(t, a));
  return X;
}

bool IsDegenerateTet(const TetPositions &X) {
  const double length = LongestEdge(X);
  return !(std::abs(SignedVolume(X)) > kDegenerateVolume * length * length * length);
}

Eigen::Vector3d VolumeWeightedCentroid(const TetMesh &mesh) {
  Eigen::Vector3d weighted = Eigen::Vector3d::Zero();
  double total = 0;
  for (int32_t t = 0; t < mesh.num_tets(); ++t) {
    const TetPositions X = TetCorners(mesh, t);
    const double volume = std::abs(SignedVolume(X));
    weighted += volume * X.colwise().mean().transpose();
    total += volume;
  }
  return weighted / total;
}

Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor> BoundaryTriangles(const TetMesh &mesh) {
  // Faces of a positively oriented tet (0,1,2,3) with outward normals.
  static const int kFaces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  struct Face {
    std::array<int32_t, 3> key;       // sorted vertex indices
    std::array<int32_t, 3> oriented;  // outward orientation
  };
  std::vector<Face> faces;
  faces.reserve(4 * static_cast<size_t>(mesh.num_tets()));
  for (int32_t t = 0; t < mesh.num_tets(); ++t) {
    const bool positive = SignedVolume(TetCorners(mesh, t)) > 0;
    for (const auto &f : kFaces) {
      Face face;
      for (int k = 0; k < 3; ++k) face.oriented[k] = mesh.tets(t, f[k]);
      if (!positive) std::swap(face.oriented[1], face.oriented[2]);
      face.key = face.oriented;
      std::sort(face.key.begin(), face.key.end());
      faces.push_back(face);
    }
  }
  std::sort(faces.begin(), faces.end(), [](const Face &a, const Face &b) { return a.key < b.key; });
  std::vector<std::array<int32_t, 3>> boundary;
  for (size_t i = 0; i < faces.size();) {
    size_t j = i + 1;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j - i == 1) boundary.push_back(faces[i].oriented);
    i = j;
  }
  Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor> result(boundary.size(), 3);
  for (size_t b = 0; b < boundary.size(); ++b)
    for (int k = 0; k < 3; ++k) result(b, k) = boundary[b][k];
  return result;
}

}  // namespace softbody
