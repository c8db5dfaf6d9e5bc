#include "contact/collision_guard.hpp"

#include <algorithm>
#include <cstdio>

#include "common/exchange.hpp"
#include "contact/contact_meshes.hpp"

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
  scene_ = &scene;
  layout_ = &layout;
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  parallel_ = size > 1;
  reach_ = reach;
  reuse_ = options.guard_reuse;
  query_.self_contact = self_contact;
  query_.ground = options.ground;
  query_.ground_y = options.ground_y;
  query_.tolerance.separation = kSeparationOfGap * options.gap * min_edge;
  query_.tolerance.band = kBand * query_.tolerance.separation;
  // The whole surface, for the set-up only.
  ContactSurface whole;
  whole.Build(scene, meshes);
  const int32_t n = whole.num_vertices();
  std::vector<Point> rest(n);
  std::vector<char> moving(n, 0), owned(n, 0);
  for (int32_t v = 0; v < n; ++v) {
    const int32_t natural = whole.natural[v];
    rest[v] = meshes.rest(natural);
    if (layout.PetscVertexOfNatural(natural) < 0) continue;
    moving[v] = 1;
    ++whole_free_vertices_;
    owned[v] = layout.LocalOfNatural(natural) >= 0;
  }
  whole_triangles_ = whole.triangles.size();
  whole_edges_ = whole.edges.size();
  half_skin_ = SurfaceCollisionFinder::HalfSkins(whole, rest);
  Reassemble(whole, owned, moving, {});
  for (int32_t v = 0; v < surface_.num_vertices(); ++v)
    start_[v] = end_[v] = rest[surface_.global[v]];
  usable_.assign(surface_.num_vertices(), 1);
  PetscCall(FetchMasses(lumped_mass));
  if (parallel_) PetscCall(neighbours_.Setup(comm));
  query_.surface = &surface_;
  query_.start = &start_;
  query_.end = &end_;
  query_.moving = &moving_;
  finder_.Setup(query_, &half_skin_);
  PetscCall(CountInitialClosePairs());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// At the rest positions, after a halo exchange there: each rank counts the
// pairs whose lowest moving vertex it owns (a pair that close lies well within
// the halo's reach), and the counts are summed. On one rank the candidate
// lists built here serve the first step.
PetscErrorCode CollisionGuard::CountInitialClosePairs() {
  PetscFunctionBeginUser;
  if (parallel_) PetscCall(ExchangeHalo());
  query_.usable = parallel_ ? &usable_ : nullptr;
  query_.owned = parallel_ ? &owned_mask_ : nullptr;
  CollisionCount count;
  finder_.Find(query_, &count);  // start = end = rest: which pairs start too close
  PetscInt close = static_cast<PetscInt>(count.close);
  if (parallel_) PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, &close, 1, MPIU_INT, MPI_SUM, comm_));
  stats_.initial_close_pairs = close;
  PetscFunctionReturn(PETSC_SUCCESS);
}

void CollisionGuard::Reassemble(const ContactSurface &before, const std::vector<char> &own,
                                const std::vector<char> &moving,
                                const std::vector<SurfacePrimitive> &primitives) {
  const std::vector<Point> start = std::move(start_), end = std::move(end_);
  const std::vector<double> mass = std::move(mass_);
  const std::vector<char> usable = std::move(usable_);
  const bool carry = start.size() == static_cast<size_t>(before.num_vertices());
  ContactSurface held;
  AssembleHeldSurface(before, own, moving, received_, primitives, &pending_, &held);
  surface_ = std::move(held);
  const int32_t n = surface_.num_vertices();
  start_.assign(n, Point::Zero());
  end_.assign(n, Point::Zero());
  mass_.assign(n, 0.0);
  usable_.assign(n, 0);
  for (int32_t v = 0, w = 0; v < n && carry; ++v) {  // both in whole order
    while (w < before.num_vertices() && before.global[w] < surface_.global[v]) ++w;
    if (w == before.num_vertices() || before.global[w] != surface_.global[v]) continue;
    start_[v] = start[w];
    end_[v] = end[w];
    mass_[v] = mass[w];
    usable_[v] = usable[w];
  }
  moving_.assign(n, 0);
  owned_mask_.assign(n, 0);
  owned_.clear();
  for (int32_t v = 0; v < n; ++v) {
    const int32_t natural = surface_.natural[v];
    if (layout_->PetscVertexOfNatural(natural) < 0) continue;
    moving_[v] = 1;
    const PetscInt local = layout_->LocalOfNatural(natural);
    if (local >= 0) owned_.push_back({v, local}), owned_mask_[v] = 1;
  }
  owned_.shrink_to_fit();
  moved_.assign(n, 0);
  frozen_.assign(n, 0);
}

