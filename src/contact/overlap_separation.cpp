#include "contact/overlap_separation.hpp"

#include <algorithm>

#include "contact/contact_meshes.hpp"

namespace softbody {

namespace {

// Centroids closer than this (m) give no direction: the pair moves apart along x.
constexpr double kSameCentroid = 1e-12;
// Numbers per fetched vertex: natural index, position (3).
constexpr int kPackedVertex = 4;
// The inside test's ray direction: no axis or diagonal, so that it rarely
// grazes an edge of a mesh built on a grid.
const Point kRayDirection = Point(1.0, 0.3141592653589793, 0.2718281828459045).normalized();

}  // namespace

void OverlapSeparation::Setup(MPI_Comm comm, const Scene &scene, const ContactMeshes &meshes,
                              const FreeState &state, Obstacles *obstacles) {
  comm_ = comm;
  scene_ = &scene;
  state_ = &state;
  obstacles_ = obstacles;
  edges_.resize(scene.bodies.size());
  triangles_.resize(scene.bodies.size());
  box_.assign(scene.bodies.size(), Box());
  centroid_.assign(scene.bodies.size(), Point::Zero());
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    if (body.fixed) continue;
    const auto &boundary = meshes.boundary(b);
    for (const auto &[u, w] : BoundaryEdges(boundary))
      edges_[b].push_back({body.first_vertex + u, body.first_vertex + w});
    for (Eigen::Index f = 0; f < boundary.rows(); ++f)
      triangles_[b].push_back({body.first_vertex + boundary(f, 0),
                               body.first_vertex + boundary(f, 1),
                               body.first_vertex + boundary(f, 2)});
  }
  NumberSurface();
}

// surface_ from the edges' and triangles' natural vertices, which then name
// surface indices.
void OverlapSeparation::NumberSurface() {
  for (size_t b = 0; b < edges_.size(); ++b) {
    for (const auto &[u, w] : edges_[b]) surface_.insert(surface_.end(), {u, w});
    for (const auto &t : triangles_[b]) surface_.insert(surface_.end(), t.begin(), t.end());
  }
  std::sort(surface_.begin(), surface_.end());
  surface_.erase(std::unique(surface_.begin(), surface_.end()), surface_.end());
  surface_.shrink_to_fit();
  for (size_t b = 0; b < edges_.size(); ++b) {
    for (auto &[u, w] : edges_[b]) u = SurfaceIndex(u), w = SurfaceIndex(w);
    for (auto &t : triangles_[b])
      for (int32_t &n : t) n = SurfaceIndex(n);
  }
  positions_.assign(3 * surface_.size(), 0.0);
}

void OverlapSeparation::ReleaseSurfaces() {
  std::vector<std::vector<std::pair<int32_t, int32_t>>>().swap(edges_);
  std::vector<std::vector<std::array<int32_t, 3>>>().swap(triangles_);
  std::vector<int32_t>().swap(surface_);
  std::vector<double>().swap(positions_);
}

int32_t OverlapSeparation::SurfaceIndex(int32_t natural) const {
  const auto at = std::lower_bound(surface_.begin(), surface_.end(), natural);
  return at != surface_.end() && *at == natural ? static_cast<int32_t>(at - surface_.begin()) : -1;
}

