#include "contact/friction.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace softbody {

namespace {

// Relative tolerance of quantities equal up to round-off: the tangential
// velocity a sticking step leaves, a sticking reaction at the Coulomb limit.
constexpr double kRoundOff = 1e-9;
// A slip's impulse is updated when the normal reaction moved by more than this
// fraction since the last solve round: the rounds' fixed point is reached.
constexpr double kSlipUpdate = 1e-6;

}  // namespace

void Friction::Clear() {
  tangents_.clear();
  sticking_contact_.clear();
  in_solve_.clear();
  slips_.clear();
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
}

std::vector<char> Friction::InSolve(size_t num_contacts) const {
  std::vector<char> in_solve(num_contacts, 0);
  for (const size_t contact : sticking_contact_) in_solve[contact] = 1;
  for (size_t i = 0; i < std::min(num_contacts, in_solve_.size()); ++i)
    if (in_solve_[i]) in_solve[i] = 1;
  return in_solve;
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

PetscInt Friction::ReleaseSlipping(const std::vector<PetscReal> &reactions, size_t num_contacts,
                                   PetscScalar *rhs) {
  in_solve_.resize(num_contacts, 0);
  PetscInt released = FollowSlips(reactions, rhs);
  std::vector<VelocityConstraint> kept_tangents;
  std::vector<size_t> kept_contacts;
  for (size_t k = 0; k < sticking_contact_.size(); ++k) {
    const size_t contact = sticking_contact_[k], first = num_contacts + 2 * k;
    const VelocityConstraint &t1 = tangents_[2 * k], &t2 = tangents_[2 * k + 1];
    const Point impulse = reactions[first] * t1.normal + reactions[first + 1] * t2.normal;
    const double limit = mu_ * std::max(reactions[contact], 0.0);
    if (impulse.norm() <= limit * (1 + kRoundOff)) {
      kept_tangents.insert(kept_tangents.end(), {t1, t2});
      kept_contacts.push_back(contact);
      continue;
    }
    // Kinetic friction for this step: mu lambda_n along the sticking reaction.
    const Point direction = impulse / impulse.norm();
    for (int c = 0; c < 3; ++c) rhs[3 * t1.vertex + c] += limit * direction[c];
    slips_.push_back({contact, t1.vertex, direction, limit});
    in_solve_[contact] = 1;
    ++released;
  }
  tangents_.swap(kept_tangents);
  sticking_contact_.swap(kept_contacts);
  return released;
}

}  // namespace softbody
