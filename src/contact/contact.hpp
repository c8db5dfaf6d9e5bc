// Collisions and distance constraints.
//
// Collisions are part of the implicit step (see projected_solve.hpp): a free
// vertex that the step would take inside an obstacle gets a velocity constraint
// n . v = n . (s - x0) / dt, so that it ends the step on the obstacle's surface
// (s its closest surface point, n the surface's outward normal; against a fixed
// body s is where the vertex's path enters it and n that face's normal: near an
// edge the closest surface point of the end point can lie on the neighbouring
// face; a vertex already inside at the start of the step leaves at most a tenth
// of its body's mean edge length per step faster than the obstacle, but more
// than that deep inside another free body it only stops sinking); the step is then
// solved again with the constraint, so the whole body feels the contact in the
// same step. Obstacles: the ground half-space y < y0 (-ground; every free vertex
// is checked), fixed bodies and the other free bodies (their tets tell inside,
// their boundary triangles give the closest surface point; every vertex of the
// free bodies is checked). Detection uses uniform grids over tets and
// triangles, never all pairs. After the step a contact vertex leaves with the
// two sides' momentum-weighted normal velocity; it stays constrained while the
// obstacle pushes it (lambda >= 0, lambda the contact's normal impulse) and is
// released when it would pull. Coulomb friction (-friction mu): a sliding
// contact loses at most mu lambda / m of its tangential velocity relative to the
// obstacle after the step (m the vertex mass), and one that this leaves at rest
// sticks: in the next step's solve two tangent constraints hold it to the
// obstacle, so the whole body feels the friction. If their reaction exceeds
// mu lambda, the contact slips: the tangents are dropped, the impulse mu lambda
// along their reaction enters the right-hand side (following lambda over the
// solve rounds), and the step is solved again. (Friction only after the solve
// stopped a sliding block 47 % late: the stuck contact face let the body slide on.)
// Restitution (-restitution e): new contacts closing faster than 2 |g| dt (what
// gravity adds in a step; slower ones are resting contact) give the body back e
// times the normal impulse J they received, as the uniform velocity change
// e J / M (M the body's mass): a bounce that never adds energy. (A soft body's
// impact lasts several steps and damps part of it: the rebound is below a rigid
// body's e^2 of the fall height.) Whatever still ends inside an obstacle is projected to its
// surface as a last resort.
//
// Sharp edges (-sharp_edges, default on): a free vertex cannot enter a fixed
// face, but a fixed body's edge or corner can cut into a free body between its
// vertices (the stairway's bunny draped over a step's edge: 1.8 m deep). The
// fixed bodies' real edges (faces meeting at more than 30 degrees, not flush
// with another fixed body) are sampled as points at most half the finest free
// body's mean edge length apart; a point p that the step's solve would take
// into a free body more than 1e-3 of its edge length deep constrains the free
// surface triangle it entered through (on its path relative to the body; if
// it was inside already, the closest one, and it comes out gradually): the
// triangle's point under p moves away from p by the depth d along m, minus
// the triangle's outward normal (ConstrainFeature). The same velocity
// response, resting contacts (re-aimed at the face now closest to p, all of
// its vertices) and friction as a vertex's. A free vertex that its
// constraints could not all keep out of a fixed body or the ground (more than
// three directions) is projected out after the step. Edges are sampled, so a
// free edge can still cross a fixed one between samples.
//
// Impulse spreading (-impulse_spreading): the momentum m_c dv_c that the
// velocity response gives a contact vertex c is shared by all vertices j of its
// body with weights w_j = 1 / (l + |x_j - x_c|)^2 (l the body's mean boundary
// edge length), m_j dv_j = m_c dv_c w_j / sum_k w_k: the body receives the same
// impulse, the nearest vertices most of it.
//
// Distance constraints (-constraints FILE, and -edge_bounds lo,hi on every
// boundary edge of the free bodies), resolved after the step: |x_b - x_a| is kept
// within [lo, hi] x the rest distance by mass-weighted projection of both
// positions along the constraint, with the relative velocity along it removed
// when it points out of the bounds; Gauss-Seidel sweeps until every constraint
// holds to 1e-12 relative (at most 500). Fixed and stray vertices have infinite mass.
//
// Parallel model: the free state is gathered on every rank when free bodies
// collide with each other, constraints exist or impulses spread, and while a
// free body's box meets a fixed body with sharp edges (Refresh); each rank
// then detects the contacts of its own vertices (and every sharp-edge point,
// constraining its own vertices of the triangle), every rank resolves all
// distance constraints identically, and each keeps its own vertices' results.
// The ground alone and fixed bodies away from the free ones need no gather.
#pragma once

