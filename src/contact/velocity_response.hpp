// The velocity response after the step's solve, x1 = x0 + dt v1, given the
// constraints' reactions (normal impulses lambda, N s, >= 0 where the obstacle
// pushes):
// - a contact vertex leaves with the two sides' momentum-weighted normal
//   velocity (Contact::normal_velocity), minus sliding friction if the solve
//   rounds ran out before its friction was decided (friction.hpp);
// - restitution (-restitution e): impacts are new contacts closing faster than
//   the bounce speed 2 |g| dt (what gravity adds in a step; slower ones are
//   resting). A body with impacts against the ground or a fixed body bounces
//   like a rigid one, at once: with n the direction of the impacts' normal
//   impulse and u the approach n . V0 < 0 of its centroid at the step's start,
//   a uniform velocity change along n sets its centroid's normal velocity to
//   -e u, so its centroid rises to e^2 of the height it fell from. The change
//   is capped so that the body's kinetic energy stays at most what it had at
//   the step's start (a bounce never gives back more than the fall brought);
//   its deformation keeps vibrating about the centroid. Impacts against a free
//   body give their body back e times their normal impulse J as the uniform
//   velocity change e J / M (M the body's mass), which keeps the pair's momentum;
// - impulse spreading (-impulse_spreading): the momentum m_c dv_c given to a
//   contact vertex c is shared by all vertices j of its body with weights
//   w_j = 1 / (l + |x_j - x_c|)^2 (l the body's mean boundary edge length),
//   m_j dv_j = m_c dv_c w_j / sum_k w_k: the body receives the same impulse,
//   the nearest vertices most of it; without it, each vertex keeps its own dv;
// - last resort: a vertex still inside an obstacle after the step is projected
//   to its surface (ProjectRemaining).
#pragma once

#include <petscvec.h>

#include <cstdint>
#include <utility>
#include <vector>

#include "contact/contact_constraints.hpp"
#include "contact/contact_options.hpp"
#include "contact/free_state.hpp"
#include "contact/friction.hpp"
#include "contact/obstacles.hpp"
#include "contact/resting_contacts.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"

namespace softbody {

// A velocity change dv (m/s) of natural vertex `vertex` of `body` at `position`.
struct Collision {
  int32_t vertex;
  int32_t body;
  Point position, dv;
};

class VelocityResponse {
 public:
  void Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout, const FreeState &state,
             const Obstacles &obstacles, const ContactOptions &options);
  // Not collective. Each contact's velocity change (x, v: this rank's
  // vertices' arrays, v not yet changed); the contacts that rest go into *resting.
  std::vector<Collision> Respond(const ContactConstraints &constraints, const Friction &friction,
                                 const std::vector<PetscReal> &reactions, const PetscScalar *x,
                                 const PetscScalar *v, RestingContacts *resting) const;
  // Not collective. Projects the checked (local, natural) vertices still inside
  // an obstacle to its surface; adds their velocity changes; returns how many.
  PetscInt ProjectRemaining(const std::vector<std::pair<PetscInt, int32_t>> &checked,
                            const ContactConstraints &constraints, PetscScalar *x,
                            const PetscScalar *v, std::vector<Collision> *collisions) const;
  // Not collective. Each collision's dv to its own vertex.
  void Apply(const std::vector<Collision> &collisions, PetscScalar *v) const;
  // Collective. Every rank's collisions, spread over their bodies' vertices.
  PetscErrorCode SpreadImpulses(const std::vector<Collision> &local, Vec v) const;
  // Not collective. The bodies' momenta and kinetic energies at the step's
  // start (v0), this rank's share, for Bounce.
  PetscErrorCode RecordStart(Vec v0);
  // Collective. Restitution (see the file comment); reactions in contact order.
  PetscErrorCode Bounce(const ContactConstraints &constraints,
                        const std::vector<PetscReal> &reactions, Vec v) const;

 private:
  // The velocity change of one contact's vertex: normal response and sliding friction.
  Point ContactVelocityChange(const Contact &contact, const VelocityConstraint &constraint,
                              double reaction, bool friction_in_solve, const Point &position,
                              const Point &velocity) const;
  // Whether the vertex at x (inside an obstacle at hit) is projected out.
  bool ShouldProject(PetscInt local, int32_t natural, const Point &x, const SurfaceHit &hit,
                     const ContactConstraints &constraints) const;
  // Per body, this rank's share of momentum (3) and kinetic energy (1) of
  // velocities v (kPackedMotion numbers per body, added to *sums).
  void AddMotion(const PetscScalar *v, double *sums) const;
  // Body b's uniform velocity change along n (unit) that sets its centroid's
  // normal velocity to target (m/s), capped by its kinetic energy at the
  // step's start; motion: its momentum and kinetic energy, at the start and now.
  double RigidBounce(size_t b, const Point &n, double target, const double *start,
                     const double *now) const;
  // Every rank's collisions on every rank, packed kPackedCollision numbers
  // each: vertex, body, position, dv, the vertex's inverse mass.
  PetscErrorCode AllGather(const std::vector<Collision> &local, std::vector<double> *all) const;
  // A free vertex's weight in spreading an impulse given at `at`: 1 / (l + r)^2,
  // l the body's mean boundary edge, r the distance (m).
  double Weight(int32_t body, int32_t natural, const Point &at) const;
  // The sum of the weights of this rank's vertices of `body`.
  double OwnedWeights(int32_t body, const Point &at) const;
  // Adds to this rank's vertices of `body` their share of `impulse` (N s)
  // given at `at`; total: the weights summed over all the body's free vertices.
  void Spread(int32_t body, const Point &at, const Point &impulse, double total,
              PetscScalar *v) const;

  MPI_Comm comm_ = MPI_COMM_NULL;
  const Scene *scene_ = nullptr;
  const DofLayout *layout_ = nullptr;
  const FreeState *state_ = nullptr;
  const Obstacles *obstacles_ = nullptr;
  ContactOptions options_;
  std::vector<double> start_motion_;  // RecordStart's sums, kPackedMotion per body
};

}  // namespace softbody
