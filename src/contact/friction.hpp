// Coulomb friction of the contacts (-friction mu) inside the implicit step's
// solve, lambda a contact's normal impulse over the step (N s): each contact
// either sticks (its velocity relative to the obstacle has no tangential part)
// with a tangential impulse of at most mu lambda, or slips with the impulse
// mu lambda against its sliding direction. Both act in the solve, so the whole
// body feels them in the step (backward Euler in the friction force too):
// - sticking: two tangent constraints hold the contact to the obstacle;
// - slipping: the impulse mu lambda along d enters the right-hand side.
// The contacts' velocities after each solve come in through Observe; after
// each solve that added no contact, Update decides, contact by contact, and the
// step is solved again while anything changed:
// - a contact resting without tangential velocity at the step's start sticks
//   from the first solve on (Stick); any other is undecided in the first solve
//   and then sticks if the solve left it no tangential velocity, else slips
//   against that velocity;
// - a slip's magnitude follows mu lambda; its direction follows the sliding
//   (d = -v_t / |v_t|, when it turned by more than kSlipTurn); a slip whose
//   impulse reversed or stopped the sliding (v_t . d >= 0) sticks instead;
// - a sticking contact whose tangential reaction exceeds mu lambda slips along
//   that reaction. Contacts released together move each other, so such a slip
//   can be reversed in turn and stick again; after kMaxReleases reversed
//   releases it sticks for the rest of the step (it stands at the Coulomb
//   limit: holding it is the dissipative choice), so no contact cycles.
// Friction between two free bodies acts on the constrained vertex only (the
// obstacle's side gets its own contacts). Not collective.
#pragma once

#include <petscvec.h>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "contact/contact_constraints.hpp"
#include "contact/obstacles.hpp"
#include "solvers/projected_solve.hpp"

namespace softbody {

class Friction {
 public:
  // A vertex's lumped mass (kg) by natural index.
  using MassOf = std::function<double(int32_t natural)>;
  void Setup(double mu, MassOf mass_of) {
    mu_ = mu;
    mass_of_ = std::move(mass_of);
  }
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
    kReleased,   // slipping after sticking beyond mu lambda
    kHeld,       // sticking after kMaxReleases reversed releases: for the rest of the step
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
  // Sticking contacts beyond mu lambda slip along their reaction (the first
  // `solved` pairs: those in the last solve).
  PetscInt ReleaseSticking(const std::vector<PetscReal> &reactions, size_t num_contacts,
                           size_t solved, PetscScalar *rhs);
  // Slips that reversed or stopped their contact's sliding stick instead; the
  // others turn with it.
  PetscInt SteerSlips(PetscScalar *rhs);
  // Undecided contacts stick or slip.
  PetscInt DecideNewContacts(const std::vector<PetscReal> &reactions, size_t num_contacts,
                             PetscScalar *rhs);
  void AddTangents(size_t contact, Mode mode);
  void AddSlip(size_t contact, const Point &direction, double magnitude, Mode mode,
               PetscScalar *rhs);

  double mu_ = 0;
  MassOf mass_of_;
  std::vector<VelocityConstraint> tangents_;  // (t1, t2) per sticking contact
  std::vector<size_t> sticking_contact_;      // the contact of each pair
  std::vector<Slip> slips_;
  std::vector<Mode> mode_;      // per contact
  std::vector<char> releases_;  // per contact: its releases from sticking this step
  // Per contact, from the last Observe: vertex (local), normal, obstacle
  // velocity, the tangential relative velocity, the speeds' scale |v| + |v_o|,
  // the vertex's mass (kg) and whether the obstacle cannot yield.
  struct Observed {
    PetscInt vertex;
    Point normal, obstacle_velocity, tangential;
    double scale, mass;
    bool immobile;
  };
  std::vector<Observed> observed_;
};

}  // namespace softbody
