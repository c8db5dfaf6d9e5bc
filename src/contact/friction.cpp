#include "contact/friction.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace softbody {

namespace {

// Relative tolerance of quantities equal up to round-off: the tangential
// velocity a sticking step leaves, a sticking reaction at the Coulomb limit.
constexpr double kRoundOff = 1e-9;
// A slip's impulse is updated (and the step solved again) when its normal
// reaction moved by more than this fraction since the last solve round: the
// friction impulses then hold to 0.1 %, well inside what the friction tests
// ask (5 %), in half the rounds a 1e-6 fixed point took.
constexpr double kSlipUpdate = 1e-3;

// A slip's direction turns with its contact's sliding when the two differ by
// more than this (1 - cos of the angle, about 2.6 degrees): closer than that,
// another solve round is not worth it.
constexpr double kSlipTurn = 1e-3;

// Releases of one contact from sticking in a step after which a reversed
// slip holds it for the rest of the step: it bounds the rounds a contact can
// spend flipping between stick and slip (contacts released in the same round
// push each other). With the trial impulse deciding, a reversed release is
// rare: the friction tests give the same figures with 1, 2, 3 or 5.
constexpr int kMaxReleases = 3;

}  // namespace

void Friction::Clear() {
  tangents_.clear();
  sticking_contact_.clear();
  slips_.clear();
  mode_.clear();
  releases_.clear();
  observed_.clear();
}

void Friction::Stick(PetscInt local, const Point &velocity, const SurfaceHit &hit, size_t contact) {
  const Point &n = hit.normal;
  const Point relative = velocity - hit.velocity;
  if ((relative - n.dot(relative) * n).norm() > kRoundOff * (velocity.norm() + hit.velocity.norm()))
    return;
  const Point t1 = n.unitOrthogonal(), t2 = n.cross(t1);
  tangents_.push_back({local, t1, t1.dot(hit.velocity), hit.inverse_mass == 0});
  tangents_.push_back({local, t2, t2.dot(hit.velocity), hit.inverse_mass == 0});
  sticking_contact_.push_back(contact);
  if (mode_.size() <= contact) mode_.resize(contact + 1, kUndecided);
  mode_[contact] = kSticking;
}

void Friction::Observe(const std::vector<VelocityConstraint> &normals,
                       const std::vector<Contact> &contacts, const PetscScalar *v) {
  observed_.resize(contacts.size());
  for (size_t i = 0; i < contacts.size(); ++i) {
    const VelocityConstraint &normal = normals[i];
    const Point velocity(&v[3 * normal.vertex]), &n = normal.normal;
    const Point relative = velocity - contacts[i].obstacle_velocity;
    observed_[i] = {normal.vertex,
                    n,
                    contacts[i].obstacle_velocity,
                    relative - n.dot(relative) * n,
                    velocity.norm() + contacts[i].obstacle_velocity.norm(),
                    mass_of_(contacts[i].natural),
                    normal.immobile};
  }
}

std::vector<char> Friction::InSolve(size_t num_contacts) const {
  std::vector<char> in_solve(num_contacts, 0);
  for (size_t i = 0; i < std::min(num_contacts, mode_.size()); ++i)
    in_solve[i] = mode_[i] != kUndecided;
  return in_solve;
}

void Friction::AddTangents(size_t contact, Mode mode) {
  const Observed &o = observed_[contact];
  const Point t1 = o.normal.unitOrthogonal(), t2 = o.normal.cross(t1);
  tangents_.push_back({o.vertex, t1, t1.dot(o.obstacle_velocity), o.immobile});
  tangents_.push_back({o.vertex, t2, t2.dot(o.obstacle_velocity), o.immobile});
  sticking_contact_.push_back(contact);
  mode_[contact] = mode;
}

void Friction::AddSlip(size_t contact, const Point &direction, double magnitude, Mode mode,
                       PetscScalar *rhs) {
  const PetscInt vertex = observed_[contact].vertex;
  for (int c = 0; c < 3; ++c) rhs[3 * vertex + c] += magnitude * direction[c];
  slips_.push_back({contact, vertex, direction, magnitude});
  mode_[contact] = mode;
}

PetscInt Friction::FollowSlips(const std::vector<PetscReal> &reactions, PetscScalar *rhs) {
  PetscInt changed = 0;
  for (Slip &slip : slips_) {
    const double limit = mu_ * std::max(reactions[slip.contact], 0.0);
    if (std::abs(limit - slip.magnitude) <= kSlipUpdate * std::max(limit, slip.magnitude)) continue;
    for (int c = 0; c < 3; ++c)
      rhs[3 * slip.vertex + c] += (limit - slip.magnitude) * slip.direction[c];
    slip.magnitude = limit;
    ++changed;
  }
  return changed;
}

