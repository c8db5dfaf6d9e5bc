// Collisions, friction and distance constraints of the free bodies.
//
// Collisions are part of the implicit step (solvers/projected_solve.hpp): a
// free vertex that the step's solve would take inside an obstacle gets a
// velocity constraint n . v = n . (s - x0) / dt that ends the step on the
// obstacle's surface (s the surface point, n its outward normal; details in
// contact_constraints.hpp), and the step is solved again with it, so the whole
// body feels the contact in the same step. Obstacles (obstacles.hpp): the
// ground half-space y < y0 (-ground), fixed bodies and the other free bodies;
// fixed bodies' sharp edges and corners also push free faces (-sharp_edges,
// sharp_features.hpp). After the step the velocity response
// (velocity_response.hpp) applies restitution, Coulomb friction (friction.hpp)
// and impulse spreading, and projects what still ends inside an obstacle to
// its surface; contacts that rest stay constrained into the next step
// (resting_contacts.hpp); distance constraints are resolved after that, and the
// collision guard (collision_guard.hpp) last: no surface primitive crosses
// another or its own body's during the step. Contacts end -contact_gap of the
// body's mean boundary edge outside the obstacle, so that resting contacts stay
// clear of the guard's separation. Free bodies placed overlapping are moved
// apart rigidly over the first steps (overlap_separation.hpp).
//
// Units: metres, seconds, kilograms; velocities m/s, impulses N s. Normals
// point out of the obstacle; a normal impulse lambda >= 0 pushes.
//
// Parallel model: each rank detects the contacts of its own vertices. When
// free bodies can collide with each other, and while a free body's box meets
// a fixed body with sharp edges, a rank fetches the halo of other ranks'
// vertices near its own (free_state.hpp: boxes gathered, vertices sent point
// to point) and queries the obstacles its halo holds whole; sharp-edge points
// constrain the rank's own vertices of the triangle they push. Distance
// constraints' vertices are fetched on every rank (a scatter of just them) and
// resolved identically there; impulse spreading sums its weights over ranks.
// The ground alone and fixed bodies away from the free ones need no exchange.
// The guard likewise tests the pairs of its own surface vertices against a
// halo, and shares only the colliding pairs (collision_guard.hpp).
#pragma once

#include <petscvec.h>

#include <array>
#include <string>
#include <utility>
#include <vector>

#include "contact/collision_guard.hpp"
#include "contact/contact_constraints.hpp"
#include "contact/contact_options.hpp"
#include "contact/distance_constraints.hpp"
#include "contact/free_state.hpp"
#include "contact/friction.hpp"
#include "contact/obstacles.hpp"
#include "contact/overlap_separation.hpp"
#include "contact/resting_contacts.hpp"
#include "contact/sharp_features.hpp"
#include "contact/velocity_response.hpp"
#include "fem/mesh_share.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"
#include "solvers/projected_solve.hpp"

namespace softbody {

class ContactMeshes;

struct ContactStatistics {
  PetscInt collisions = 0;         // new vertex contacts, all steps, all ranks
  PetscInt exchanges = 0;          // times the free state's halo or fixed set was exchanged
  PetscInt feature_contacts = 0;   // vertex constraints from fixed bodies' sharp edges
  PetscInt projections = 0;        // last-resort projections, all steps, all ranks
  PetscLogDouble seconds = 0;      // wall time in contact detection and response
  PetscInt constraint_sweeps = 0;  // Gauss-Seidel sweeps, all steps
  PetscInt max_constraint_sweeps = 0;
  PetscReal max_constraint_violation = 0;  // relative, after resolution
};

// A step's motion as contact sees it (PETSc-order vectors): the surfaces move
// straight from `start` (the step's start positions x_n) to x1 = base + h u,
// u the step's unknown velocity (m/s): constraints act on u through this map.
// Backward Euler: base = start, h = dt, u = v1. Other schemes (time_scheme.hpp)
// have their own base and h, and an end velocity v1 that is not u: a vertex
// the guard held or moved then ends with the mean velocity (x1 - x_n) / dt,
// which `mean_velocity_differs` asks for.
struct StepMotion {
  Vec start = nullptr, base = nullptr;
  PetscReal h = 0;   // s
  PetscReal dt = 0;  // the whole step (s)
  bool mean_velocity_differs = false;
};

// Bytes of contact's O(scene) arrays on one rank (ContactSolver::scene_bytes).
struct ContactSceneBytes {
  int64_t free_state = 0;  // FreeState's natural-indexed arrays (its slot map)
  int64_t obstacles = 0;   // the bodies' tets and triangles, indexed by vertex
  int64_t guard = 0;       // the collision guard's surface arrays
  int64_t separation = 0;  // OverlapSeparation's surfaces and fetched positions
};

class ContactSolver {
 public:
  ContactSolver() = default;
  ContactSolver(const ContactSolver &) = delete;
  ContactSolver &operator=(const ContactSolver &) = delete;