int32_t CollisionGuard::HeldIndex(int32_t whole) const {
  const auto at = std::lower_bound(surface_.global.begin(), surface_.global.end(), whole);
  return at != surface_.global.end() && *at == whole
             ? static_cast<int32_t>(at - surface_.global.begin())
             : -1;
}

int64_t CollisionGuard::SceneBytes() const {
  return HeldBytes(surface_.natural) + HeldBytes(surface_.body) + HeldBytes(surface_.global) +
         HeldBytes(surface_.triangles) + HeldBytes(surface_.triangle_id) +
         HeldBytes(surface_.edges) + HeldBytes(received_) + HeldBytes(pending_) + HeldBytes(sent_) +
         HeldBytes(owned_) + HeldBytes(owned_mask_) + HeldBytes(usable_) + HeldBytes(moving_) +
         HeldBytes(mass_) + HeldBytes(start_) + HeldBytes(end_) + HeldBytes(moved_) +
         HeldBytes(frozen_);
}

PetscErrorCode CollisionGuard::FetchMasses(Vec lumped_mass) {
  PetscFunctionBeginUser;
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
// of the vertex's body; the triangles and edges keyed at it go with it.
PetscErrorCode CollisionGuard::ExchangeHalo() {
  PetscFunctionBeginUser;
  for (int32_t v = 0; v < surface_.num_vertices(); ++v)
    if (moving_[v]) usable_[v] = 0;
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
    HaloVertex h{surface_.global[v], surface_.natural[v], surface_.body[v], {}, {}, mass_[v]};
    for (int d = 0; d < 3; ++d) h.start[d] = start_[v][d], h.end[d] = end_[v][d];
    records.push_back(h);
  }
  std::vector<SurfacePrimitive> primitives, received_primitives;
  std::vector<PetscMPIInt> primitive_ranks, primitive_counts;
  KeyedPrimitives(plan, &primitives, &primitive_ranks, &primitive_counts);
  PetscInt64 bytes;
  PetscCall(neighbours_.Exchange(plan.ranks, plan.counts, records, &received, &bytes));
  bytes_sent_ += bytes;
  PetscCall(neighbours_.Exchange(primitive_ranks, primitive_counts, primitives,
                                 &received_primitives, &bytes));
  bytes_sent_ += bytes;
  std::sort(received.begin(), received.end(),
            [](const HaloVertex &a, const HaloVertex &b) { return a.whole < b.whole; });
  const bool same =
      received.size() == received_.size() &&
      std::equal(received.begin(), received.end(), received_.begin(),
                 [](const HaloVertex &h, const SurfaceVertex &v) { return h.whole == v.whole; });
  if (!same) {
    received_.clear();
    for (const HaloVertex &h : received) received_.push_back({h.whole, h.natural, h.body});
    const ContactSurface before = std::move(surface_);
    const std::vector<char> own = owned_mask_, moving = moving_;
    Reassemble(before, own, moving, received_primitives);
    finder_.Renumber(query_);
  }
  for (const HaloVertex &h : received) {
    const int32_t v = HeldIndex(h.whole);
    start_[v] = Point(h.start);
    end_[v] = Point(h.end);
    mass_[v] = h.mass;
    usable_[v] = 1;
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// A rank keeps the primitives of the vertices it received at the last
// exchange (held_surface.hpp), so only a vertex new to a rank's halo takes
// its primitives along.
void CollisionGuard::KeyedPrimitives(const HaloPlan &plan,
                                     std::vector<SurfacePrimitive> *primitives,
                                     std::vector<PetscMPIInt> *ranks,
                                     std::vector<PetscMPIInt> *counts) {
  std::vector<std::pair<int32_t, size_t>> sends;      // (held vertex, index in plan.ranks): new
  std::vector<std::pair<PetscMPIInt, int32_t>> sent;  // (rank, whole vertex): all
  for (size_t r = 0, k = 0; r < plan.ranks.size(); ++r)
    for (PetscMPIInt c = 0; c < plan.counts[r]; ++c, ++k) {
      const int32_t v = owned_[plan.items[k]].first;
      sent.push_back({plan.ranks[r], surface_.global[v]});
      if (!std::binary_search(sent_.begin(), sent_.end(), sent.back())) sends.push_back({v, r});
    }
  std::sort(sends.begin(), sends.end());
  std::sort(sent.begin(), sent.end());
  sent_ = std::move(sent);
  std::vector<std::vector<SurfacePrimitive>> by_rank(plan.ranks.size());
  // Held indices are in whole order: the lowest held vertex is the key.
  auto route = [&](const auto &item, int32_t id) {
    const int32_t key = *std::min_element(item.begin(), item.end());
    if (!owned_mask_[key]) return;
    auto at = std::lower_bound(sends.begin(), sends.end(), std::make_pair(key, size_t{0}));
    for (; at != sends.end() && at->first == key; ++at) {
      SurfacePrimitive p{id, {kNoSurfaceVertex, kNoSurfaceVertex, kNoSurfaceVertex}};
      for (size_t k = 0; k < item.size(); ++k) p.vertices[k] = surface_.global[item[k]];
      by_rank[at->second].push_back(p);
    }
  };
  if (!sends.empty()) {
    for (size_t t = 0; t < surface_.triangles.size(); ++t)
      route(surface_.triangles[t], surface_.triangle_id[t]);
    for (const auto &edge : surface_.edges) route(edge, kNoSurfaceVertex);
  }
  for (size_t r = 0; r < by_rank.size(); ++r) {
    if (by_rank[r].empty()) continue;
    ranks->push_back(plan.ranks[r]);
    counts->push_back(static_cast<PetscMPIInt>(by_rank[r].size()));
    primitives->insert(primitives->end(), by_rank[r].begin(), by_rank[r].end());
  }
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
    *moved = moved_any_;
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
  if (stopped_all_)
    for (const Body &body : scene_->bodies)
      if (!body.fixed)
        std::fill(marked->begin() + body.first_vertex,
                  marked->begin() + body.first_vertex + body.num_vertices(), 1);
  for (const ZoneVertex &z : zone_vertices_)
    if (z.moved) (*marked)[z.natural] = 1;
}

// Which pairs freeze is decided on the zones as the last round left them: pairs
// of one round share vertices, and merging one must not make the next look like
// a zone colliding with itself.
void CollisionGuard::MergeZones(const std::vector<SurfaceCollision> &pairs) {
  std::vector<char> immobile(pairs.size(), 0);
  for (size_t i = 0; i < pairs.size(); ++i) {
    const SurfaceCollision &c = pairs[i];
    immobile[i] = c.count == 1 || zones_.InOneMobileZone(c.vertices.data(), c.count);
    for (int k = 0; k < c.count; ++k)
      immobile[i] = immobile[i] || !zone_vertices_[c.vertices[k]].moving;
  }
  for (size_t i = 0; i < pairs.size(); ++i)
    zones_.Merge(pairs[i].vertices.data(), pairs[i].count, immobile[i]);
}

int32_t CollisionGuard::ZoneVertexOf(const SharedCollision &c, int k) {
  const auto [at, added] =
      zone_of_.emplace(c.vertices[k], static_cast<int32_t>(zone_vertices_.size()));
  if (added) {
    zones_.Add();
    zone_vertices_.push_back({c.vertices[k], c.natural[k], c.moving[k] != 0, false});
    zone_start_.push_back(Point(c.start[k]));
    zone_end_.push_back(Point(c.end[k]));
    zone_mass_.push_back(c.mass[k]);
  }
  return at->second;
}

// In a fixed order (ground pairs first, then by whole vertices), so that zones
// merge alike on every rank and at every rank count.
PetscErrorCode CollisionGuard::ShareCollisions(const std::vector<SurfaceCollision> &found,
                                               std::vector<SurfaceCollision> *pairs) {
  PetscFunctionBeginUser;
  std::vector<SharedCollision> mine, all;
  for (const SurfaceCollision &c : found) {
    SharedCollision shared{{}, {}, {}, c.count, {}, {}, {}};
    for (int k = 0; k < 4; ++k) {
      const int32_t v = c.vertices[k];
      shared.vertices[k] = surface_.global[v];
      shared.natural[k] = surface_.natural[v];
      shared.moving[k] = moving_[v];
      shared.mass[k] = mass_[v];
      for (int d = 0; d < 3; ++d) {
        shared.start[k][d] = start_[v][d];
        shared.end[k][d] = end_[v][d];
      }
    }
    mine.push_back(shared);
  }
  if (parallel_) {
    PetscCall(AllGatherRecords(comm_, mine, &all));
    bytes_sent_ += static_cast<PetscInt64>(mine.size() * sizeof(SharedCollision));
  } else {
    all = std::move(mine);
  }
  std::sort(all.begin(), all.end(), [](const SharedCollision &a, const SharedCollision &b) {
    return a.count != b.count ? a.count < b.count
                              : std::lexicographical_compare(a.vertices, a.vertices + 4, b.vertices,
                                                             b.vertices + 4);
  });
  pairs->clear();
  for (const SharedCollision &c : all) {
    SurfaceCollision pair{{}, c.count};
    for (int k = 0; k < 4; ++k) {
      pair.vertices[k] = ZoneVertexOf(c, k);
      const int32_t v = HeldIndex(c.vertices[k]);
      if (v < 0) continue;
      start_[v] = Point(c.start[k]);
      end_[v] = Point(c.end[k]);
      mass_[v] = c.mass[k];
      usable_[v] = 1;  // zones move it: later rounds test it wherever it goes
    }
    pairs->push_back(pair);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CollisionGuard::Resolve(std::vector<char> *moved) {
  PetscFunctionBeginUser;
  const int32_t n = surface_.num_vertices();
  std::vector<char> changed;
  moved->assign(n, 0);
  zones_.Reset(0);
  zone_vertices_.clear();
  zone_of_.clear();
  zone_start_.clear();
  zone_end_.clear();
  zone_mass_.clear();
  query_.changed = nullptr;
  query_.usable = parallel_ ? &usable_ : nullptr;
  query_.owned = parallel_ ? &owned_mask_ : nullptr;
  // Pairs tested, pairs close at the start, self-contact and static candidate lists built.
  PetscInt rounds = 0, counts[4] = {0, 0, 0, 0};
  bool stopped_all = false;  // every free vertex stays where it started (no zone settled)
  for (;; ++rounds) {
    CollisionCount count;
    const std::vector<SurfaceCollision> found = finder_.Find(query_, &count);
    counts[0] += count.candidates;
    if (rounds == 0) counts[1] += count.close;
    counts[2] += count.rebuilds;
    counts[3] += count.static_rebuilds;
    std::vector<SurfaceCollision> pairs;
    PetscCall(ShareCollisions(found, &pairs));
    if (pairs.empty()) break;
    stats_.collisions += static_cast<PetscInt>(pairs.size());
    if (rounds == kMaxRounds) {
      for (int32_t v = 0; v < n; ++v)
        if (moving_[v]) end_[v] = start_[v], (*moved)[v] = 1;
      stopped_all = true;
      break;
    }
    MergeZones(pairs);
    changed.assign(n, 0);
    for (const int32_t z : zones_.Move(zone_start_, zone_mass_, &zone_end_)) {
      zone_vertices_[z].moved = true;
      const int32_t v = HeldIndex(zone_vertices_[z].whole);
      if (v < 0) continue;
      end_[v] = zone_end_[z];
      changed[v] = (*moved)[v] = 1;
    }
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
  CountZoneVertices(stopped_all);
  frozen_.assign(n, 0);
  for (int32_t v = 0; v < n; ++v)
    if ((*moved)[v] && moving_[v])
      frozen_[v] = stopped_all || zones_.immobile(zone_of_.at(surface_.global[v]));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// From the zones' vertices, which every rank has alike; when the safety net
// stopped every free vertex, all of them moved and froze.
void CollisionGuard::CountZoneVertices(bool stopped_all) {
  stopped_all_ = stopped_all;
  moved_any_ = stopped_all;
  if (stopped_all) {
    stats_.zone_vertices += whole_free_vertices_;
    stats_.frozen_vertices += whole_free_vertices_;
    return;
  }
  for (size_t z = 0; z < zone_vertices_.size(); ++z) {
    if (!zone_vertices_[z].moved) continue;
    moved_any_ = true;
    if (!zone_vertices_[z].moving) continue;
    ++stats_.zone_vertices;
    if (zones_.immobile(static_cast<int32_t>(z))) ++stats_.frozen_vertices;
  }
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
                whole_triangles_, whole_edges_, query_.tolerance.separation,
                query_.self_contact ? ", self-contact" : "");
  return text;
}

}  // namespace softbody