PetscInt Friction::ReleaseSticking(const std::vector<PetscReal> &reactions, size_t num_contacts,
                                   size_t solved, PetscScalar *rhs) {
  PetscInt released = 0;
  std::vector<VelocityConstraint> kept_tangents;
  std::vector<size_t> kept_contacts;
  for (size_t k = 0; k < sticking_contact_.size(); ++k) {
    const size_t contact = sticking_contact_[k], first = num_contacts + 2 * k;
    const VelocityConstraint &t1 = tangents_[2 * k], &t2 = tangents_[2 * k + 1];
    const bool keep = k >= solved || mode_[contact] == kHeld;
    const Point impulse =
        keep ? Point::Zero()
             : Point(reactions[first] * t1.normal + reactions[first + 1] * t2.normal);
    const double limit = mu_ * std::max(reactions[contact], 0.0);
    if (keep || impulse.norm() <= limit * (1 + kRoundOff)) {
      kept_tangents.insert(kept_tangents.end(), {t1, t2});
      kept_contacts.push_back(contact);
      continue;
    }
    // Kinetic friction: mu lambda_n along the sticking reaction.
    const Point direction = impulse / impulse.norm();
    for (int c = 0; c < 3; ++c) rhs[3 * t1.vertex + c] += limit * direction[c];
    slips_.push_back({contact, t1.vertex, direction, limit});
    mode_[contact] = kReleased;
    ++releases_[contact];
    ++released;
  }
  tangents_.swap(kept_tangents);
  sticking_contact_.swap(kept_contacts);
  return released;
}

// The slip's impulse r points against the sliding it met; when the trial
// impulse r - m v_t lies within the cone |.| <= mu lambda (the sliding
// stopped, or reversed by less than 2 mu lambda / m, twice what friction
// alone gives the vertex in a step), friction would have stopped the contact
// within the step and it sticks. Otherwise the impulse turns towards the
// trial's direction, which becomes -v_t as the rounds go on.
PetscInt Friction::SteerSlips(PetscScalar *rhs) {
  PetscInt changed = 0;
  std::vector<Slip> kept;
  for (Slip &slip : slips_) {
    const Observed &o = observed_[slip.contact];
    // Alart-Curnier's trial impulse r - c v_t, c the vertex's mass: within
    // the cone, friction holds the contact. One without load (it pulls) slips.
    const Point trial = slip.magnitude * slip.direction - o.mass * o.tangential;
    if (slip.magnitude > 0 && trial.norm() <= slip.magnitude) {
      for (int c = 0; c < 3; ++c) rhs[3 * slip.vertex + c] -= slip.magnitude * slip.direction[c];
      const bool hold = mode_[slip.contact] == kReleased && releases_[slip.contact] >= kMaxReleases;
      AddTangents(slip.contact, hold ? kHeld : kSticking);
      ++changed;
      continue;
    }
    const Point turned = trial / trial.norm();
    if (1 - turned.dot(slip.direction) > kSlipTurn) {
      for (int c = 0; c < 3; ++c)
        rhs[3 * slip.vertex + c] += slip.magnitude * (turned[c] - slip.direction[c]);
      slip.direction = turned;
      ++changed;
    }
    kept.push_back(slip);
  }
  slips_.swap(kept);
  return changed;
}

PetscInt Friction::DecideNewContacts(const std::vector<PetscReal> &reactions, size_t num_contacts,
                                     PetscScalar *rhs) {
  PetscInt decided = 0;
  for (size_t i = 0; i < num_contacts; ++i) {
    if (mode_[i] != kUndecided) continue;
    const Observed &o = observed_[i];
    const double slip = o.tangential.norm();
    // A contact that is being released (it pulls) gets no hold, only the
    // slip's magnitude following its reaction.
    if (slip <= kRoundOff * o.scale && reactions[i] > 0)
      AddTangents(i, kSticking);
    else
      AddSlip(i, slip > 0 ? Point(-o.tangential / slip) : Point::Zero(),
              mu_ * std::max(reactions[i], 0.0), kSlipping, rhs);
    ++decided;
  }
  return decided;
}

PetscInt Friction::Update(const std::vector<PetscReal> &reactions, size_t num_contacts,
                          PetscScalar *rhs) {
  if (mode_.size() < num_contacts) mode_.resize(num_contacts, kUndecided);
  if (releases_.size() < num_contacts) releases_.resize(num_contacts, 0);
  const size_t solved_pairs = sticking_contact_.size();
  PetscInt changed = FollowSlips(reactions, rhs);
  const bool observed = observed_.size() >= num_contacts;  // else no velocities seen
  if (observed) changed += SteerSlips(rhs);
  changed += ReleaseSticking(reactions, num_contacts, solved_pairs, rhs);
  if (observed) changed += DecideNewContacts(reactions, num_contacts, rhs);
  return changed;
}

}  // namespace softbody
