#include "contact/velocity_response.hpp"

#include <algorithm>
#include <cmath>

namespace softbody {

namespace {

// A constrained vertex closer than this fraction of its body's mean edge
// length to the surface ended the step on it (its constraint held, up to
// round-off): no projection.
constexpr double kOnSurface = 1e-6;
// A two-sided contact rests into the next step when its impulse would change
// its vertex's velocity by more than this (m/s): smaller ones are the
// round-off of the solve (another rank count, another factorisation), and
// must not decide which contacts the next step starts with.
constexpr double kRestingSpeed = 1e-9;
// Numbers per collision when collisions travel between ranks: vertex, body,
// position (3), dv (3), the vertex's inverse mass.
constexpr size_t kPackedCollision = 9;
// Numbers per body describing its motion: momentum (3), kinetic energy.
constexpr size_t kPackedMotion = 4;
// Numbers per body that Bounce reduces: the motion at the start and now, the
// normal impulse of its impacts against immobile obstacles (3) and against
// free bodies (3).
constexpr size_t kPackedBounce = 2 * kPackedMotion + 6;

}  // namespace

void VelocityResponse::Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                             const FreeState &state, const Obstacles &obstacles,
                             const ContactOptions &options) {
  comm_ = comm;
  scene_ = &scene;
  layout_ = &layout;
  state_ = &state;
  obstacles_ = &obstacles;
  options_ = options;
}

std::vector<Collision> VelocityResponse::Respond(const ContactConstraints &constraints,
                                                 const Friction &friction,
                                                 const std::vector<PetscReal> &reactions,
                                                 const PetscScalar *x, const PetscScalar *v,
                                                 RestingContacts *resting) const {
  const auto &contacts = constraints.contacts();
  const std::vector<char> friction_in_solve = friction.InSolve(contacts.size());
  std::vector<Collision> collisions;
  for (size_t i = 0; i < contacts.size(); ++i) {
    if (constraints.released(i)) continue;  // left the solve: its vertex is free
    const Contact &contact = contacts[i];
    const VelocityConstraint &constraint = constraints.normals()[i];
    const Point position(&x[3 * constraint.vertex]), velocity(&v[3 * constraint.vertex]);
    collisions.push_back({contact.natural, state_->body_of(contact.natural), position,
                          ContactVelocityChange(contact, constraint, reactions[i],
                                                friction_in_solve[i], position, velocity)});
    // Resting contacts stay constrained while the obstacle pushes; bouncing ones leave.
    // A two-sided contact is an inequality: one that did not push this step
    // is found again if its vertex sinks.
    const bool pushes = constraint.two_sided
                            ? reactions[i] * state_->inverse_mass(contact.natural) > kRestingSpeed
                            : reactions[i] >= 0;
    if (pushes && !(options_.restitution > 0 && contact.impact)) {
      Contact carried = contact;
      carried.reaction = reactions[i];
      resting->Add(constraint.vertex, carried);
    }
  }
  return collisions;
}

// Relative normal velocity -e times the approach for a new contact, 0 for a
// resting one (Contact::normal_velocity). Sliding friction, unless friction
// acted in the solve: at most mu lambda / m of the tangential velocity
// relative to the obstacle is lost. (One expression with the normal part:
// the result stays bit for bit.)
Point VelocityResponse::ContactVelocityChange(const Contact &contact,
                                              const VelocityConstraint &constraint, double reaction,
                                              bool friction_in_solve, const Point &position,
                                              const Point &velocity) const {
  const Point &n = constraint.normal;
  // A two-sided contact's solve gave both sides their equal and opposite
  // impulses: setting one side's normal velocity would break that balance.
  Point dv = constraint.two_sided ? Point(Point::Zero())
                                  : Point((contact.normal_velocity - n.dot(velocity)) * n);
  SurfaceHit hit;
  const double limit = options_.friction * std::max(reaction, 0.0);
  if (!friction_in_solve && options_.friction > 0 &&
      obstacles_->ContactOnBody(position, contact.natural, contact.body, &hit)) {
    const Point relative = velocity - hit.velocity;
    const Point tangential = relative - n.dot(relative) * n;
    const double slip = tangential.norm(), grip = limit * state_->inverse_mass(contact.natural);
    if (slip > 0) dv -= std::min(1.0, grip / slip) * tangential;
  }
  return dv;
}

