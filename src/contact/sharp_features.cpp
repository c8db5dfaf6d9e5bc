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

// The outward normals of the boundary faces at each boundary edge (body-local
// vertices); rest(v) the body's vertex v at rest.
template <class Rest>
std::map<std::pair<int32_t, int32_t>, std::vector<Point>> FacesOfEdges(
    const ContactMeshes::Triangles &triangles, Rest rest) {
  std::map<std::pair<int32_t, int32_t>, std::vector<Point>> faces_of_edge;
  for (Eigen::Index t = 0; t < triangles.rows(); ++t) {
    const Point a = rest(triangles(t, 0)), b = rest(triangles(t, 1)), c = rest(triangles(t, 2));
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

// The sharp features of a body's surface (its boundary triangles, body-local;
// rest(v) its vertex v at rest) as points: the end points of its sharp edges,
// and points along them at most `spacing` apart.
template <class Rest>
std::vector<Candidate> FeaturePoints(const ContactMeshes::Triangles &boundary, Rest rest,
                                     double spacing) {
  std::map<int32_t, NormalPairs> corners;
  std::vector<Candidate> points;
  for (const auto &[edge, normals] : FacesOfEdges(boundary, rest)) {
    const NormalPairs pairs = SharpPairs(normals);
    if (pairs.empty()) continue;
    for (const int32_t v : {edge.first, edge.second})
      corners[v].insert(corners[v].end(), pairs.begin(), pairs.end());
    const Point a = rest(edge.first), b = rest(edge.second);
    const int pieces = static_cast<int>(std::ceil((b - a).norm() / spacing));
    for (int k = 1; k < pieces; ++k) points.push_back({a + (b - a) * (double(k) / pieces), pairs});
  }
  for (const auto &[v, pairs] : corners) points.push_back({rest(v), pairs});
  return points;
}

}  // namespace

SharpFeatures::Candidates SharpFeatures::Sample(const Scene &scene, const FreeState &state,
                                                const ContactMeshes &meshes) {
  double spacing = kUnbounded;
  for (size_t b = 0; b < scene.bodies.size(); ++b)
    if (!scene.bodies[b].fixed) spacing = std::min(spacing, kFeatureSpacing * state.edge(b));
  Candidates candidates;
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    if (!scene.bodies[b].fixed) continue;
    const int32_t first = scene.bodies[b].first_vertex;
    candidates[b] = FeaturePoints(
        meshes.boundary(b), [&](int32_t v) { return meshes.rest(first + v); }, spacing);
  }
  return candidates;
}

// A candidate is kept when, for one of its edges, the points a probe off both
// faces lie in no other fixed body: all probe points are asked at once
// (FixedTets::Covered, every rank its share of the fixed tets).
PetscErrorCode SharpFeatures::Keep(const Candidates &candidates, const Scene &scene,
                                   const FreeState &state, const FixedTets &fixed) {
  PetscFunctionBeginUser;
  std::vector<Point> probes;
  std::vector<int32_t> bodies;
  for (const auto &[b, list] : candidates) {
    const double probe = kFlushProbe * state.edge(b);
    for (const Candidate &candidate : list)
      for (const auto &faces : candidate.edges)
        for (const Point &normal : {faces.first, faces.second}) {
          probes.push_back(candidate.point + probe * normal);
          bodies.push_back(static_cast<int32_t>(b));
        }
  }
  std::vector<char> covered;
  PetscCall(fixed.Covered(probes, bodies, &covered));
  begin_.assign(1, 0);
  size_t next = 0;  // the next probe's index
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const auto found = candidates.find(b);
    if (found != candidates.end())
      for (const Candidate &candidate : found->second) {
        bool real = false;
        for (size_t e = 0; e < candidate.edges.size(); ++e, next += 2)
          real = real || (!covered[next] && !covered[next + 1]);
        if (real) point_.push_back(candidate.point);
      }
    begin_.push_back(static_cast<int32_t>(point_.size()));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