  // Collective. Builds only what the scene and options need. scene and layout
  // (its replicated numbering, when contact may need it) must outlive the
  // solver; lumped_mass: per DOF (kg), PETSc order. The meshes are read here
  // only, from the ranks' shares (contact_meshes.hpp); a caller holding the
  // meshes whole may release them after (Scene::ReleaseMeshes); the counts,
  // flags and first vertices stay read.
  PetscErrorCode Setup(MPI_Comm comm, const Scene &scene, const MeshShare &share,
                       const DofLayout &layout, Vec lumped_mass, const ContactOptions &options);
  // Anything to resolve at all.
  bool active() const { return ground_ || body_obstacles_ || !distance_.empty() || guard_on_; }

  // The step's contact protocol (collective calls):
  // 1. BeginStep: the resting contacts of the last step, re-aimed at the surface
  //    for the end positions base + h u0 (u0: the obstacles' velocities).
  PetscErrorCode BeginStep(const StepMotion &motion, Vec u0);
  // 2. After a solve giving u: constrains every unconstrained vertex that
  //    base + h u puts inside an obstacle; *added tells any rank added one.
  PetscErrorCode AddPenetrations(const StepMotion &motion, Vec u, bool *added);
  // The constraints for the solve (owned vertices, local numbering): one normal
  // per contact, in contact order, then two tangents per sticking contact; and
  // how many there are on all ranks (the same on every rank: decides
  // collectively whether the step needs the constrained solve).
  const std::vector<VelocityConstraint> &velocity_constraints() const {
    return constraints_.solve_constraints();
  }
  PetscInt global_constraint_count() const { return constraints_.global_count(); }
  // 2b. After a solve that added no contact: friction decides which contacts
  //    stick (tangent pairs) and which slip (impulses mu lambda_n into rhs, owned
  //    entries), friction.hpp; with friction, contacts that pull leave the
  //    solve; *released tells any rank changed anything.
  PetscErrorCode ReleaseSlipping(const std::vector<PetscReal> &reactions, Vec rhs, bool *released);
  // 2c. After the solves, on x = base + h u: when the collision guard would move
  //    vertices (collision_guard.hpp) on the motion from start to x, their
  //    unknowns are prescribed for the rest of the step, contacts that pull
  //    (reactions from the last solve) are released, and *held tells the step
  //    to solve again, so the body answers them; the guard after the step
  //    (EndStep) has the last word.
  PetscErrorCode HoldGuardedVertices(const StepMotion &motion, Vec x,
                                     const std::vector<PetscReal> &reactions, bool *held);
  // 2d. After a solve with held vertices (reactions: its constraints'): the
  //    held vertices of zones that touch nothing immobile push with reactions
  //    whose sum Delta P (kg m/s) no outside body gave (a zone between free
  //    bodies is internal to them). It is taken back from the bodies those
  //    vertices belong to as one velocity change, u -= Delta P / M (M their
  //    mass; mass: lumped, per DOF), the same for all of them, so their motion
  //    relative to each other stays as the solve left it. Without it a
  //    frictionless resting stack, held by the guard at its blocks' rims in
  //    most steps, drifted sideways (2.6 N along x = z). Delta P's component
  //    along directions in which an immobile obstacle holds one of those
  //    bodies (the span of their immobile constraints' normals) is left to
  //    that obstacle.
  PetscErrorCode CancelHeldImpulse(const std::vector<PetscReal> &reactions, Vec mass, Vec u);
  // 3. After the step's x1, v1 with the constraints' reactions: velocity
  //    response, impulse spreading, resting contacts for the next step,
  //    last-resort projection, distance constraints, and last the collision
  //    guard (collision_guard.hpp) on the motion from start to x. *changed: x or
  //    v modified here.
  PetscErrorCode EndStep(const StepMotion &motion, Vec x, Vec v,
                         const std::vector<PetscReal> &reactions, bool *changed);

  // Checkpoints: the resting contacts carried into the next step, as (natural
  // vertex, obstacle: body, -1 the ground, -2 - f sharp-edge point f) and their reactions
  // (resting_contacts.hpp). Gather: collective, every rank's in rank order, on rank 0 (empty
  // elsewhere). Restore: not collective, each rank keeps its own vertices' entries in the list's
  // order (entries this run's obstacles do not have are dropped); reactions may be empty.
  PetscErrorCode GatherRestingContacts(std::vector<std::array<int32_t, 2>> *all,
                                       std::vector<double> *reactions) const;
  void RestoreRestingContacts(const std::vector<std::array<int32_t, 2>> &all,
                              const std::vector<double> &reactions);