#include <petscvec.h>

#include <algorithm>
#include <array>
#include <string>
#include <vector>

#include "contact/geometry.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"
#include "solvers/projected_solve.hpp"

namespace softbody {

struct ContactOptions {
  PetscBool ground = PETSC_FALSE;
  PetscReal ground_y = 0;     // m
  PetscReal restitution = 0;  // e in [0, 1]
  PetscReal friction = 0;     // Coulomb coefficient mu >= 0
  PetscReal gravity = 0;      // |g| (m/s^2), set by the caller: no bounce below 2 |g| dt
  PetscBool impulse_spreading = PETSC_FALSE;
  PetscBool sharp_edges = PETSC_TRUE;  // fixed bodies' edges and corners against free faces
  std::string constraints_path;        // "" = none
  PetscBool edge_bounds = PETSC_FALSE;
  PetscReal edge_lower = 1, edge_upper = 1;  // x rest length
};

// Collective. Reads -ground -restitution -friction -sharp_edges -impulse_spreading -constraints
// -edge_bounds.
PetscErrorCode ProcessContactOptions(MPI_Comm comm, ContactOptions *options);

// A distance constraint between natural vertices a and b: lower <= |x_b - x_a| <= upper (m).
struct DistanceConstraint {
  int32_t a, b;
  double lower, upper;
};

// Reads a constraints file: n, then n lines "m1 v1 m2 v2" (rest distance kept)
// or "m1 v1 m2 v2 lo hi" (within [lo, hi] x rest distance), 0-based mesh and
// vertex indices. Not collective; throws InputError naming file and line.
std::vector<DistanceConstraint> ReadConstraints(const std::string &path, const Scene &scene);

struct ContactStatistics {
  PetscInt collisions = 0;  // new vertex contacts, all steps, all ranks
  PetscInt gathers = 0;     // times the free state was gathered on every rank
  PetscInt feature_contacts =
      0;  // vertex constraints from fixed bodies' sharp edges entering free faces
  PetscInt projections = 0;        // last-resort projections, all steps, all ranks
  PetscLogDouble seconds = 0;      // wall time in contact detection and response
  PetscInt constraint_sweeps = 0;  // Gauss-Seidel sweeps, all steps
  PetscInt max_constraint_sweeps = 0;
  PetscReal max_constraint_violation = 0;  // relative, after resolution
};

class ContactSolver {
 public:
  ContactSolver() = default;
  ContactSolver(const ContactSolver &) = delete;
  ContactSolver &operator=(const ContactSolver &) = delete;
  ~ContactSolver();

  // Collective. Builds only what the scene and options need.
  PetscErrorCode Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout, Vec lumped_mass,
                       const ContactOptions &options);
  // Anything to resolve at all.
  bool active() const { return ground_ || obstacles_ || !constraints_.empty(); }

