#include "contact/collision_guard.hpp"

#include <algorithm>
#include <cstdio>

#include "common/exchange.hpp"
#include "contact/contact_meshes.hpp"
#include "contact/halo.hpp"

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

PetscErrorCode CollisionGuard::Setup(MPI_Comm comm, const Scene &scene, const ContactMeshes &meshes,
                                     const DofLayout &layout, Vec lumped_mass,
                                     const ContactOptions &options, bool self_contact,
                                     double min_edge, const std::vector<double> &reach) {
  PetscFunctionBeginUser;
  comm_ = comm;
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  parallel_ = size > 1;
  reach_ = reach;
  reuse_ = options.guard_reuse;
  surface_.Build(scene, meshes);
  const int32_t n = surface_.num_vertices();
  moving_.assign(n, 0);
  owned_mask_.assign(n, 0);
  rest_.resize(n);
  for (int32_t v = 0; v < n; ++v) {
    const int32_t natural = surface_.natural[v];
    rest_[v] = meshes.rest(natural);
    if (layout.PetscVertexOfNatural(natural) < 0) continue;
    moving_[v] = 1;
    free_vertices_.push_back(v);
    const PetscInt local = layout.LocalOfNatural(natural);
    if (local >= 0) owned_.push_back({v, local}), owned_mask_[v] = 1;
  }
  PetscCall(FetchMasses(lumped_mass));
  if (parallel_) PetscCall(neighbours_.Setup(comm));
  start_ = end_ = rest_;
  usable_.assign(n, 1);
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

PetscErrorCode CollisionGuard::FetchMasses(Vec lumped_mass) {
  PetscFunctionBeginUser;
  mass_.assign(surface_.num_vertices(), 0.0);
  const PetscScalar *mass;
  PetscCall(VecGetArrayRead(lumped_mass, &mass));
  for (const auto &[v, local] : owned_) mass_[v] = mass[3 * local];
  PetscCall(VecRestoreArrayRead(lumped_mass, &mass));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CollisionGuard::WriteOwnedPositions(Vec x0, Vec x) {
  PetscFunctionBeginUser;
  const PetscScalar *a0, *a1;
  PetscCall(VecGetArrayRead(x0, &a0));
  PetscCall(VecGetArrayRead(x, &a1));
  for (const auto &[v, local] : owned_) {
    start_[v] = Point(&a0[3 * local]);
    end_[v] = Point(&a1[3 * local]);
  }
  PetscCall(VecRestoreArrayRead(x0, &a0));
  PetscCall(VecRestoreArrayRead(x, &a1));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Usable: the static vertices, this rank's and the halo's. A vertex goes to a
// rank when its motion's box meets one of that rank's boxes grown by the reach
// of the vertex's body.
PetscErrorCode CollisionGuard::ExchangeHalo() {
  PetscFunctionBeginUser;
  for (const int32_t v : free_vertices_) usable_[v] = 0;
  std::vector<Box> boxes(surface_.num_bodies());
  for (const auto &[v, local] : owned_) {
    usable_[v] = 1;
    boxes[surface_.body[v]].Extend(start_[v]);
    boxes[surface_.body[v]].Extend(end_[v]);
  }
  HaloPlan plan;
  PetscCall(PlanHalo(
      comm_, boxes, owned_.size(),
      [&](int32_t i, const RankBox &box) {
        const int32_t v = owned_[i].first;
        Box motion;
        motion.Extend(start_[v]);
        motion.Extend(end_[v]);
        const double reach = reach_[surface_.body[v]];
        motion.lower.array() -= reach;
        motion.upper.array() += reach;
        return motion.Overlaps(box.box());
      },
      &plan, &bytes_sent_));
  std::vector<HaloVertex> records, received;
  for (const int32_t i : plan.items) {
    const int32_t v = owned_[i].first;
    HaloVertex h{v, {}, {}, mass_[v]};
    for (int c = 0; c < 3; ++c) h.start[c] = start_[v][c], h.end[c] = end_[v][c];
    records.push_back(h);
  }
  PetscInt64 bytes;
  PetscCall(neighbours_.Exchange(plan.ranks, plan.counts, records, &received, &bytes));
  bytes_sent_ += bytes;
  for (const HaloVertex &h : received) {
    start_[h.vertex] = Point(h.start);
    end_[h.vertex] = Point(h.end);
    mass_[h.vertex] = h.mass;
    usable_[h.vertex] = 1;
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CollisionGuard::Probe(Vec x0, Vec x, bool *moved) {
  PetscFunctionBeginUser;
  PetscLogDouble begin, finish;
  PetscCall(PetscTime(&begin));
  PetscCall(WriteOwnedPositions(x0, x));
  ++stats_.probes;
  int repeats = RepeatsCleanProbe();
  if (parallel_) PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, &repeats, 1, MPI_INT, MPI_MIN, comm_));
  if (repeats) {  // moved_ is the last probe's: nothing
    ++stats_.repeated;
    *moved = false;
  } else {
    if (parallel_) PetscCall(ExchangeHalo());
    PetscCall(Resolve(&moved_));
    *moved = std::find(moved_.begin(), moved_.end(), 1) != moved_.end();
    last_clean_ = !*moved;
    if (last_clean_) RememberCleanProbe();
  }
  PetscCall(PetscTime(&finish));
  stats_.seconds += finish - begin;
  PetscFunctionReturn(PETSC_SUCCESS);
}

bool CollisionGuard::RepeatsCleanProbe() const {
  if (!reuse_ || !last_clean_) return false;
  for (size_t i = 0; i < owned_.size(); ++i) {
    const int32_t v = owned_[i].first;
    if (start_[v] != clean_start_[i] || end_[v] != clean_end_[i]) return false;
  }
  return true;
}

void CollisionGuard::RememberCleanProbe() {
  clean_start_.resize(owned_.size());
  clean_end_.resize(owned_.size());
  for (size_t i = 0; i < owned_.size(); ++i) {
    clean_start_[i] = start_[owned_[i].first];
    clean_end_[i] = end_[owned_[i].first];
  }
}

std::vector<std::pair<PetscInt, int32_t>> CollisionGuard::OwnedMoved() const {
  std::vector<std::pair<PetscInt, int32_t>> owned;
  for (const auto &[v, local] : owned_)
    if (moved_[v]) owned.push_back({local, v});
  return owned;
}

std::vector<CollisionGuard::MovedVertex> CollisionGuard::MovedEnds() const {
  std::vector<MovedVertex> moved;
  for (const auto &[local, s] : OwnedMoved()) moved.push_back({local, end_[s], frozen_[s] != 0});
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

// In a fixed order (ground pairs first, then by vertices), so that zones merge
// alike on every rank and at every rank count.
PetscErrorCode CollisionGuard::ShareCollisions(std::vector<SurfaceCollision> *collisions) {
  PetscFunctionBeginUser;
  if (parallel_) {
    std::vector<SharedCollision> mine, all;
    for (const SurfaceCollision &c : *collisions) {
      SharedCollision shared{{}, c.count, {}, {}, {}};
      for (int k = 0; k < 4; ++k) {
        shared.vertices[k] = c.vertices[k];
        shared.mass[k] = mass_[c.vertices[k]];
        for (int d = 0; d < 3; ++d) {
          shared.start[k][d] = start_[c.vertices[k]][d];
          shared.end[k][d] = end_[c.vertices[k]][d];
        }
      }
      mine.push_back(shared);
    }
    PetscCall(AllGatherRecords(comm_, mine, &all));
    bytes_sent_ += static_cast<PetscInt64>(mine.size() * sizeof(SharedCollision));
    collisions->clear();
    for (const SharedCollision &c : all) {
      collisions->push_back(
          {{c.vertices[0], c.vertices[1], c.vertices[2], c.vertices[3]}, c.count});
      for (int k = 0; k < 4; ++k) {
        start_[c.vertices[k]] = Point(c.start[k]);
        end_[c.vertices[k]] = Point(c.end[k]);
        mass_[c.vertices[k]] = c.mass[k];
        usable_[c.vertices[k]] = 1;  // zones move it: later rounds test it wherever it goes
      }
    }
  }
  std::sort(collisions->begin(), collisions->end(),
            [](const SurfaceCollision &a, const SurfaceCollision &b) {
              return a.count != b.count ? a.count < b.count : a.vertices < b.vertices;
            });
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CollisionGuard::Resolve(std::vector<char> *moved) {
  PetscFunctionBeginUser;
  const int32_t n = surface_.num_vertices();
  std::vector<char> changed;
  moved->assign(n, 0);
  zones_.Reset(n);
  query_.changed = nullptr;
  query_.usable = parallel_ ? &usable_ : nullptr;
  query_.owned = parallel_ ? &owned_mask_ : nullptr;
  // Pairs tested, pairs close at the start, self-contact and static candidate lists built.
  PetscInt rounds = 0, counts[4] = {0, 0, 0, 0};
  bool stopped_all = false;  // every free vertex stays where it started (no zone settled)
  for (;; ++rounds) {
    CollisionCount count;
    std::vector<SurfaceCollision> collisions = finder_.Find(query_, &count);
    counts[0] += count.candidates;
    if (rounds == 0) counts[1] += count.close;
    counts[2] += count.rebuilds;
    counts[3] += count.static_rebuilds;
    PetscCall(ShareCollisions(&collisions));
    if (collisions.empty()) break;
    stats_.collisions += static_cast<PetscInt>(collisions.size());
    if (rounds == kMaxRounds) {
      for (const int32_t v : free_vertices_) end_[v] = start_[v], (*moved)[v] = 1;
      stopped_all = true;
      break;
    }
    MergeZones(collisions);
    changed.assign(n, 0);
    for (const int32_t v : zones_.Move(start_, mass_, &end_)) changed[v] = (*moved)[v] = 1;
    query_.changed = &changed;
  }
  query_.changed = nullptr;
  if (parallel_) PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, counts, 4, MPIU_INT, MPI_SUM, comm_));
  stats_.candidates += counts[0];
  stats_.close_pairs += counts[1];
  stats_.rebuilds += counts[2];
  stats_.static_rebuilds += counts[3];
  if (rounds > 0) ++stats_.passes_guarded;
  stats_.rounds += rounds;
  stats_.max_rounds = std::max(stats_.max_rounds, rounds);
  frozen_.assign(n, 0);
  for (int32_t v = 0; v < n; ++v)
    if ((*moved)[v] && moving_[v]) {
      ++stats_.zone_vertices;
      frozen_[v] = stopped_all || zones_.immobile(v);
      if (frozen_[v]) ++stats_.frozen_vertices;
    }
  PetscFunctionReturn(PETSC_SUCCESS);
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