PetscErrorCode OverlapSeparation::FindOverlaps(Vec x, size_t *found) {
  PetscFunctionBeginUser;
  std::vector<char> bodies(scene_->bodies.size());
  for (size_t b = 0; b < bodies.size(); ++b) bodies[b] = !scene_->bodies[b].fixed;
  PetscCall(Fetch(x, bodies));
  for (size_t a = 0; a < bodies.size(); ++a)
    for (size_t b = a + 1; b < bodies.size(); ++b)
      if (bodies[a] && bodies[b] && Cross(a, b)) pairs_.push_back({a, b});
  initial_pairs_ = pairs_.size();
  obstacles_->SetSeparating(pairs_);
  *found = pairs_.size();
  if (pairs_.empty()) ReleaseSurfaces();
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode OverlapSeparation::Step(Vec x, bool *moved) {
  PetscFunctionBeginUser;
  *moved = false;
  std::vector<char> bodies(scene_->bodies.size(), 0);
  for (const auto &[a, b] : pairs_) bodies[a] = bodies[b] = 1;
  PetscCall(Fetch(x, bodies));
  std::vector<std::pair<size_t, size_t>> crossing;
  for (const auto &[a, b] : pairs_)
    if (Cross(a, b)) crossing.push_back({a, b});
  if (crossing.size() != pairs_.size()) {
    pairs_ = crossing;
    obstacles_->SetSeparating(pairs_);
  }
  if (pairs_.empty()) {
    ReleaseSurfaces();
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  ++steps_;
  std::vector<Point> shift(scene_->bodies.size(), Point::Zero());
  for (const auto &[a, b] : pairs_) {
    const auto [move_a, move_b] = Translations(a, b);
    shift[a] += move_a;
    shift[b] += move_b;
  }
  PetscScalar *lx;
  PetscCall(VecGetArray(x, &lx));
  for (PetscInt p = 0; p < state_->local_count(); ++p) {
    const Point &s = shift[state_->body_of(state_->owned_natural()[p])];
    for (int c = 0; c < 3; ++c) lx[3 * p + c] += s[c];
  }
  PetscCall(VecRestoreArray(x, &lx));
  *moved = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Each rank packs its own surface vertices of the bodies; the mass moments
// (sum m x, sum m per body) are reduced.
PetscErrorCode OverlapSeparation::Fetch(Vec x, const std::vector<char> &bodies) {
  PetscFunctionBeginUser;
  const size_t count = scene_->bodies.size();
  std::vector<double> packed, moments(4 * count, 0.0);
  const PetscScalar *lx;
  PetscCall(VecGetArrayRead(x, &lx));
  for (PetscInt p = 0; p < state_->local_count(); ++p) {
    const int32_t natural = state_->owned_natural()[p];
    const int32_t b = state_->body_of(natural);
    const double w = state_->inverse_mass(natural);
    if (!bodies[b]) continue;
    if (w > 0) {
      for (int c = 0; c < 3; ++c) moments[4 * b + c] += lx[3 * p + c] / w;
      moments[4 * b + 3] += 1 / w;
    }
    if (SurfaceIndex(natural) >= 0)
      packed.insert(packed.end(), {double(natural), lx[3 * p], lx[3 * p + 1], lx[3 * p + 2]});
  }
  PetscCall(VecRestoreArrayRead(x, &lx));
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, moments.data(), static_cast<PetscMPIInt>(4 * count),
                              MPI_DOUBLE, MPI_SUM, comm_));
  PetscMPIInt size, sent = static_cast<PetscMPIInt>(packed.size());
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  std::vector<PetscMPIInt> counts(size), offsets(size + 1, 0);
  PetscCallMPI(MPI_Allgather(&sent, 1, MPI_INT, counts.data(), 1, MPI_INT, comm_));
  for (int r = 0; r < size; ++r) offsets[r + 1] = offsets[r] + counts[r];
  std::vector<double> all(offsets[size]);
  PetscCallMPI(MPI_Allgatherv(packed.data(), sent, MPI_DOUBLE, all.data(), counts.data(),
                              offsets.data(), MPI_DOUBLE, comm_));
  for (size_t b = 0; b < count; ++b) {
    box_[b] = Box();
    if (bodies[b] && moments[4 * b + 3] > 0)
      centroid_[b] = Point(&moments[4 * b]) / moments[4 * b + 3];
  }
  for (size_t i = 0; i < all.size(); i += kPackedVertex) {
    const int32_t natural = static_cast<int32_t>(all[i]);
    const int32_t surface = SurfaceIndex(natural);
    for (int c = 0; c < 3; ++c) positions_[3 * surface + c] = all[i + 1 + c];
    box_[state_->body_of(natural)].Extend(At(surface));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

bool OverlapSeparation::Cross(size_t a, size_t b) const {
  if (!box_[a].Overlaps(box_[b])) return false;
  if (EdgeCrossesSurface(a, b) || EdgeCrossesSurface(b, a)) return true;
  // No edge crosses: apart, or one inside the other.
  return InsideSurface(At(edges_[a].front().first), b) ||
         InsideSurface(At(edges_[b].front().first), a);
}

bool OverlapSeparation::EdgeCrossesSurface(size_t a, size_t b) const {
  std::vector<Box> boxes(triangles_[b].size());
  for (size_t t = 0; t < boxes.size(); ++t)
    for (int k = 0; k < 3; ++k) boxes[t].Extend(At(triangles_[b][t][k]));
  UniformGrid grid;
  grid.Build(boxes);
  for (const auto &[u, w] : edges_[a]) {
    const Point p = At(u), q = At(w);
    Box edge;
    edge.Extend(p);
    edge.Extend(q);
    bool crosses = false;
    grid.ForEachInBox(edge, [&](int32_t t) {
      const auto &tri = triangles_[b][t];
      double along;
      Eigen::Vector3d weights;
      crosses = crosses ||
                (boxes[t].Overlaps(edge) && SegmentCrossesTriangle(p, q, At(tri[0]), At(tri[1]),
                                                                   At(tri[2]), &along, &weights));
    });
    if (crosses) return true;
  }
  return false;
}

bool OverlapSeparation::InsideSurface(const Point &p, size_t b) const {
  if (!box_[b].Contains(p)) return false;
  const Point far = p + 2 * (box_[b].upper - box_[b].lower).norm() * kRayDirection;
  int crossings = 0;
  for (const auto &tri : triangles_[b]) {
    double along;
    Eigen::Vector3d weights;
    if (SegmentCrossesTriangle(p, far, At(tri[0]), At(tri[1]), At(tri[2]), &along, &weights))
      ++crossings;
  }
  return crossings % 2 == 1;
}

std::pair<Point, Point> OverlapSeparation::Translations(size_t a, size_t b) const {
  const Point line = centroid_[b] - centroid_[a];
  const Point d = line.norm() > kSameCentroid ? Point(line.normalized()) : Point::UnitX();
  const double length = kSeparationPerStep * std::min(state_->edge(a), state_->edge(b));
  const double mass_a = state_->mass(a), mass_b = state_->mass(b);
  return {-length * mass_b / (mass_a + mass_b) * d, length * mass_a / (mass_a + mass_b) * d};
}

}  // namespace softbody