PetscInt VelocityResponse::ProjectRemaining(
    const std::vector<std::pair<PetscInt, int32_t>> &checked, const ContactConstraints &constraints,
    PetscScalar *x, const PetscScalar *v, std::vector<Collision> *collisions) const {
  PetscInt projected = 0;
  for (const auto &[local, natural] : checked) {
    const Point position(&x[3 * local]);
    SurfaceHit hit;
    // Only vertices truly inside: the ground's margin (within half the contact
    // gap above it) is for the constraints, and lifting such a vertex adds energy.
    if (!obstacles_->FindPenetration(position, state_->body_of(natural), VertexObstacles(), &hit,
                                     natural) ||
        hit.normal.dot(position - hit.point) >= 0 ||
        !ShouldProject(local, natural, position, hit, constraints))
      continue;
    const Point velocity(&v[3 * local]);
    const double approach = hit.normal.dot(velocity - hit.velocity);
    const Point target =
        hit.point + options_.gap * state_->edge(state_->body_of(natural)) * hit.normal;
    for (int c = 0; c < 3; ++c) x[3 * local + c] = target[c];
    if (approach < 0)
      collisions->push_back({natural, state_->body_of(natural), target,
                             -(1 + options_.restitution) * approach * hit.normal});
    ++projected;
  }
  return projected;
}

// Deeper than kMaxRecoveryPerStep edge lengths: left to the next step's
// constraints, which bring it out gradually. A constrained vertex ends on the
// surface (to round-off) unless its constraints could not all hold (more than
// three directions, e.g. a sticking contact's and a sharp edge's); it is
// projected out of fixed bodies and the ground only (out of a free body, one
// side's projection would change the momentum of the pair).
bool VelocityResponse::ShouldProject(PetscInt local, int32_t natural, const Point &x,
                                     const SurfaceHit &hit,
                                     const ContactConstraints &constraints) const {
  const double depth = (hit.point - x).norm(), edge = state_->edge(state_->body_of(natural));
  const bool immobile = hit.body < 0 || scene_->bodies[hit.body].fixed;
  return !(depth > kMaxRecoveryPerStep * edge ||
           (constraints.obstacles_of(local).count && (depth < kOnSurface * edge || !immobile)));
}

void VelocityResponse::Apply(const std::vector<Collision> &collisions, PetscScalar *v) const {
  for (const Collision &c : collisions) {
    const PetscInt local = layout_->LocalOfNatural(c.vertex);
    for (int k = 0; k < 3; ++k) v[3 * local + k] += c.dv[k];
  }
}

void VelocityResponse::AddMotion(const PetscScalar *v, double *sums) const {
  for (PetscInt p = 0; p < state_->local_count(); ++p) {
    const int32_t natural = state_->owned_natural()[p];
    const double w = state_->inverse_mass(natural);
    if (!(w > 0)) continue;
    const Point velocity(&v[3 * p]);
    double *body = &sums[kPackedMotion * state_->body_of(natural)];
    for (int k = 0; k < 3; ++k) body[k] += velocity[k] / w;
    body[3] += 0.5 * velocity.squaredNorm() / w;
  }
}

