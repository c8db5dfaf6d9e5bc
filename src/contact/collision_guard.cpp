#include "contact/collision_guard.hpp"

#include <algorithm>
#include <cstdio>

namespace softbody {

namespace {

// The guard's separation as a fraction of the contact gap: contacts end a gap
// apart and come back to it once within half of it of the ground, the guard
// acts below a quarter of it, so resting contacts never trigger it.
constexpr double kSeparationOfGap = 0.25;
// CCD reports pairs that come within separation (1 + kBand): the margin that
// lets conservative advancement stop (ccd.hpp).
constexpr double kBand = 0.1;
// Rounds of detection and zones before every moving surface vertex is frozen
// (its start position is apart from everything): a safety net, each round
// merges zones or freezes one, so a bounded count is reached only on huge
// pile-ups.
constexpr int kMaxRounds = 1000;

}  // namespace

CollisionGuard::~CollisionGuard() {
  VecScatterDestroy(&gather_);
  VecDestroy(&gathered_);
}

PetscErrorCode CollisionGuard::Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                                     Vec lumped_mass, const ContactOptions &options,
                                     bool self_contact, double min_edge) {
  PetscFunctionBeginUser;
  comm_ = comm;
  layout_ = &layout;
  surface_.Build(scene);
  const int32_t n = surface_.num_vertices();
  moving_.assign(n, 0);
  rest_.resize(n);
  std::vector<PetscInt> dofs;
  for (int32_t v = 0; v < n; ++v) {
    const int32_t natural = surface_.natural[v];
    const Body &body = scene.bodies[surface_.body[v]];
    rest_[v] = body.mesh.vertices.row(natural - body.first_vertex).transpose();
    const PetscInt petsc = layout.PetscVertexOfNatural(natural);
    if (petsc < 0) continue;
    moving_[v] = 1;
    free_vertices_.push_back(v);
    for (int c = 0; c < 3; ++c) dofs.push_back(3 * petsc + c);
  }
  IS from;
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, static_cast<PetscInt>(dofs.size()), dofs.data(),
                            PETSC_COPY_VALUES, &from));
  PetscCall(VecCreateSeq(PETSC_COMM_SELF, static_cast<PetscInt>(dofs.size()), &gathered_));
  PetscCall(VecScatterCreate(lumped_mass, from, gathered_, nullptr, &gather_));
  PetscCall(ISDestroy(&from));
  std::vector<Point> mass(n, Point::Zero());
  PetscCall(Fetch(lumped_mass, &mass));
  mass_.assign(n, 0.0);
  for (const int32_t v : free_vertices_) mass_[v] = mass[v][0];
  start_ = end_ = rest_;
  query_ = {&surface_,        &start_, &end_, &moving_, {}, self_contact, bool(options.ground),
            options.ground_y, nullptr};
  query_.tolerance.separation = kSeparationOfGap * options.gap * min_edge;
  query_.tolerance.band = kBand * query_.tolerance.separation;
  finder_.Setup(query_);
  CollisionCount count;
  finder_.Find(query_, &count);  // start = end = rest: which pairs start too close
  stats_.initial_close_pairs = static_cast<PetscInt>(count.close);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The free surface vertices' entries of a PETSc vector (3 per vertex), on every rank.
