// The contact constraints of one step, built vertex by vertex for the solve
// (owned vertices, local numbering; see solvers/projected_solve.hpp).
//
// Vertex contact: a free vertex that the step would take from x0 to x0 + dt v
// inside an obstacle gets the normal velocity constraint
//   n . v = n . (s - x0) / dt,
// s its closest surface point (against a fixed body, where its path enters it)
// and n that surface's outward normal, so that it ends the step on the
// surface. Against a free body the constraint is two-sided
// (projected_solve.hpp): n . (v - sum_k w_k v_k) >= c on the relative normal
// velocity of the vertex and the face point (w its barycentric weights), which
// takes the vertex from its start height above the face to the gap; the two
// bodies get equal and opposite impulses; the face is the closest one facing
// the vertex (Obstacles::ContactOnBody), and a vertex within the ground's
// margin outside another free body is constrained too. A vertex already inside
// at the start of the step leaves at most kMaxRecoveryPerStep edge lengths per
// step faster than the obstacle; more than that deep inside another free body,
// it only stops sinking. A one-sided contact leaves with the two sides'
// momentum-weighted normal velocity (Contact::normal_velocity); a two-sided one
// with the solve's.
//
// Feature contact: a fixed body's sharp-edge point p (SharpFeatures) that the
// solve would take into a free body's surface triangle (closest point q,
// outward normal n, barycentric weights w) pushes the triangle away along
// m = -n by d = m . (p - q): vertex k of the triangle gets
//   m . v_k = m . v_k' + d_k / dt,  d_k = w_k d / sum_j w_j^2
// (v' the solve's velocity; the sum over the vertices that move), the least
// displacement that moves the triangle's point under p by d. One feature
// constraint per vertex (the larger d_k).
//
// Combine lists the normals in contact order, then the friction tangents, and
// counts them on all ranks. Not collective except Combine.
#pragma once

#include <petscsys.h>

#include <cstddef>
#include <cstdint>
#include <vector>

#include "contact/free_state.hpp"
#include "contact/obstacles.hpp"
#include "contact/sharp_features.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"
#include "solvers/projected_solve.hpp"

namespace softbody {

// The most a vertex found inside an obstacle is moved out per step, as a
// fraction of its body's mean boundary edge length: deeper overlaps come out
// over several steps, since a jump of the whole depth would be a huge strain.
constexpr double kMaxRecoveryPerStep = 0.1;

// A constrained vertex (parallel to the normal constraints).
struct Contact {
  int32_t natural;
  int32_t body;            // obstacle, -1 for the ground
  double normal_velocity;  // n . v after the step's velocity response
  bool impact;             // new this step and closing faster than the bounce speed
  int32_t feature = -1;    // a fixed body's feature point pressing on the vertex's face
  Point obstacle_velocity = Point::Zero();  // the obstacle's surface velocity there (m/s)
  // A resting contact's reaction in the step that found it resting (N s): the
  // next step's two-sided row starts its multiplier there (VelocityConstraint::guess).
  double reaction = 0;
};

class ContactConstraints {
 public:
  // gap: contacts end this fraction of the vertex's body's mean boundary edge
  // outside the obstacle (a feature point that far inside the face).
  void Setup(const Scene &scene, const DofLayout &layout, const FreeState &state,
             const Obstacles &obstacles, const SharpFeatures &features, double gap);
  // A new step: no constraints; impacts closing slower than bounce_speed (m/s)
  // do not bounce.
  void Clear(PetscReal bounce_speed);

  // Constrains owned vertex `local` (at x0, velocity `velocity` from the solve)
  // when x0 + dt velocity lies inside an obstacle it is not yet held by;
  // returns whether it did.
  bool AddVertexPenetration(PetscInt local, int32_t natural, const Point &x0, const Point &velocity,
                            PetscReal dt);
  // Constrains owned vertex `local` (at x0, heading for `predicted`) against the
  // hit (see the file comment); `fresh`: a new contact, which may bounce.
  // guess: the contact's reaction estimate (VelocityConstraint::guess).
  void Constrain(PetscInt local, int32_t natural, const Point &x0, const Point &predicted,
                 const Point &velocity, PetscReal dt, const SurfaceHit &hit, bool fresh,
                 double guess = 0);
  // After a solve: the feature points each free body's predicted surface passes
  // over (the free state gathered at x0 + dt v); returns the constraints added
  // or changed on this rank.
  PetscInt AddFeaturePenetrations(PetscReal dt);
  // Feature point `feature` against the free triangle of the hit, d at most
  // kMaxRecoveryPerStep edge lengths when `limit`; constrains this rank's
  // vertices of the triangle; returns how many constraints it added or changed.
  PetscInt ConstrainFeature(int32_t feature, const SurfaceHit &hit, PetscReal dt, bool fresh,
                            bool limit);