  // The step's contact protocol (collective calls):
  // 1. BeginStep: the resting contacts of the last step, re-aimed at the surface
  //    for positions x0 (v0: the obstacles' velocities) and step dt.
  PetscErrorCode BeginStep(Vec x0, Vec v0, PetscReal dt);
  // 2. After a solve giving v: constrains every unconstrained vertex that
  //    x0 + dt v puts inside an obstacle; *added tells any rank added one.
  PetscErrorCode AddPenetrations(Vec x0, Vec v, PetscReal dt, bool *added);
  // The constraints for the solve (owned vertices, local numbering): one normal
  // per contact, in contact order, then two tangents per sticking contact; and
  // how many there are on all ranks (the same on every rank: decides
  // collectively whether the step needs the constrained solve).
  const std::vector<VelocityConstraint> &velocity_constraints() const { return solve_constraints_; }
  PetscInt global_constraint_count() const { return global_constraints_; }
  // 2b. After a solve that added no contact: a sticking contact whose tangential
  //    reaction exceeds mu times its normal one slips instead: its tangent pair
  //    is dropped and the Coulomb impulse mu lambda_n along the reaction goes
  //    into rhs (owned entries) for the next solve; *released tells any rank did.
  PetscErrorCode ReleaseSlipping(const std::vector<PetscReal> &reactions, Vec rhs, bool *released);
  // 3. After x1 = x0 + dt v1 with the constraints' reactions: velocity response,
  //    impulse spreading, resting contacts for the next step, last-resort
  //    projection, distance constraints. *changed: x or v modified here.
  PetscErrorCode EndStep(Vec x, Vec v, const std::vector<PetscReal> &reactions, bool *changed);

  // Checkpoints: the resting contacts carried into the next step, as (natural
  // vertex, obstacle body; -1 the ground). Gather: collective, every rank's in
  // rank order, on rank 0 (empty elsewhere). Restore: not collective, each rank
  // keeps its own vertices' entries in the list's order (entries this run's
  // obstacles do not have are dropped).
  PetscErrorCode GatherRestingContacts(std::vector<std::array<int32_t, 2>> *all) const;
  void RestoreRestingContacts(const std::vector<std::array<int32_t, 2>> &all);

  const ContactStatistics &statistics() const { return stats_; }
  // Not collective. How often this rank built the free bodies' grids (only
  // when a vertex came within another free body's box or a fixed body's sharp
  // edge within a free body's).
  PetscInt free_grid_builds() const { return free_grid_builds_; }
  bool tracks_free_bodies() const { return track_free_; }
  size_t num_constraints() const { return constraints_.size(); }
  // What Setup built, for the run summary.
  std::string Description() const;