PetscErrorCode VelocityResponse::RecordStart(Vec v0) {
  PetscFunctionBeginUser;
  const PetscScalar *start;
  start_motion_.assign(kPackedMotion * scene_->bodies.size(), 0.0);
  PetscCall(VecGetArrayRead(v0, &start));
  AddMotion(start, start_motion_.data());
  PetscCall(VecRestoreArrayRead(v0, &start));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The change d = target - n . V (V the centroid velocity now); when that
// speeds the body up, at most what keeps its kinetic energy
// K + M (n . V) d + M d^2 / 2 within its kinetic energy K0 at the start.
double VelocityResponse::RigidBounce(size_t b, const Point &n, double target, const double *start,
                                     const double *now) const {
  const double mass = state_->mass(b), normal = n.dot(Point(now)) / mass;
  const double wanted = target - normal;
  if (wanted <= 0) return wanted;
  const double room = normal * normal - 2 * (now[3] - start[3]) / mass;
  return std::min(wanted, room > 0 ? std::max(0.0, -normal + std::sqrt(room)) : 0.0);
}

PetscErrorCode VelocityResponse::Bounce(const ContactConstraints &constraints,
                                        const std::vector<PetscReal> &reactions, Vec v) const {
  PetscFunctionBeginUser;
  const size_t bodies = scene_->bodies.size();
  std::vector<double> local(kPackedBounce * bodies, 0.0), all(local.size());
  PetscScalar *lv;
  PetscCall(VecGetArray(v, &lv));
  for (size_t b = 0; b < bodies; ++b)
    for (size_t k = 0; k < kPackedMotion && !start_motion_.empty(); ++k)
      local[kPackedBounce * b + k] = start_motion_[kPackedMotion * b + k];
  std::vector<double> now(kPackedMotion * bodies, 0.0);
  AddMotion(lv, now.data());
  const auto &contacts = constraints.contacts();
  for (size_t b = 0; b < bodies; ++b)
    for (size_t k = 0; k < kPackedMotion; ++k)
      local[kPackedBounce * b + kPackedMotion + k] = now[kPackedMotion * b + k];
  for (size_t i = 0; i < contacts.size(); ++i) {
    if (!contacts[i].impact || reactions[i] <= 0 || constraints.released(i)) continue;
    const VelocityConstraint &normal = constraints.normals()[i];
    double *impulse = &local[kPackedBounce * state_->body_of(contacts[i].natural) +
                             2 * kPackedMotion + (normal.immobile ? 0 : 3)];
    for (int k = 0; k < 3; ++k) impulse[k] += reactions[i] * normal.normal[k];
  }
  PetscCallMPI(MPI_Allreduce(local.data(), all.data(), static_cast<int>(local.size()), MPI_DOUBLE,
                             MPI_SUM, comm_));
  std::vector<Point> change(bodies, Point::Zero());
  for (size_t b = 0; b < bodies; ++b) {
    const double *body = &all[kPackedBounce * b];
    const Point immobile(&body[2 * kPackedMotion]), free(&body[2 * kPackedMotion + 3]);
    change[b] = options_.restitution * free / state_->mass(b);
    if (immobile.norm() > 0) {
      const Point n = immobile / immobile.norm();
      const double approach = n.dot(Point(body)) / state_->mass(b);  // < 0: closing
      if (approach < 0)
        change[b] +=
            RigidBounce(b, n, -options_.restitution * approach, body, body + kPackedMotion) * n;
    }
  }
  for (PetscInt p = 0; p < state_->local_count(); ++p)
    for (int k = 0; k < 3; ++k)
      lv[3 * p + k] += change[state_->body_of(state_->owned_natural()[p])][k];
  PetscCall(VecRestoreArray(v, &lv));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode VelocityResponse::AllGather(const std::vector<Collision> &local,
                                           std::vector<double> *all) const {
  PetscFunctionBeginUser;
  std::vector<double> packed;
  for (const Collision &c : local) {
    packed.insert(packed.end(), {double(c.vertex), double(c.body)});
    packed.insert(packed.end(), c.position.data(), c.position.data() + 3);
    packed.insert(packed.end(), c.dv.data(), c.dv.data() + 3);
    packed.push_back(state_->inverse_mass(c.vertex));
  }
  PetscMPIInt size, count = static_cast<PetscMPIInt>(packed.size());
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  std::vector<PetscMPIInt> counts(size), offsets(size + 1, 0);
  PetscCallMPI(MPI_Allgather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, comm_));
  for (int r = 0; r < size; ++r) offsets[r + 1] = offsets[r] + counts[r];
  all->resize(offsets[size]);
  PetscCallMPI(MPI_Allgatherv(packed.data(), count, MPI_DOUBLE, all->data(), counts.data(),
                              offsets.data(), MPI_DOUBLE, comm_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Each collision's weights are summed over its body's free vertices, this
// rank's first, then over the ranks (MPI_SUM): no rank reads another's vertices.
PetscErrorCode VelocityResponse::SpreadImpulses(const std::vector<Collision> &local, Vec v) const {
  PetscFunctionBeginUser;
  std::vector<double> all;
  PetscCall(AllGather(local, &all));
  const size_t count = all.size() / kPackedCollision;
  std::vector<double> totals(count, 0.0);
  for (size_t i = 0; i < count; ++i) {
    const double *c = &all[kPackedCollision * i];
    totals[i] = OwnedWeights(static_cast<int32_t>(c[1]), Point(c[2], c[3], c[4]));
  }
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, totals.data(), static_cast<int>(count), MPI_DOUBLE,
                             MPI_SUM, comm_));
  PetscScalar *lv;
  PetscCall(VecGetArray(v, &lv));
  for (size_t i = 0; i < count; ++i) {
    const double *c = &all[kPackedCollision * i];
    const Point at(c[2], c[3], c[4]), dv(c[5], c[6], c[7]);
    Spread(static_cast<int32_t>(c[1]), at, dv / c[8], totals[i], lv);
  }
  PetscCall(VecRestoreArray(v, &lv));
  PetscFunctionReturn(PETSC_SUCCESS);
}

double VelocityResponse::Weight(int32_t body, int32_t natural, const Point &at) const {
  return 1 / std::pow(state_->edge(body) + (state_->position(natural) - at).norm(), 2);
}

double VelocityResponse::OwnedWeights(int32_t body, const Point &at) const {
  double total = 0;
  for (const int32_t n : state_->owned_natural())
    if (state_->body_of(n) == body) total += Weight(body, n, at);
  return total;
}

void VelocityResponse::Spread(int32_t body, const Point &at, const Point &impulse, double total,
                              PetscScalar *v) const {
  for (PetscInt p = 0; p < state_->local_count(); ++p) {
    const int32_t n = state_->owned_natural()[p];
    if (state_->body_of(n) != body) continue;
    const double share = Weight(body, n, at) / total;
    for (int c = 0; c < 3; ++c) v[3 * p + c] += share * state_->inverse_mass(n) * impulse[c];
  }
}

}  // namespace softbody
