// Coulomb friction of the contacts (-friction mu), lambda a contact's normal
// impulse (N s) and m its vertex mass (kg):
// - sliding: a contact loses at most mu lambda / m of its tangential velocity
//   relative to the obstacle after the step (the velocity response);
// - sticking: a contact that this left at rest relative to the obstacle gets,
//   in the next step's solve, two tangent constraints (Stick) holding it to
//   the obstacle, so the whole body feels the friction;
// - slipping: when a sticking contact's tangential reaction exceeds
//   mu lambda, its tangents are dropped and the impulse mu lambda along their
//   reaction enters the right-hand side (ReleaseSlipping), following lambda
//   over the solve rounds. Not collective.
#pragma once

#include <petscvec.h>

#include <cstddef>
#include <vector>

#include "contact/obstacles.hpp"
#include "solvers/projected_solve.hpp"

namespace softbody {

class Friction {
 public:
  void Setup(double mu) { mu_ = mu; }
  double mu() const { return mu_; }
  // A new step: no tangents, no slips.
  void Clear();
  // Adds the tangent pair of `contact` (vertex `local` at `velocity`, just
  // constrained against the hit) when it sticks: its velocity relative to the
  // obstacle has no tangential part.
  void Stick(PetscInt local, const Point &velocity, const SurfaceHit &hit, size_t contact);
  // After a solve: sticking contacts whose tangential reaction exceeds mu times
  // their normal one slip (into rhs, owned entries), and earlier slips follow
  // their normal reaction. reactions: the solve's, normals first (num_contacts
  // of them), then the tangent pairs. Returns how many changed on this rank.
  PetscInt ReleaseSlipping(const std::vector<PetscReal> &reactions, size_t num_contacts,
                           PetscScalar *rhs);
  // The tangent pairs, in sticking order.
  const std::vector<VelocityConstraint> &tangents() const { return tangents_; }
  // Per contact, whether its friction acted in the solve (held or slipped):
  // the velocity response then adds no sliding friction.
  std::vector<char> InSolve(size_t num_contacts) const;

 private:
  // A released sticking contact: impulse magnitude along direction in rhs.
  struct Slip {
    size_t contact;
    PetscInt vertex;
    Point direction;
    double magnitude;
  };
  // Earlier slips: their impulse follows the latest normal reaction.
  PetscInt FollowSlips(const std::vector<PetscReal> &reactions, PetscScalar *rhs);

  double mu_ = 0;
  std::vector<VelocityConstraint> tangents_;  // (t1, t2) per sticking contact
  std::vector<size_t> sticking_contact_;      // the contact of each pair
  std::vector<char> in_solve_;                // per contact: its friction slipped in the solve
  std::vector<Slip> slips_;
};

}  // namespace softbody