PetscErrorCode CollisionGuard::Fetch(Vec from, std::vector<Point> *to) {
  PetscFunctionBeginUser;
  PetscCall(VecScatterBegin(gather_, from, gathered_, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(gather_, from, gathered_, INSERT_VALUES, SCATTER_FORWARD));
  const PetscScalar *g;
  PetscCall(VecGetArrayRead(gathered_, &g));
  for (size_t k = 0; k < free_vertices_.size(); ++k) (*to)[free_vertices_[k]] = Point(&g[3 * k]);
  PetscCall(VecRestoreArrayRead(gathered_, &g));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CollisionGuard::Probe(Vec x0, Vec x, bool *moved) {
  PetscFunctionBeginUser;
  PetscLogDouble begin, finish;
  PetscCall(PetscTime(&begin));
  PetscCall(Fetch(x0, &start_));
  PetscCall(Fetch(x, &end_));
  moved_ = Resolve();
  *moved = std::find(moved_.begin(), moved_.end(), 1) != moved_.end();
  PetscCall(PetscTime(&finish));
  stats_.seconds += finish - begin;
  PetscFunctionReturn(PETSC_SUCCESS);
}

std::vector<std::pair<PetscInt, int32_t>> CollisionGuard::OwnedMoved() const {
  std::vector<std::pair<PetscInt, int32_t>> owned;
  for (const int32_t s : free_vertices_) {
    const PetscInt local = layout_->LocalOfNatural(surface_.natural[s]);
    if (moved_[s] && local >= 0) owned.push_back({local, s});
  }
  return owned;
}

std::vector<std::pair<PetscInt, Point>> CollisionGuard::MovedVelocities(PetscReal dt) const {
  std::vector<std::pair<PetscInt, Point>> moved;
  for (const auto &[local, s] : OwnedMoved()) moved.push_back({local, (end_[s] - start_[s]) / dt});
  return moved;
}

PetscErrorCode CollisionGuard::Apply(Vec x0, Vec x, Vec v, PetscReal dt, bool *changed) {
  PetscFunctionBeginUser;
  PetscCall(Probe(x0, x, changed));
  if (*changed) PetscCall(WriteBack(x, v, dt));
  PetscFunctionReturn(PETSC_SUCCESS);
}

void CollisionGuard::MarkMoved(std::vector<char> *marked) const {
  for (size_t s = 0; s < moved_.size(); ++s)
    if (moved_[s]) (*marked)[surface_.natural[s]] = 1;
}

// Which pairs freeze is decided on the zones as the last round left them: pairs
// of one round share vertices, and merging one must not make the next look like
// a zone colliding with itself.
void CollisionGuard::MergeZones(const std::vector<SurfaceCollision> &collisions) {
  std::vector<char> immobile(collisions.size(), 0);
  for (size_t i = 0; i < collisions.size(); ++i) {
    const SurfaceCollision &c = collisions[i];
    immobile[i] = c.count == 1 || zones_.InOneMobileZone(c.vertices.data(), c.count);
    for (int k = 0; k < c.count; ++k) immobile[i] = immobile[i] || !moving_[c.vertices[k]];
  }
  for (size_t i = 0; i < collisions.size(); ++i)
    zones_.Merge(collisions[i].vertices.data(), collisions[i].count, immobile[i]);
}

std::vector<char> CollisionGuard::Resolve() {
  const int32_t n = surface_.num_vertices();
  std::vector<char> moved(n, 0), changed;
  zones_.Reset(n);
  query_.changed = nullptr;
  PetscInt rounds = 0;
  for (;; ++rounds) {
    CollisionCount count;
    const std::vector<SurfaceCollision> collisions = finder_.Find(query_, &count);
    stats_.candidates += count.candidates;
    if (rounds == 0) stats_.close_pairs += count.close;
    if (collisions.empty()) break;
    stats_.collisions += static_cast<PetscInt>(collisions.size());
    if (rounds == kMaxRounds) {
      for (const int32_t v : free_vertices_) end_[v] = start_[v], moved[v] = 1;
      break;
    }
    MergeZones(collisions);
    changed.assign(n, 0);
    for (const int32_t v : zones_.Move(start_, mass_, &end_)) changed[v] = moved[v] = 1;
    query_.changed = &changed;
  }
  query_.changed = nullptr;
  if (rounds > 0) ++stats_.passes_guarded;
  stats_.rounds += rounds;
  stats_.max_rounds = std::max(stats_.max_rounds, rounds);
  for (int32_t v = 0; v < n; ++v)
    if (moved[v] && moving_[v]) {
      ++stats_.zone_vertices;
      if (zones_.immobile(v)) ++stats_.frozen_vertices;
    }
  return moved;
}

// This rank's moved vertices: x = the zone's end position, v = (x - x0) / dt.
PetscErrorCode CollisionGuard::WriteBack(Vec x, Vec v, PetscReal dt) {
  PetscFunctionBeginUser;
  PetscScalar *lx, *lv;
  PetscCall(VecGetArray(x, &lx));
  PetscCall(VecGetArray(v, &lv));
  for (const auto &[local, s] : OwnedMoved())
    for (int c = 0; c < 3; ++c) {
      lx[3 * local + c] = end_[s][c];
      lv[3 * local + c] = (end_[s][c] - start_[s][c]) / dt;
    }
  PetscCall(VecRestoreArray(x, &lx));
  PetscCall(VecRestoreArray(v, &lv));
  PetscFunctionReturn(PETSC_SUCCESS);
}

std::string CollisionGuard::Description() const {
  char text[160];
  std::snprintf(text, sizeof(text),
                "collision guard (%zu surface triangles, %zu edges, separation %.3g m%s)",
                surface_.triangles.size(), surface_.edges.size(), query_.tolerance.separation,
                query_.self_contact ? ", self-contact" : "");
  return text;
}

}  // namespace softbody
