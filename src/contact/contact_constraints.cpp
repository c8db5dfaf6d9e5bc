#include "contact/contact_constraints.hpp"

#include <algorithm>

namespace softbody {

namespace {

// A feature contact moves the triangle's vertices whose barycentric weight at
// the contact point is at least this: a vertex the point barely touches (the
// point lies on the opposite edge) would get a constraint that hardly pushes
// it and only holds it.
constexpr double kMovingWeight = 1e-3;
// A feature point within this fraction of the free body's mean edge length of
// its surface touches it (a fixed edge flush with a free face) and does not
// penetrate.
constexpr double kFeatureTouching = 1e-3;
// A feature point is inside a free body when all its barycentric coordinates
// in one of the body's tets exceed this: points on the surface are touching.
constexpr double kFeatureInsideMargin = 1e-6;
// A contact pulls when its reaction is below -kPullRoundOff times the impulse
// that stops its vertex at the bounce speed (m times about two steps of
// gravity); smaller pulls are round-off of contacts at zero load.
constexpr double kPullRoundOff = 1e-9;

// Removes obstacle o from the vertex's list (keeping the others' order).
void Remove(VertexObstacles *held, int32_t o) {
  int32_t *end = held->obstacle + held->count;
  if (std::remove(held->obstacle, end, o) != end) --held->count;
}

}  // namespace

void ContactConstraints::Setup(const Scene &scene, const DofLayout &layout, const FreeState &state,
                               const Obstacles &obstacles, const SharpFeatures &features,
                               double gap) {
  gap_ = gap;
  scene_ = &scene;
  layout_ = &layout;
  state_ = &state;
  obstacles_ = &obstacles;
  features_ = &features;
}

void ContactConstraints::Clear(PetscReal bounce_speed) {
  normals_.clear();
  solve_constraints_.clear();
  contacts_.clear();
  constrained_.assign(state_->local_count(), VertexObstacles());
  feature_held_.assign(features_->size(), 0);
  feature_contact_.assign(state_->local_count(), -1);
  held_.clear();
  held_slot_.assign(state_->local_count(), -1);
  global_count_ = 0;
  bounce_speed_ = bounce_speed;
  released_.clear();
  release_reaction_.clear();
  num_released_ = 0;
}

bool ContactConstraints::AddVertexPenetration(PetscInt local, int32_t natural, const Point &x0,
                                              const Point &velocity, PetscReal dt) {
  const VertexObstacles &held = constrained_[local];
  if (held.full()) return false;
  const Point predicted = x0 + dt * velocity;
  SurfaceHit hit;
  if (!obstacles_->FindPenetration(predicted, state_->body_of(natural), held, &hit, natural))
    return false;
  PreferEntry(x0, predicted, &hit);
  Constrain(local, natural, x0, predicted, velocity, dt, hit, true);
  return true;
}

// A vertex that starts the step outside a fixed obstacle meets the face it
// enters through: near an edge or across a thin part the closest surface point
// of the end point can be another face. Against a free body the path relative
// to its surface is only estimated: the closest point stays.
void ContactConstraints::PreferEntry(const Point &x0, const Point &predicted,
                                     SurfaceHit *hit) const {
  if (hit->body < 0 || !scene_->bodies[hit->body].fixed) return;
  SurfaceHit entry;
  if (!obstacles_->InsideBody(x0, hit->body) &&
      obstacles_->EntryOnBody(x0, predicted, hit->body, &entry))
    *hit = entry;
}

void ContactConstraints::Constrain(PetscInt local, int32_t natural, const Point &x0,
                                   const Point &predicted, const Point &velocity, PetscReal dt,
                                   const SurfaceHit &hit, bool fresh, double guess) {
  const Point &n = hit.normal;
  const double w = state_->inverse_mass(natural), w_obstacle = hit.inverse_mass;
  const double share = w / (w + w_obstacle);  // 1 against a fixed obstacle
  // The contact ends the gap outside, but never higher than the vertex started
  // the step: lifting a vertex that vibrates within the gap would add energy.
  const double gap = gap_ * state_->edge(state_->body_of(natural));
  const double start_height = n.dot(x0 - hit.point);
  const Point outside = hit.point + (start_height >= 0 ? std::min(gap, start_height) : gap) * n;
  const Point target = predicted + share * (outside - predicted);
  const double approach = n.dot(velocity - hit.velocity);  // < 0: closing
  const double common = (w_obstacle * n.dot(velocity) + w * n.dot(hit.velocity)) / (w + w_obstacle);
  const double normal_velocity = RecoveryVelocity(natural, x0, target, dt, hit);
  normals_.push_back({local, n, normal_velocity, w_obstacle == 0});
  if (hit.body >= 0 && !scene_->bodies[hit.body].fixed && hit.triangle >= 0) {
    MakeTwoSided(natural, x0, dt, hit, &normals_.back());
    normals_.back().guess = guess;
  }
  contacts_.push_back(
      {natural, hit.body, common, fresh && approach < -bounce_speed_, -1, hit.velocity});
  VertexObstacles &obstacles = constrained_[local];
  obstacles.obstacle[obstacles.count++] = hit.body;
}

// The relative normal velocity that takes the vertex from its start height
// above the face (the face point at the step's start: the predicted one less
// dt times its velocity) to the gap, never higher than it started; from
// inside, at most kMaxRecoveryPerStep edges per step, and deeper than that
// only stopping the sinking (RecoveryVelocity's rules, relative to the face).
void ContactConstraints::MakeTwoSided(int32_t natural, const Point &x0, PetscReal dt,
                                      const SurfaceHit &hit, VelocityConstraint *constraint) const {
  const Point &n = hit.normal;
  const double edge = state_->edge(state_->body_of(natural)), gap = gap_ * edge;
  const double height = n.dot(x0 - (hit.point - dt * hit.velocity));
  double velocity = ((height >= 0 ? std::min(gap, height) : gap) - height) / dt;
  if (height < 0)
    velocity = std::min(
        velocity, -height > kMaxRecoveryPerStep * edge ? 0.0 : kMaxRecoveryPerStep * edge / dt);
  const auto &triangle = hit.face;
  constraint->velocity = velocity;
  constraint->two_sided = true;
  constraint->weights = hit.weights;
  for (int k = 0; k < 3; ++k) constraint->face[k] = layout_->PetscVertexOfNatural(triangle[k]);
}

// A vertex already inside at the start of the step (a body placed in the
// ground, say) comes out gradually: at most kMaxRecoveryPerStep of its body's
// edge length per step faster than the obstacle. Deeper than that inside
// another free body, it only stops sinking: there closest-point normals point
// every way, and pushing along them strains both bodies without separating them.
double ContactConstraints::RecoveryVelocity(int32_t natural, const Point &x0, const Point &target,
                                            PetscReal dt, const SurfaceHit &hit) const {
  const Point &n = hit.normal;
  const double edge = state_->edge(state_->body_of(natural));
  const bool deep_in_free_body = hit.body >= 0 && !scene_->bodies[hit.body].fixed &&
                                 n.dot(hit.point - x0) > kMaxRecoveryPerStep * edge;
  const double recovery =
      n.dot(hit.velocity) + (deep_in_free_body ? 0.0 : kMaxRecoveryPerStep * edge / dt);
  double normal_velocity = n.dot(target - x0) / dt;
  if (n.dot(hit.point - x0) > 0) normal_velocity = std::min(normal_velocity, recovery);
  return normal_velocity;
}

// The vertices that move: those with weight, but not one lying on a fixed
// surface that faces within kFeatureAngle of m (its own contact holds it along
// nearly m; both held exactly would need a sideways velocity of
// (c_1 - c_2) / sin(angle)), unless all do (leaving every vertex on a fixed
// surface alone would push the others by up to d / w_k).
std::array<bool, 3> ContactConstraints::MovingVertices(const std::array<int32_t, 4> &triangle,
                                                       const SurfaceHit &hit,
                                                       const Point &m) const {
  std::array<bool, 3> moves;
  for (int k = 0; k < 3; ++k)
    moves[k] =
        hit.weights[k] >= kMovingWeight &&
        !obstacles_->OnFixedSurface(state_->position(triangle[k]), m, std::cos(kFeatureAngle));
  if (std::none_of(moves.begin(), moves.end(), [](bool b) { return b; }))
    for (int k = 0; k < 3; ++k) moves[k] = hit.weights[k] >= kMovingWeight;
  return moves;
}

PetscInt ContactConstraints::ConstrainFeature(int32_t feature, const SurfaceHit &hit, PetscReal dt,
                                              bool fresh, bool limit) {
  const Point m = -hit.normal;
  const auto &triangle = hit.face;
  const int32_t obstacle = features_->body_of(feature);
  double depth = m.dot(features_->point(feature) - hit.point) + gap_ * state_->edge(triangle[3]);
  if (limit) depth = std::min(depth, kMaxRecoveryPerStep * state_->edge(triangle[3]));
  const std::array<bool, 3> moves = MovingVertices(triangle, hit, m);
  double squares = 0;
  for (int k = 0; k < 3; ++k)
    if (moves[k]) squares += hit.weights[k] * hit.weights[k];
  PetscInt changed = 0;
  for (int k = 0; k < 3; ++k) {
    const int32_t natural = triangle[k];
    const PetscInt local = layout_->LocalOfNatural(natural);
    if (!moves[k] || local < 0) continue;
    const Point velocity = state_->velocity(natural);
    const double push = hit.weights[k] * depth / squares / dt;  // d_k / dt
    const VelocityConstraint constraint{local, m, m.dot(velocity) + push, true};
    const Contact contact{natural, obstacle, 0.0, fresh && m.dot(velocity) < -bounce_speed_,
                          feature};
    if (PlaceFeatureConstraint(constraint, contact, velocity, push)) ++changed;
  }
  return changed;
}

bool ContactConstraints::PlaceFeatureConstraint(const VelocityConstraint &constraint,
                                                const Contact &contact, const Point &velocity,
                                                double push) {
  ptrdiff_t &slot = feature_contact_[constraint.vertex];
  if (slot >= 0) {  // the vertex's larger push stays
    const VelocityConstraint &held = normals_[slot];
    if (!(push > held.velocity - held.normal.dot(velocity))) return false;
    normals_[slot] = constraint;
    contacts_[slot] = contact;
    return true;
  }
  slot = static_cast<ptrdiff_t>(contacts_.size());
  normals_.push_back(constraint);
  contacts_.push_back(contact);
  return true;
}

PetscInt ContactConstraints::AddFeaturePenetrations(PetscReal dt) {
  PetscInt found = 0;
  for (size_t b = 0; b < scene_->bodies.size(); ++b) {
    if (scene_->bodies[b].fixed || obstacles_->body_box(b).Empty()) continue;
    for (size_t f = 0; f < features_->num_bodies(); ++f)
      // Broad phase: the fixed body's box meets the free one's.
      if (features_->on_body(f) && obstacles_->body_box(f).Overlaps(obstacles_->body_box(b)))
        found += AddFeaturePenetrationsOf(f, b, dt);
  }
  return found;
}

// Touching (within kFeatureTouching edge lengths of the surface, e.g. a fixed
// edge flush with a free face) is no penetration. Else p pushes the triangle
// it entered through, on its path relative to the body (p + dt v -> p, v the
// body's velocity at p); if it was inside already, the closest one, and it
// comes out gradually.
PetscInt ContactConstraints::AddFeaturePenetrationsOf(size_t f, size_t b, PetscReal dt) {
  const int32_t body = static_cast<int32_t>(b);
  PetscInt found = 0;
  for (int32_t i = features_->begin(f); i < features_->end(f); ++i) {
    const Point &p = features_->point(i);
    Point velocity;
    if (feature_held_[i] || !obstacles_->body_box(b).Contains(p) ||
        !obstacles_->LocateInFreeBody(p, body, kFeatureInsideMargin, &velocity))
      continue;
    SurfaceHit hit;
    if (!obstacles_->ClosestOnBody(p, body, &hit) ||
        (hit.point - p).norm() < kFeatureTouching * state_->edge(b))
      continue;
    const bool entered = obstacles_->EntryOnBody(p + dt * velocity, p, body, &hit);
    feature_held_[i] = 1;
    found += ConstrainFeature(i, hit, dt, true, !entered);
  }
  return found;
}

void ContactConstraints::Hold(PetscInt local, const Point &velocity, bool immobile) {
  ptrdiff_t &slot = held_slot_[local];
  if (slot < 0) {
    slot = static_cast<ptrdiff_t>(held_.size());
    held_.resize(held_.size() + 3);
  }
  for (int k = 0; k < 3; ++k)
    held_[slot + k] = {local, Point::Unit(k), velocity[k], immobile, true};
}

PetscInt ContactConstraints::ReleasePulling(const std::vector<PetscReal> &reactions) {
  released_.resize(contacts_.size(), 0);
  release_reaction_.resize(contacts_.size(), 0);
  PetscInt released = 0;
  for (size_t i = 0; i < contacts_.size(); ++i) {
    const Contact &contact = contacts_[i];
    const double scale = bounce_speed_ / state_->inverse_mass(contact.natural);
    if (released_[i] || contact.feature >= 0 || !(reactions[i] < -kPullRoundOff * scale)) continue;
    released_[i] = 1;
    release_reaction_[i] = reactions[i];
    Remove(&constrained_[normals_[i].vertex], contact.body);
    ++num_released_;
    ++released;
  }
  return released;
}

std::vector<PetscReal> ContactConstraints::ByContact(
    const std::vector<PetscReal> &reactions) const {
  if (num_released_ == 0) return reactions;
  std::vector<PetscReal> by_contact(reactions.size() + num_released_);
  size_t next = 0;
  for (size_t i = 0; i < contacts_.size(); ++i)
    by_contact[i] = i < released_.size() && released_[i] ? release_reaction_[i] : reactions[next++];
  std::copy(reactions.begin() + next, reactions.end(), by_contact.begin() + contacts_.size());
  return by_contact;
}

PetscErrorCode ContactConstraints::Combine(MPI_Comm comm,
                                           const std::vector<VelocityConstraint> &tangents) {
  PetscFunctionBeginUser;
  solve_constraints_.clear();
  for (size_t i = 0; i < normals_.size(); ++i)
    if (i >= released_.size() || !released_[i]) solve_constraints_.push_back(normals_[i]);
  solve_constraints_.insert(solve_constraints_.end(), tangents.begin(), tangents.end());
  solve_constraints_.insert(solve_constraints_.end(), held_.begin(), held_.end());
  for (VelocityConstraint &c : solve_constraints_) c.order_key = state_->owned_natural()[c.vertex];
  const PetscInt local = static_cast<PetscInt>(solve_constraints_.size());
  PetscCallMPI(MPIU_Allreduce(&local, &global_count_, 1, MPIU_INT, MPI_SUM, comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
