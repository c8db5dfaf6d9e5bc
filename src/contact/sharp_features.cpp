#include "contact/sharp_features.hpp"

#include <Eigen/Geometry>

namespace softbody {

namespace {

// Sharp edges are sampled at most this fraction of the finest free body's mean
// boundary edge length apart: a free face cannot pass between two samples
// without one of them entering it.
constexpr double kFeatureSpacing = 0.5;
// The flush test steps this fraction of the fixed body's mean edge length off
// each face of an edge: far enough to leave round-off, close enough to stay
// within a touching neighbour.
constexpr double kFlushProbe = 1e-6;

using Candidate = SharpFeatures::Candidate;
using NormalPairs = std::vector<std::pair<Point, Point>>;

// The outward normals of the boundary faces at each boundary edge.
std::map<std::pair<int32_t, int32_t>, std::vector<Point>> FacesOfEdges(const TetMesh &mesh) {
  const auto triangles = BoundaryTriangles(mesh);
  std::map<std::pair<int32_t, int32_t>, std::vector<Point>> faces_of_edge;
  for (Eigen::Index t = 0; t < triangles.rows(); ++t) {
    const Point a = mesh.vertices.row(triangles(t, 0)), b = mesh.vertices.row(triangles(t, 1)),
                c = mesh.vertices.row(triangles(t, 2));
    const Point normal = (b - a).cross(c - a).normalized();
    for (int k = 0; k < 3; ++k) {
      const int32_t u = triangles(t, k), w = triangles(t, (k + 1) % 3);
      faces_of_edge[{std::min(u, w), std::max(u, w)}].push_back(normal);
    }
  }
  return faces_of_edge;
}

// The face-normal pairs of a sharp edge; none when its faces meet flat enough.
NormalPairs SharpPairs(const std::vector<Point> &normals) {
  NormalPairs pairs;
  if (normals.size() == 2 && normals[0].dot(normals[1]) >= std::cos(kFeatureAngle)) return pairs;
  if (normals.size() == 2)
    pairs.emplace_back(normals[0], normals[1]);
  else
    for (const Point &n : normals) pairs.emplace_back(n, n);
  return pairs;
}

// The sharp features of a body's surface as points: the end points of its
// sharp edges, and points along them at most `spacing` apart.
std::vector<Candidate> FeaturePoints(const TetMesh &mesh, double spacing) {
  std::map<int32_t, NormalPairs> corners;
  std::vector<Candidate> points;
  for (const auto &[edge, normals] : FacesOfEdges(mesh)) {
    const NormalPairs pairs = SharpPairs(normals);
    if (pairs.empty()) continue;
    for (const int32_t v : {edge.first, edge.second})
      corners[v].insert(corners[v].end(), pairs.begin(), pairs.end());
    const Point a = mesh.vertices.row(edge.first), b = mesh.vertices.row(edge.second);
    const int pieces = static_cast<int>(std::ceil((b - a).norm() / spacing));
    for (int k = 1; k < pieces; ++k) points.push_back({a + (b - a) * (double(k) / pieces), pairs});
  }
  for (const auto &[v, pairs] : corners)
    points.push_back({mesh.vertices.row(v).transpose(), pairs});
  return points;
}

}  // namespace

SharpFeatures::Candidates SharpFeatures::Sample(const Scene &scene, const FreeState &state) {
  double spacing = kUnbounded;
  for (size_t b = 0; b < scene.bodies.size(); ++b)
    if (!scene.bodies[b].fixed) spacing = std::min(spacing, kFeatureSpacing * state.edge(b));
  Candidates candidates;
  for (size_t b = 0; b < scene.bodies.size(); ++b)
    if (scene.bodies[b].fixed) candidates[b] = FeaturePoints(scene.bodies[b].mesh, spacing);
  return candidates;
}

void SharpFeatures::Keep(const Candidates &candidates, const Scene &scene, const FreeState &state,
                         const Obstacles &obstacles) {
  begin_.assign(1, 0);
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const double probe = kFlushProbe * state.edge(b);
    auto covered = [&](const Point &p) {
      for (size_t o = 0; o < scene.bodies.size(); ++o)
        if (o != b && scene.bodies[o].fixed && obstacles.body_box(o).Contains(p, probe) &&
            obstacles.InsideBody(p, static_cast<int32_t>(o)))
          return true;
      return false;
    };
    const auto found = candidates.find(b);
    if (found != candidates.end())
      for (const Candidate &candidate : found->second) {
        const bool real =
            std::any_of(candidate.edges.begin(), candidate.edges.end(), [&](const auto &faces) {
              return !covered(candidate.point + probe * faces.first) &&
                     !covered(candidate.point + probe * faces.second);
            });
        if (real) point_.push_back(candidate.point);
      }
    begin_.push_back(static_cast<int32_t>(point_.size()));
  }
}

}  // namespace softbody