  bool feature_held(int32_t feature) const { return feature_held_[feature]; }
  void hold_feature(int32_t feature) { feature_held_[feature] = 1; }
  // The vertex's feature contact this step (-1: none).
  ptrdiff_t feature_contact(PetscInt local) const { return feature_contact_[local]; }
  const std::vector<Contact> &contacts() const { return contacts_; }
  const std::vector<VelocityConstraint> &normals() const { return normals_; }
  const VertexObstacles &obstacles_of(PetscInt local) const { return constrained_[local]; }

  // Prescribes owned vertex `local`'s whole velocity (m/s) for the rest of the
  // step (the collision guard's zones), overriding its other constraints;
  // a later call for the same vertex replaces the prescription. immobile: its
  // zone touched something immobile (VelocityConstraint::immobile).
  void Hold(PetscInt local, const Point &velocity, bool immobile);
  // After a solve (reactions in contact order, ByContact): releases the vertex
  // contacts that pull (lambda < 0 beyond round-off) for the rest of the step: they leave the
  // solve, and their vertex may be constrained again if it sinks. Friction
  // needs it: a pulling contact holding the body down adds to the others'
  // normal load and so to their friction. Returns how many it released.
  PetscInt ReleasePulling(const std::vector<PetscReal> &reactions);
  bool released(size_t contact) const { return contact < released_.size() && released_[contact]; }
  // The solve's reactions (its constraints' order) in contact order, normals
  // then tangents; a released contact keeps the reaction it was released with.
  std::vector<PetscReal> ByContact(const std::vector<PetscReal> &reactions) const;

  // Collective. The solve's constraints: the normals not released, then `tangents`,
  // then the held vertices' (three each).
  PetscErrorCode Combine(MPI_Comm comm, const std::vector<VelocityConstraint> &tangents);
  const std::vector<VelocityConstraint> &solve_constraints() const { return solve_constraints_; }
  PetscInt global_count() const { return global_count_; }

 private:
  // Whether x0's path to `predicted` enters a fixed obstacle through a face
  // other than the closest one; then *hit becomes that entry.
  void PreferEntry(const Point &x0, const Point &predicted, SurfaceHit *hit) const;
  // The normal velocity that takes x0 to target, limited for a vertex already inside.
  double RecoveryVelocity(int32_t natural, const Point &x0, const Point &target, PetscReal dt,
                          const SurfaceHit &hit) const;
  // Against a free body: *constraint becomes two-sided (projected_solve.hpp),
  // on the relative normal velocity of the vertex and the hit's face point.
  void MakeTwoSided(int32_t natural, const Point &x0, PetscReal dt, const SurfaceHit &hit,
                    VelocityConstraint *constraint) const;
  // Which vertices of the triangle a feature contact moves.
  std::array<bool, 3> MovingVertices(const std::array<int32_t, 4> &triangle, const SurfaceHit &hit,
                                     const Point &m) const;
  // Adds the vertex's feature constraint (push: d_k / dt), or replaces the
  // one it has when pushing harder; returns whether it did.
  bool PlaceFeatureConstraint(const VelocityConstraint &constraint, const Contact &contact,
                              const Point &velocity, double push);
  // Feature points of fixed body f inside free body b; returns constraints changed.
  PetscInt AddFeaturePenetrationsOf(size_t f, size_t b, PetscReal dt);

  const Scene *scene_ = nullptr;
  const DofLayout *layout_ = nullptr;
  const FreeState *state_ = nullptr;
  const Obstacles *obstacles_ = nullptr;
  const SharpFeatures *features_ = nullptr;
  double bounce_speed_ = 0;                  // slower impacts do not bounce (m/s)
  double gap_ = 0;                           // contacts end this many edge lengths outside
  std::vector<VelocityConstraint> normals_;  // parallel to contacts_
  std::vector<Contact> contacts_;
  std::vector<VertexObstacles> constrained_;  // per local vertex
  std::vector<char> feature_held_;            // per feature point: constrained this step
  std::vector<ptrdiff_t> feature_contact_;    // per local vertex: its feature contact (-1: none)
  std::vector<char> released_;                // per contact: left the solve (ReleasePulling)
  std::vector<PetscReal> release_reaction_;   // per contact: its reaction when released
  size_t num_released_ = 0;
  std::vector<VelocityConstraint> held_;  // the held vertices' three axis constraints
  std::vector<ptrdiff_t> held_slot_;      // per local vertex: its first in held_ (-1: none)
  std::vector<VelocityConstraint> solve_constraints_;  // normals not released, tangents, held
  PetscInt global_count_ = 0;
};

}  // namespace softbody
