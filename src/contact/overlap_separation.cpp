#include "contact/overlap_separation.hpp"

#include <algorithm>

namespace softbody {

namespace {

// Centroids closer than this (m) give no direction: the pair moves apart along x.
constexpr double kSameCentroid = 1e-12;

}  // namespace

void OverlapSeparation::Setup(const Scene &scene, const FreeState &state, Obstacles *obstacles) {
  scene_ = &scene;
  state_ = &state;
  obstacles_ = obstacles;
  edges_.resize(scene.bodies.size());
  triangles_.resize(scene.bodies.size());
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    if (body.fixed) continue;
    for (const auto &[u, w] : BoundaryEdges(body.mesh))
      edges_[b].push_back({body.first_vertex + u, body.first_vertex + w});
    const auto boundary = BoundaryTriangles(body.mesh);
    for (Eigen::Index f = 0; f < boundary.rows(); ++f)
      triangles_[b].push_back({body.first_vertex + boundary(f, 0),
                               body.first_vertex + boundary(f, 1),
                               body.first_vertex + boundary(f, 2)});
  }
}

size_t OverlapSeparation::FindOverlaps() {
  for (size_t a = 0; a < scene_->bodies.size(); ++a)
    for (size_t b = a + 1; b < scene_->bodies.size(); ++b)
      if (!scene_->bodies[a].fixed && !scene_->bodies[b].fixed && Cross(a, b))
        pairs_.push_back({a, b});
  initial_pairs_ = pairs_.size();
  obstacles_->SetSeparating(pairs_);
  return pairs_.size();
}

PetscErrorCode OverlapSeparation::Step(Vec x, FreeState *state, bool *moved) {
  PetscFunctionBeginUser;
  *moved = false;
  std::vector<std::pair<size_t, size_t>> crossing;
  for (const auto &[a, b] : pairs_)
    if (Cross(a, b)) crossing.push_back({a, b});
  if (crossing.size() != pairs_.size()) {
    pairs_ = crossing;
    obstacles_->SetSeparating(pairs_);
  }
  if (pairs_.empty()) PetscFunctionReturn(PETSC_SUCCESS);
  ++steps_;
  std::vector<Point> shift(scene_->bodies.size(), Point::Zero());
  for (const auto &[a, b] : pairs_) {
    const auto [move_a, move_b] = Translations(a, b);
    shift[a] += move_a;
    shift[b] += move_b;
  }
  PetscScalar *lx;
  PetscCall(VecGetArray(x, &lx));
  for (PetscInt p = 0; p < state->local_count(); ++p) {
    const Point &s = shift[state->body_of(state->owned_natural()[p])];
    for (int c = 0; c < 3; ++c) lx[3 * p + c] += s[c];
  }
  PetscCall(VecRestoreArray(x, &lx));
  for (size_t b = 0; b < scene_->bodies.size(); ++b) {
    const Body &body = scene_->bodies[b];
    if (body.fixed || shift[b].isZero(0)) continue;
    for (int32_t v = 0; v < body.mesh.num_vertices(); ++v)
      state->position_ref(body.first_vertex + v) += shift[b];
  }
  obstacles_->MoveFreeBodies();
  *moved = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

bool OverlapSeparation::Cross(size_t a, size_t b) const {
  if (!obstacles_->body_box(a).Overlaps(obstacles_->body_box(b))) return false;
  if (EdgeCrossesSurface(a, b) || EdgeCrossesSurface(b, a)) return true;
  // No edge crosses: apart, or one inside the other.
  return obstacles_->InsideBody(state_->position(edges_[a].front().first),
                                static_cast<int32_t>(b)) ||
         obstacles_->InsideBody(state_->position(edges_[b].front().first), static_cast<int32_t>(a));
}

bool OverlapSeparation::EdgeCrossesSurface(size_t a, size_t b) const {
  std::vector<Box> boxes(triangles_[b].size());
  for (size_t t = 0; t < boxes.size(); ++t)
    for (int k = 0; k < 3; ++k) boxes[t].Extend(state_->position(triangles_[b][t][k]));
  UniformGrid grid;
  grid.Build(boxes);
  for (const auto &[u, w] : edges_[a]) {
    const Point p = state_->position(u), q = state_->position(w);
    Box edge;
    edge.Extend(p);
    edge.Extend(q);
    bool crosses = false;
    grid.ForEachInBox(edge, [&](int32_t t) {
      const auto &tri = triangles_[b][t];
      double along;
      Eigen::Vector3d weights;
      crosses = crosses ||
                (boxes[t].Overlaps(edge) &&
                 SegmentCrossesTriangle(p, q, state_->position(tri[0]), state_->position(tri[1]),
                                        state_->position(tri[2]), &along, &weights));
    });
    if (crosses) return true;
  }
  return false;
}

Point OverlapSeparation::Centroid(size_t b) const {
  const Body &body = scene_->bodies[b];
  Point sum = Point::Zero();
  double mass = 0;
  for (int32_t v = 0; v < body.mesh.num_vertices(); ++v) {
    const double w = state_->inverse_mass(body.first_vertex + v);
    if (!(w > 0)) continue;
    sum += state_->position(body.first_vertex + v) / w;
    mass += 1 / w;
  }
  return mass > 0 ? Point(sum / mass) : sum;
}

std::pair<Point, Point> OverlapSeparation::Translations(size_t a, size_t b) const {
  const Point line = Centroid(b) - Centroid(a);
  const Point d = line.norm() > kSameCentroid ? Point(line.normalized()) : Point::UnitX();
  const double length = kSeparationPerStep * std::min(state_->edge(a), state_->edge(b));
  const double mass_a = state_->mass(a), mass_b = state_->mass(b);
  return {-length * mass_b / (mass_a + mass_b) * d, length * mass_a / (mass_a + mass_b) * d};
}

}  // namespace softbody