 private:
  // Where a point meets an obstacle: closest surface point, outward normal, the
  // surface's velocity and inverse mass there (0: fixed or ground), the obstacle
  // (-1: the ground).
  struct SurfaceHit {
    Point point, normal, velocity;
    double inverse_mass;
    int32_t body;
    int32_t triangle = -1;  // index into the obstacle's triangle list (-1: the ground)
    Eigen::Vector3d weights = Eigen::Vector3d::Zero();  // barycentric coordinates of point in it
  };
  // A constrained vertex (parallel to velocity_constraints_).
  struct Contact {
    int32_t natural;
    int32_t body;            // obstacle, -1 for the ground
    double normal_velocity;  // n . v after the step's velocity response
    bool impact;             // new this step and closing faster than bounce_speed_
    int32_t feature = -1;    // a fixed body's feature point pressing on the vertex's face
  };
  struct Collision {  // a velocity response, for impulse spreading
    int32_t vertex;
    int32_t body;
    Point position, dv;
  };
  PetscErrorCode Gather(Vec x, Vec v, PetscReal dt);
  // Collective. The free state and grids that this call needs at x + dt v:
  // gathered when free bodies collide, constraints exist or impulses spread,
  // and, when `features`, while a free body's box meets a fixed body with
  // sharp-edge points or a sharp-edge contact rests (sets features_near_).
  PetscErrorCode Refresh(Vec x, Vec v, PetscReal dt, bool features);
  // Body boxes, and the fixed part's grids; the free part's grids are marked
  // stale and built when a query first needs them (EnsureFreeGrids): while the
  // bodies' boxes stay apart, a step builds none.
  void BuildObstacleGrids(bool fixed_part);
  void EnsureFreeGrids() const;
  // Each tet's box, and the tets' and triangles' grids, at the world positions.
  void BuildGrids(const std::vector<std::array<int32_t, 5>> &tets,
                  const std::vector<std::array<int32_t, 4>> &triangles, std::vector<Box> *tet_boxes,
                  UniformGrid *tet_grid, UniformGrid *triangle_grid) const;
  Point WorldPoint(int32_t n) const {
    return Point(world_x_[3 * n], world_x_[3 * n + 1], world_x_[3 * n + 2]);
  }
  // Per local vertex, the obstacles constraining it this step (-1: the ground).
  struct VertexObstacles {
    int count = 0;
    int32_t obstacle[3];
    bool Has(int32_t o) const {
      return std::find(obstacle, obstacle + count, o) != obstacle + count;
    }
  };
  // The first obstacle other than `body` and those in `skip` that contains p.
  bool FindPenetration(const Point &p, int32_t body, const VertexObstacles &skip,
                       SurfaceHit *hit) const;
  bool ClosestOnBody(const Point &p, int32_t obstacle, SurfaceHit *hit) const;
  // Whether p lies in one of the obstacle body's tets (faces included).
  bool InsideBody(const Point &p, int32_t obstacle) const;
  // The free body's tet holding p with all barycentric coordinates above
  // `margin`, and the body's velocity there; false if none.
  bool LocateInFreeBody(const Point &p, int32_t body, double margin, Point *velocity) const;
  // Where the segment start -> end first enters the obstacle body through its
  // surface (a boundary triangle crossed against its outward normal).
  bool EntryOnBody(const Point &start, const Point &end, int32_t obstacle, SurfaceHit *hit) const;
  // Constrains owned vertex `local` (at x0, heading for `predicted`) against the
  // hit: it ends the step on the plane where the two sides meet, the overlap
  // split by inverse mass (all of it for a fixed obstacle or the ground), and
  // leaves with the two sides' momentum-weighted normal velocity.
  void Constrain(PetscInt local, int32_t natural, const Point &x0, const Point &predicted,
                 const Point &velocity, PetscReal dt, const SurfaceHit &hit, bool fresh);
  // Feature contacts: a fixed body's feature point p that the step would take
  // into a free body's surface triangle (the hit: closest point q, outward
  // normal n, barycentric weights w) pushes the triangle away along m = -n by
  // d = m . (p - q) (at most a tenth of an edge when `limit`): vertex k of the
  // triangle gets m . v_k = m . v_k' + d_k / dt (v' the solve's velocity) with
  // d_k = w_k d / sum_j w_j^2 over the vertices that move (w_k >= 1e-3, and
  // not on a fixed surface facing nearly along m: OnFixedSurface), the least
  // displacement that moves the triangle's point under p by d. One feature
  // constraint per vertex (the larger d_k). Constrains this rank's vertices
  // of the triangle; returns how many constraints it added or changed.
  PetscInt ConstrainFeature(int32_t feature, const SurfaceHit &hit, PetscReal dt, bool fresh,
                            bool limit);
  // After a solve: the feature points each free body's predicted surface passes
  // over; returns the constraints added or changed on this rank.
  PetscInt AddFeaturePenetrations(PetscReal dt);
  // The local index of natural vertex n if this rank owns it, else -1.
  PetscInt LocalOf(int32_t natural) const;
  // The fixed body that feature point `feature` lies on.
  int32_t FeatureBody(int32_t feature) const {
    return static_cast<int32_t>(
        std::upper_bound(feature_begin_.begin(), feature_begin_.end(), feature) -
        feature_begin_.begin() - 1);
  }
  // Whether x lies in or on a fixed body (or the ground) whose surface there
  // faces within kFeatureAngle of direction.
  bool OnFixedSurface(const Point &x, const Point &direction) const;
  PetscErrorCode ProjectRemaining(PetscScalar *x, PetscScalar *v,
                                  std::vector<Collision> *collisions);
  PetscErrorCode SpreadImpulses(const std::vector<Collision> &local, Vec v);
  double ResolveConstraints();

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
  bool ground_ = false, obstacles_ = false, free_obstacles_ = false, gather_ = false;
  std::vector<int32_t> body_of_;           // natural vertex -> body
  std::vector<int32_t> owned_natural_;     // local vertex -> natural vertex
  std::vector<double> inverse_mass_;       // natural vertex (0: fixed or stray)
  std::vector<double> world_x_, world_v_;  // natural, 3 per vertex (free ones gathered)
  VecScatter to_all_ = nullptr;
  Vec all_x_ = nullptr, all_v_ = nullptr;
  // Obstacles: tets and boundary triangles as natural vertex indices + body.
  std::vector<std::array<int32_t, 5>> fixed_tets_, free_tets_;
  std::vector<std::array<int32_t, 4>> fixed_triangles_, free_triangles_;
  UniformGrid fixed_tet_grid_, fixed_triangle_grid_;
  mutable UniformGrid free_tet_grid_, free_triangle_grid_;
  mutable bool free_grids_current_ = false;
  mutable PetscInt free_grid_builds_ = 0;
  std::vector<Box> body_box_;       // broad phase: each obstacle body's bounding box
  std::vector<Box> fixed_tet_box_;  // each obstacle tet's box (cheap rejection)
  mutable std::vector<Box> free_tet_box_;
  std::vector<std::pair<PetscInt, int32_t>>
      query_vertices_;  // owned free-body vertices: (local, natural)
  // Sharp features of the fixed bodies as points (world), grouped by body:
  // body b's are [feature_begin_[b], feature_begin_[b + 1]).
  std::vector<Point> feature_point_;
  std::vector<int32_t> feature_begin_;
  std::vector<char> feature_held_;  // per feature point: constrained this step
  std::vector<ptrdiff_t>
      feature_contact_;            // per local vertex: its feature contact this step (-1: none)
  bool track_free_ = false;        // the free bodies' grids are needed (free or feature obstacles)
  bool gather_always_ = false;     // every call gathers (free obstacles, constraints, spreading)
  bool features_near_ = false;     // this call's sharp-edge contacts need the free state
  std::vector<double> body_edge_;  // mean boundary edge length per body
  std::vector<double> body_mass_;  // total lumped mass per body (kg)
  double bounce_speed_ = 0;        // slower impacts do not bounce (m/s)
  PetscErrorCode Bounce(const std::vector<PetscReal> &reactions, Vec v);
  std::vector<VelocityConstraint> velocity_constraints_;  // normals, parallel to contacts_
  // Static friction: tangent pairs (t1, t2) of sticking contacts, and the contact of each pair.
  std::vector<VelocityConstraint> tangent_constraints_;
  std::vector<size_t> sticking_contact_;
  std::vector<char> friction_in_solve_;  // per contact: its friction acted in the solve
  struct Slip {  // a released sticking contact: impulse magnitude along direction in rhs
    size_t contact;
    PetscInt vertex;
    Point direction;
    double magnitude;
  };
  std::vector<Slip> slips_;
  std::vector<VelocityConstraint> solve_constraints_;  // normals, then tangents
  PetscInt global_constraints_ = 0;
  PetscErrorCode CountConstraints();
  // Adds the tangent pair of the contact just constrained when it sticks: its
  // velocity relative to the obstacle has no tangential part (it stuck in the
  // last step).
  void Stick(PetscInt local, const Point &velocity, const SurfaceHit &hit, size_t contact);
  std::vector<Contact> contacts_;
  std::vector<VertexObstacles> constrained_;           // per local vertex
  std::vector<std::pair<PetscInt, Contact>> resting_;  // kept for the next step
  std::vector<DistanceConstraint> constraints_;
  ContactStatistics stats_;
};

}  // namespace softbody