  // Repeating a step (-dt_adapt's rejected substeps): everything a step hands
  // to the next is the resting contacts (BeginStep clears the rest), so a step
  // started again from a restored copy runs as if the first attempt never
  // happened. Not collective; the statistics keep counting the attempt.
  RestingContacts CarriedState() const { return resting_; }
  void RestoreCarriedState(const RestingContacts &carried) { resting_ = carried; }

  const ContactStatistics &statistics() const { return stats_; }
  // The guard's figures (null when it does not run).
  const GuardStatistics *guard_statistics() const {
    return guard_on_ ? &guard_.statistics() : nullptr;
  }
  // Not collective. Bytes this rank sent in the free state's exchanges, and for the guard.
  PetscInt64 exchange_bytes() const { return state_.bytes_sent(); }
  PetscInt64 guard_bytes() const { return guard_on_ ? guard_.bytes_sent() : 0; }
  // Not collective. Bytes this rank holds of the whole scene for contact (the
  // O(scene) arrays; its own and halo shares not counted), by part.
  ContactSceneBytes scene_bytes() const {
    return {state_.SceneBytes(), obstacles_.SceneBytes(), guard_.SceneBytes(),
            separation_.SceneBytes()};
  }
  // Not collective. How often this rank built the free bodies' grids (only
  // when a vertex came within another free body's box or a fixed body's sharp
  // edge within a free body's).
  PetscInt free_grid_builds() const { return obstacles_.free_grid_builds(); }
  bool tracks_free_bodies() const { return track_free_; }
  // Not collective. The fixed tets: this rank's share's bytes and the tets it
  // holds now, how often they were fetched, and the obstacles' queries about
  // points outside their region (0 when KeepFixedRegion does its job).
  const FixedTets &fixed_tets() const { return fixed_tets_; }
  PetscInt fixed_outside_region() const { return obstacles_.outside_region(); }
  size_t num_constraints() const { return distance_.size(); }
  // What Setup built, for the run summary.
  std::string Description() const;

