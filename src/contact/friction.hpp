// Coulomb friction of the contacts (-friction mu) inside the implicit step's
// solve, lambda a contact's normal impulse over the step (N s): each contact
// either sticks (its velocity relative to the obstacle has no tangential part)
// with a tangential impulse of at most mu lambda, or slips with the impulse
// mu lambda against its sliding direction. Both act in the solve, so the whole
// body feels them in the step (backward Euler in the friction force too):
// - sticking: two tangent constraints hold the contact to the obstacle
//   (Stick, for contacts resting without tangential velocity at the step's
//   start; and a slip that friction would reverse);
// - slipping: the impulse mu lambda along -t (t the unit tangential velocity
//   relative to the obstacle that the solve without it gave) enters the
//   right-hand side, and follows lambda over the solve rounds;
// - after each solve that added no contact (Update): a contact not yet decided
//   sticks if the solve left it no tangential velocity, else slips; a slip
//   whose impulse reversed the tangential velocity sticks instead; a sticking
//   contact whose tangential reaction exceeds mu lambda slips along that
//   reaction, for the rest of the step (no cycling).
// The contacts' velocities after each solve come in through Observe.
// Friction between two free bodies acts on the constrained vertex only (the
// obstacle's side gets its own contacts). Not collective.
#pragma once

#include <petscvec.h>

#include <cstddef>
#include <vector>

#include "contact/contact_constraints.hpp"
#include "contact/obstacles.hpp"
#include "solvers/projected_solve.hpp"

namespace softbody {

class Friction {
 public:
  void Setup(double mu) { mu_ = mu; }
  double mu() const { return mu_; }
  // A new step: no tangents, no slips, no contact decided.
  void Clear();
  // Adds the tangent pair of `contact` (vertex `local` at `velocity`, just
  // constrained against the hit) when it sticks: its velocity relative to the
  // obstacle has no tangential part.
  void Stick(PetscInt local, const Point &velocity, const SurfaceHit &hit, size_t contact);
  // After a solve: each contact's velocity relative to its obstacle, tangential
  // part (normals, contacts: parallel; v: this rank's vertices' velocities).
  void Observe(const std::vector<VelocityConstraint> &normals, const std::vector<Contact> &contacts,
               const PetscScalar *v);
  // After a solve that added no contact, with its reactions (normals first,
  // num_contacts of them, then the tangent pairs) and the velocities last
  // observed: the decisions of the file comment, slips into rhs (owned
  // entries). Returns how many contacts changed on this rank.
  PetscInt Update(const std::vector<PetscReal> &reactions, size_t num_contacts, PetscScalar *rhs);
  // The tangent pairs, in sticking order.
  const std::vector<VelocityConstraint> &tangents() const { return tangents_; }
  // Per contact, whether its friction acted in the solve (held or slipped):
  // the velocity response then adds no sliding friction.
  std::vector<char> InSolve(size_t num_contacts) const;

 private:
  // What a contact's friction does in this step's solve.
  enum Mode : char {
    kUndecided,  // no friction yet (a new contact, or one sliding at the step's start)
    kSticking,   // held by a tangent pair
    kSlipping,   // impulse mu lambda against its sliding direction
    kReleased,   // slipping after sticking: stays so for the rest of the step
  };
  // A slipping contact: impulse magnitude along direction in rhs.
  struct Slip {
    size_t contact;
    PetscInt vertex;
    Point direction;
    double magnitude;
  };
  // Earlier slips: their impulse follows the latest normal reaction.
  PetscInt FollowSlips(const std::vector<PetscReal> &reactions, PetscScalar *rhs);
  // Sticking contacts beyond mu lambda slip along their reaction.
  PetscInt ReleaseSticking(const std::vector<PetscReal> &reactions, size_t num_contacts,
                           PetscScalar *rhs);
  // Slips that reversed their contact's tangential velocity stick instead.
  PetscInt StickReversedSlips(PetscScalar *rhs);
  // Undecided contacts stick or slip.
  PetscInt DecideNewContacts(const std::vector<PetscReal> &reactions, size_t num_contacts,
                             PetscScalar *rhs);
  void AddTangents(size_t contact);
  void AddSlip(size_t contact, const Point &direction, double magnitude, Mode mode,
               PetscScalar *rhs);

  double mu_ = 0;
  std::vector<VelocityConstraint> tangents_;  // (t1, t2) per sticking contact
  std::vector<size_t> sticking_contact_;      // the contact of each pair
  std::vector<Slip> slips_;
  std::vector<Mode> mode_;  // per contact
  // Per contact, from the last Observe: vertex (local), normal, obstacle
  // velocity, the tangential relative velocity, the speeds' scale |v| + |v_o|
  // and whether the obstacle cannot yield.
  struct Observed {
    PetscInt vertex;
    Point normal, obstacle_velocity, tangential;
    double scale;
    bool immobile;
  };
  std::vector<Observed> observed_;
};

}  // namespace softbody