 private:
  // Which parts the scene and options need.
  void DecideParts(const Scene &scene, const DofLayout &layout);
  // Collective. The guard over every body's surface.
  PetscErrorCode SetupGuard(const ContactMeshes &meshes, Vec lumped_mass);
  // What the set-up fetches of the meshes beyond the boundaries (Setup's comments).
  std::vector<int32_t> RestVerticesNeeded(const ContactMeshes &meshes) const;
  std::vector<int32_t> KeysNeeded(const ContactMeshes &meshes) const;
  // Collective. The obstacle bodies, their grids, the fixed tets around this
  // rank's vertices and the sharp features kept.
  PetscErrorCode SetupBodyObstacles(const SharpFeatures::Candidates &candidates,
                                    ContactMeshes &meshes);
  // Positions x + h v of this rank's own vertices (PETSc-order vectors; v null: x).
  struct PositionsAt {
    Vec x = nullptr, v = nullptr;
    PetscReal h = 0;
  };
  // Collective. Fetches the fixed tets again when this rank's own vertices at
  // the positions `at` (none: the free state's, at set-up) leave its region
  // (fixed_tets.hpp), so that every query about a point inside a fixed body
  // finds the tets there.
  PetscErrorCode KeepFixedRegion(const std::vector<PositionsAt> &at);
  // Not collective. Per body, this rank's own vertices' box at `at`, grown by
  // the body's halo reach.
  PetscErrorCode OwnBoxes(const std::vector<PositionsAt> &at, std::vector<Box> *boxes) const;
  // Collective. The fixed tets of fixed_region_, for the obstacles.
  PetscErrorCode FetchFixedTets();
  // The (local, natural) vertices checked against obstacles.
  void CollectCheckedVertices();
  // Collective. The free state and grids that this call needs at x + dt v:
  // gathered when free bodies collide, constraints exist or impulses spread,
  // and, when `features`, while a free body's box meets a fixed body with
  // sharp-edge points or a sharp-edge contact rests (sets features_near_).
  PetscErrorCode Refresh(Vec x, Vec v, PetscReal dt, bool features);
  // Collective. Whether a free body's box at x + dt v meets a fixed body with
  // sharp-edge points, or any rank rests a sharp-edge contact.
  PetscErrorCode FeaturesNear(Vec x, Vec v, PetscReal dt, bool *near);
  PetscErrorCode ExchangeFreeState(Vec x, Vec v, PetscReal dt, const StateNeeds &needs);
  // BeginStep's re-aiming of one resting contact; the sharp-edge ones are
  // shared by all ranks first.
  PetscErrorCode ShareRestingFeatures(std::vector<std::array<int32_t, 2>> *all) const;
  void ReaimFeatureContact(int32_t feature, int32_t natural, PetscInt local, const Point &velocity,
                           PetscReal dt);
  void ReaimVertexContact(PetscInt local, const Contact &contact, const Point &position,
                          const Point &velocity, PetscReal dt);
  PetscErrorCode ReaimRestingContacts(Vec x0, Vec v0, PetscReal dt);
  // CancelHeldImpulse's parts. Collective: Delta P of the held vertices of
  // zones touching nothing immobile, the bodies they belong to, and sum n n^T
  // over those bodies' immobile constraints.
  struct HeldImpulse {
    Point delta_p;               // kg m/s
    std::vector<char> involved;  // per body
    Eigen::Matrix3d supports;    // sum n n^T
  };
  PetscErrorCode SumHeldImpulse(const std::vector<PetscReal> &reactions,
                                HeldImpulse *impulse) const;
  // delta_p less its components along the eigenvectors of supports that
  // carry support (kSupportedShare in contact.cpp).
  static Point UnsupportedPart(const Point &delta_p, const Eigen::Matrix3d &supports);
  // The body of an owned vertex (local number).
  size_t BodyOf(PetscInt local) const;
  // AddPenetrations' vertex checks; returns how many this rank added.
  PetscErrorCode AddVertexPenetrations(Vec x0, Vec v, PetscReal dt, PetscInt *found);
  // EndStep's parts.
  PetscErrorCode RespondToContacts(Vec x, Vec v, const std::vector<PetscReal> &reactions,
                                   bool *changed);
  PetscErrorCode ResolveDistanceConstraints(Vec x, Vec v, const std::vector<char> *pinned);
  // Collective. Free bodies placed overlapping (overlap_separation.hpp): found
  // at the first step's start (x0), moved apart after each step (x) until their
  // surfaces no longer cross.
  PetscErrorCode FindOverlaps(Vec x0);
  PetscErrorCode SeparateOverlaps(Vec x, bool *changed);
  // The guard, and with distance constraints, the constraints again with the
  // vertices it moved pinned, then the guard again (it has the last word).
  PetscErrorCode Guard(Vec x0, Vec x, Vec v, PetscReal dt, bool *changed);
  // With mean_velocity_differs: the vertices held in this step end with the
  // mean velocity (x1 - x_n) / dt (the guard writes it for those it moves).
  PetscErrorCode EndHeldWithMeanVelocity(const StepMotion &motion, Vec x, Vec v);
  // Not collective. The other ranks' corners (natural) of the free boundary
  // triangles at this rank's own vertices (FreeState::SetupRingSet), from the
  // meshes of the set-up.
  std::vector<int32_t> RingNeighbours(const ContactMeshes &meshes) const;

  // Times a public method: the "Contact" event of -log_view and stats_.seconds.
  class Timing {
   public:
    explicit Timing(ContactSolver *solver);
    ~Timing();

   private:
    ContactSolver *solver_;
    PetscLogDouble start_ = 0;
  };
  PetscLogEvent event_ = 0;
  MPI_Comm comm_ = MPI_COMM_NULL;
  const Scene *scene_ = nullptr;
  const DofLayout *layout_ = nullptr;
  ContactOptions options_;
  bool ground_ = false;           // the ground is an obstacle
  bool body_obstacles_ = false;   // bodies are obstacles (a free body meets another body)
  bool free_obstacles_ = false;   // free bodies are obstacles to each other
  bool guard_on_ = false;         // the collision guard runs after each step
  bool holding_ = false;          // this step's solves hold vertices for the guard
  std::vector<PetscInt> held_;    // the local vertices held (repeats possible)
  bool track_free_ = false;       // the free bodies' grids are needed (free or feature obstacles)
  bool exchange_always_ = false;  // every call exchanges (free obstacles, constraints, spreading)
  bool features_near_ = false;    // this call's sharp-edge contacts need the free state
  // The vertices checked against obstacles: (local, natural), this rank's.
  std::vector<std::pair<PetscInt, int32_t>> checked_vertices_;
  FreeState state_;
  FixedTets fixed_tets_;
  std::vector<Box> fixed_region_;  // per body: the region of this rank's fixed tets
  Obstacles obstacles_;
  SharpFeatures features_;
  ContactConstraints constraints_;
  Friction friction_;
  VelocityResponse response_;
  RestingContacts resting_;
  DistanceConstraints distance_;
  CollisionGuard guard_;
  OverlapSeparation separation_;
  bool overlaps_checked_ = false;  // FindOverlaps ran
  ContactStatistics stats_;
};

}  // namespace softbody
