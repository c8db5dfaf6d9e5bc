#include "contact/contact.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cstdio>

#include "common/exchange.hpp"
#include "contact/contact_meshes.hpp"

namespace softbody {

namespace {

// Impacts closing slower than this many times |g| dt are resting contacts and
// do not bounce: a resting body approaches by about what gravity adds in one
// step, |g| dt; twice that separates impacts from resting contact with margin.
constexpr double kBounceSpeedInGravitySteps = 2;
// Rounds of distance constraints (with the vertices the guard moved pinned)
// and guard after the first guard of a step: each round pins more vertices, so
// the constraints' violation shrinks; the guard always ends the step.
constexpr int kMaxGuardConstraintRounds = 4;
// A vertex within this fraction of the contact gap above the ground is
// constrained back to the gap: resting contacts stay between half the gap and
// the gap, above the guard's separation (a quarter of it).
constexpr double kGroundMarginOfGap = 0.5;
// A direction carries immobile support when sum n n^T over the supporting
// constraints' normals n has an eigenvalue above this share of its largest
// along it: normals within about 6 degrees of each other (sin^2 6 deg = 1e-2)
// count as one direction, so a body on a gently curved contact is not taken to
// be held sideways.
constexpr double kSupportedShare = 1e-2;
// A rank's region of fixed tets is the box its own vertices need grown by this
// fraction of the box's largest side on every side: a body then moves about a
// quarter of its part's size between fetches, and the region holds about
// (1.5)^3 = 3.4 times the part's box.
constexpr double kRegionGrowth = 0.25;
// What a fixed tet held costs a rank's peak (B), as -contact_fixed_replicate_mb
// counts it: the tet (28 B), its box (48 B), its place in the grid (about 2
// cells of 8 B), its corners' positions in the free state (about 1/5 corner
// per tet at 64 B a slot), and the fetch's records while they travel.
// Measured: a 960 000-tet slab held whole on 2 ranks peaked 116 MB above the
// same held by region (12 696 tets), its share (21 MB) freed: about 140 B.
constexpr double kHeldBytesPerFixedTet = 140;
constexpr double kBytesPerMB = 1e6;  // as the run summary counts them

Box Grown(const Box &box, double margin) {
  Box grown = box;
  grown.lower.array() -= margin;
  grown.upper.array() += margin;
  return grown;
}

}  // namespace

ContactSolver::Timing::Timing(ContactSolver *solver) : solver_(solver) {
  PetscCallVoid(PetscLogEventBegin(solver->event_, 0, 0, 0, 0));
  PetscCallVoid(PetscTime(&start_));
}

ContactSolver::Timing::~Timing() {
  PetscLogDouble end;
  PetscCallVoid(PetscTime(&end));
  solver_->stats_.seconds += end - start_;
  PetscCallVoid(PetscLogEventEnd(solver_->event_, 0, 0, 0, 0));
}

PetscErrorCode ContactSolver::Setup(MPI_Comm comm, const Scene &scene, const MeshShare &share,
                                    const DofLayout &layout, Vec lumped_mass,
                                    const ContactOptions &options) {
  PetscFunctionBeginUser;
  PetscClassId class_id;
  PetscCall(PetscClassIdRegister("softbody contact", &class_id));
  PetscCall(PetscLogEventRegister("Contact", class_id, &event_));
  comm_ = comm;
  scene_ = &scene;
  layout_ = &layout;
  options_ = options;
  DecideParts(scene, layout);
  if (!ContactMayRun(options, scene.bodies.size())) PetscFunctionReturn(PETSC_SUCCESS);
  PetscCheck(static_cast<PetscInt>(layout.petsc_of_natural.size()) == scene.num_vertices(), comm,
             PETSC_ERR_PLIB,
             "contact needs the replicated numbering on every rank (ContactMayRun)");
  ContactMeshes meshes;
  PetscCall(meshes.Build(comm, scene, layout, share));
  PetscCall(meshes.FetchRest(RestVerticesNeeded(meshes)));
  PetscCall(distance_.Setup(comm, scene, &meshes, options));
  if (!active()) PetscFunctionReturn(PETSC_SUCCESS);
  if (body_obstacles_) PetscCall(meshes.FetchFreeTets(KeysNeeded(meshes)));

  state_.SetupBodies(scene, meshes, options.halo_reach);
  SharpFeatures::Candidates candidates;
  if (body_obstacles_ && options.sharp_edges)
    candidates = SharpFeatures::Sample(scene, state_, meshes);
  track_free_ = free_obstacles_ || !candidates.empty();
  exchange_always_ = free_obstacles_ || !distance_.empty() || options.impulse_spreading;
  PetscCall(state_.SetupMasses(comm, layout, lumped_mass, track_free_, !candidates.empty()));
  if (!distance_.empty()) PetscCall(state_.SetupFixedSet(lumped_mass, distance_.vertices()));
  // Vertices come back to the contact gap once within half of it of the ground.
  obstacles_.SetupGround(scene, state_, ground_, options.ground_y,
                         kGroundMarginOfGap * options.gap);
  if (body_obstacles_) PetscCall(SetupBodyObstacles(candidates, meshes));
  if (free_obstacles_) PetscCall(state_.SetupRingSet(lumped_mass, RingNeighbours(meshes)));
  meshes.ReleaseFreeTets();  // the free items have taken theirs
  CollectCheckedVertices();
  constraints_.Setup(scene, layout, state_, obstacles_, features_, options.gap);
  friction_.Setup(options.friction, [this](int32_t n) { return 1 / state_.inverse_mass(n); });
  response_.Setup(comm, scene, layout, state_, obstacles_, options);
  if (guard_on_) PetscCall(SetupGuard(meshes, lumped_mass));
  if (free_obstacles_) separation_.Setup(comm, scene, meshes, state_, &obstacles_);
  state_.EndSetup();
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The vertices whose rest positions the set-up reads (the fixed tets bring
// their own corners): this rank's own, every body's surface vertices (the
// guard, the mean boundary edges, the edge bounds, the fixed triangles and
// sharp features) and the free bodies' vertices without unknowns (stray
// vertices no tet names).
std::vector<int32_t> ContactSolver::RestVerticesNeeded(const ContactMeshes &meshes) const {
  std::vector<int32_t> naturals(layout_->natural_of_owned.begin(), layout_->natural_of_owned.end());
  for (size_t b = 0; b < scene_->bodies.size(); ++b) {
    const Body &body = scene_->bodies[b];
    const auto &boundary = meshes.boundary(b);
    for (Eigen::Index k = 0; k < boundary.size(); ++k)
      naturals.push_back(body.first_vertex + boundary.data()[k]);
    if (body.fixed) continue;
    for (int32_t v = body.first_vertex; v < body.first_vertex + body.num_vertices(); ++v)
      if (layout_->PetscVertexOfNatural(v) < 0) naturals.push_back(v);
  }
  return naturals;
}

// The key vertices whose free tets this rank may keep (FreeState::SetupItems):
// its own, the distance constraints' and the ring set (RingNeighbours).
std::vector<int32_t> ContactSolver::KeysNeeded(const ContactMeshes &meshes) const {
  std::vector<int32_t> keys = distance_.vertices(), ring = RingNeighbours(meshes);
  keys.insert(keys.end(), layout_->natural_of_owned.begin(), layout_->natural_of_owned.end());
  keys.insert(keys.end(), ring.begin(), ring.end());
  return keys;
}

std::vector<int32_t> ContactSolver::RingNeighbours(const ContactMeshes &meshes) const {
  std::vector<int32_t> owned(layout_->natural_of_owned.begin(), layout_->natural_of_owned.end()),
      ring;
  std::sort(owned.begin(), owned.end());
  auto own = [&](int32_t n) { return std::binary_search(owned.begin(), owned.end(), n); };
  for (size_t b = 0; b < scene_->bodies.size(); ++b) {
    const Body &body = scene_->bodies[b];
    if (body.fixed) continue;
    const auto &boundary = meshes.boundary(b);
    for (Eigen::Index f = 0; f < boundary.rows(); ++f) {
      const int32_t corners[3] = {body.first_vertex + boundary(f, 0),
                                  body.first_vertex + boundary(f, 1),
                                  body.first_vertex + boundary(f, 2)};
      if (std::none_of(corners, corners + 3, own)) continue;
      for (const int32_t c : corners)
        if (!own(c)) ring.push_back(c);
    }
  }
  return ring;
}

PetscErrorCode ContactSolver::SetupGuard(const ContactMeshes &meshes, Vec lumped_mass) {
  PetscFunctionBeginUser;
  double min_edge = kUnbounded;
  for (size_t b = 0; b < scene_->bodies.size(); ++b)
    if (!scene_->bodies[b].fixed) min_edge = std::min(min_edge, state_.edge(b));
  std::vector<double> reach(scene_->bodies.size());
  for (size_t b = 0; b < reach.size(); ++b) reach[b] = state_.reach(b);
  PetscCall(guard_.Setup(comm_, *scene_, meshes, *layout_, lumped_mass, options_,
                         options_.self_contact, min_edge, reach));
  const PetscInt close = guard_.statistics().initial_close_pairs;
  if (close > 0)
    PetscCall(PetscPrintf(comm_,
                          "softbody: warning: %" PetscInt_FMT
                          " surface pairs start closer than the contact separation %.3g m "
                          "(bodies placed touching or overlapping): the collision guard leaves "
                          "them to the contact constraints until they part, and does not untangle "
                          "surfaces that start crossing\n",
                          close, guard_.separation()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

void ContactSolver::DecideParts(const Scene &scene, const DofLayout &layout) {
  int free_bodies = 0, fixed_bodies = 0;
  for (const Body &body : scene.bodies) (body.fixed ? fixed_bodies : free_bodies)++;
  ground_ = options_.ground && layout.num_free() > 0;
  body_obstacles_ =
      free_bodies >= 1 && (fixed_bodies >= 1 || free_bodies >= 2) && layout.num_free() > 0;
  free_obstacles_ = body_obstacles_ && free_bodies >= 2;
  const bool lone_self_contact = options_.self_contact_set && options_.self_contact;
  guard_on_ =
      options_.guard && layout.num_free() > 0 && (ground_ || body_obstacles_ || lone_self_contact);
}

PetscErrorCode ContactSolver::SetupBodyObstacles(const SharpFeatures::Candidates &candidates,
                                                 ContactMeshes &meshes) {
  PetscFunctionBeginUser;
  obstacles_.SetupBodies(track_free_, meshes);
  fixed_tets_.Setup(comm_, meshes.TakeFixedShare(), meshes.num_fixed_tets());
  PetscCall(features_.Keep(candidates, *scene_, state_, fixed_tets_));
  fixed_region_.assign(scene_->bodies.size(), Box());
  PetscCall(KeepFixedRegion({}));  // around the owned vertices at rest
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Each rank's region holds, per free body, its own vertices at every position
// given, grown by the body's halo reach (the halo's vertices and the faces at
// own vertices lie within it); when a rank's vertices leave it, every rank
// sets its region to that box grown by kRegionGrowth of its largest side, and
// the fixed tets are fetched again. When the fixed tets are small
// (-contact_fixed_replicate_mb) or on one rank, the region is everything:
// they are fetched once, and the shares then freed.
PetscErrorCode ContactSolver::KeepFixedRegion(const std::vector<PositionsAt> &at) {
  PetscFunctionBeginUser;
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  const bool everything = size == 1 || fixed_tets_.scene_count() * kHeldBytesPerFixedTet <=
                                           options_.fixed_replicate_mb * kBytesPerMB;
  if (fixed_tets_.scene_count() == 0 || (everything && fixed_tets_.fetches() > 0))
    PetscFunctionReturn(PETSC_SUCCESS);
  std::vector<Box> needed;
  PetscCall(OwnBoxes(at, &needed));
  int leaves = 0;
  for (size_t b = 0; b < needed.size(); ++b)
    leaves = leaves || (!needed[b].Empty() && !(fixed_region_[b].Contains(needed[b].lower) &&
                                                fixed_region_[b].Contains(needed[b].upper)));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &leaves, 1, MPI_INT, MPI_MAX, comm_));
  if (!leaves) PetscFunctionReturn(PETSC_SUCCESS);
  Box all;
  all.lower = Point::Constant(-kUnbounded);
  all.upper = Point::Constant(kUnbounded);
  for (size_t b = 0; b < needed.size(); ++b) {
    const double growth = kRegionGrowth * (needed[b].upper - needed[b].lower).maxCoeff();
    fixed_region_[b] = needed[b].Empty() ? Box() : everything ? all : Grown(needed[b], growth);
  }
  PetscCall(FetchFixedTets());
  if (everything) fixed_tets_.ReleaseShare();  // no rank will ask for it again
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Per body, the box of this rank's own vertices at the positions `at` (none:
// the free state's), grown by the body's halo reach.
PetscErrorCode ContactSolver::OwnBoxes(const std::vector<PositionsAt> &at,
                                       std::vector<Box> *boxes) const {
  PetscFunctionBeginUser;
  std::vector<Box> &needed = *boxes;
  needed.assign(scene_->bodies.size(), Box());
  const auto &owned = state_.owned_natural();
  if (at.empty())
    for (const int32_t n : owned) needed[state_.body_of(n)].Extend(state_.position(n));
  for (const PositionsAt &positions : at) {
    const PetscScalar *x, *v = nullptr;
    PetscCall(VecGetArrayRead(positions.x, &x));
    if (positions.v) PetscCall(VecGetArrayRead(positions.v, &v));
    for (size_t p = 0; p < owned.size(); ++p) {
      Point q(&x[3 * p]);
      if (v) q += positions.h * Point(&v[3 * p]);
      needed[state_.body_of(owned[p])].Extend(q);
    }
    PetscCall(VecRestoreArrayRead(positions.x, &x));
    if (v) PetscCall(VecRestoreArrayRead(positions.v, &v));
  }
  for (size_t b = 0; b < needed.size(); ++b)
    if (!needed[b].Empty()) needed[b] = Grown(needed[b], state_.reach(b));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::FetchFixedTets() {
  PetscFunctionBeginUser;
  bool changed;
  PetscCall(fixed_tets_.Fetch(
      fixed_region_,
      [&](const FreeTet &tet) {
        Box box;
        for (int k = 0; k < 4; ++k) box.Extend(state_.position(tet[k]));
        return box;
      },
      [&](int32_t n, const Point &x) { state_.PlaceFixed(n, x); }, &changed));
  if (changed || fixed_tets_.fetches() == 1) obstacles_.SetFixedTets(fixed_tets_);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Every owned vertex, interior ones too (a soft body hitting hard can push them
// through its surface): the owned vertices are the free bodies' vertices.
void ContactSolver::CollectCheckedVertices() {
  for (PetscInt local = 0; local < state_.local_count(); ++local)
    checked_vertices_.push_back({local, state_.owned_natural()[local]});
}

std::string ContactSolver::Description() const {
  std::string text;
  auto add = [&](const std::string &part) { text += (text.empty() ? "" : ", ") + part; };
  char buffer[64];
  if (ground_) {
    std::snprintf(buffer, sizeof(buffer), "ground at y = %g m", options_.ground_y);
    add(buffer);
  }
  if (body_obstacles_)
    add(std::to_string(obstacles_.num_fixed_tets()) + " fixed and " +
        std::to_string(obstacles_.num_free_tets()) + " moving obstacle tets in uniform grids");
  if (!features_.empty())
    add(std::to_string(features_.size()) + " points on fixed bodies' sharp edges");
  if (!distance_.empty()) add(std::to_string(distance_.size()) + " distance constraints");
  if (guard_on_) add(guard_.Description());
  if (separation_.initial_pairs() > 0)
    add(std::to_string(separation_.initial_pairs()) + " pair(s) of bodies placed overlapping, " +
        (separation_.active() ? "still separating after " : "separated in ") +
        std::to_string(separation_.steps()) + " steps");
  if (active() && options_.impulse_spreading) add("impulse spreading");
  if (active() && (ground_ || body_obstacles_)) {
    std::snprintf(buffer, sizeof(buffer), "restitution %g, friction %g", options_.restitution,
                  options_.friction);
    add(buffer);
  }
  return text;
}

PetscErrorCode ContactSolver::Refresh(Vec x, Vec v, PetscReal dt, bool features) {
  PetscFunctionBeginUser;
  features_near_ = false;
  if (features && !features_.empty()) PetscCall(FeaturesNear(x, v, dt, &features_near_));
  const StateNeeds needs{free_obstacles_ || features_near_, !distance_.empty(), free_obstacles_};
  if (exchange_always_ || features_near_) PetscCall(ExchangeFreeState(x, v, dt, needs));
  if (needs.halo) obstacles_.MoveFreeBodies();
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Each free body's box at x + dt v: the owned vertices' boxes, reduced with
// MPI_MAX over -lower and upper; one more entry tells a resting sharp-edge contact.
PetscErrorCode ContactSolver::FeaturesNear(Vec x, Vec v, PetscReal dt, bool *near) {
  PetscFunctionBeginUser;
  const size_t bodies = scene_->bodies.size();
  std::vector<double> bounds(6 * bodies + 1, -kUnbounded);
  const PetscScalar *ax, *av;
  PetscCall(VecGetArrayRead(x, &ax));
  PetscCall(VecGetArrayRead(v, &av));
  for (size_t p = 0; p < state_.owned_natural().size(); ++p) {
    const size_t b = state_.body_of(state_.owned_natural()[p]);
    for (int c = 0; c < 3; ++c) {
      const double at = ax[3 * p + c] + dt * av[3 * p + c];
      bounds[6 * b + c] = std::max(bounds[6 * b + c], -at);
      bounds[6 * b + 3 + c] = std::max(bounds[6 * b + 3 + c], at);
    }
  }
  PetscCall(VecRestoreArrayRead(x, &ax));
  PetscCall(VecRestoreArrayRead(v, &av));
  if (resting_.any_feature()) bounds[6 * bodies] = 1;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, bounds.data(), static_cast<int>(bounds.size()),
                             MPI_DOUBLE, MPI_MAX, comm_));
  *near = bounds[6 * bodies] > 0;
  for (size_t b = 0; b < bodies && !*near; ++b) {
    if (scene_->bodies[b].fixed) continue;
    Box box;
    box.lower = -Point(&bounds[6 * b]);
    box.upper = Point(&bounds[6 * b + 3]);
    for (size_t f = 0; f < bodies && !*near; ++f)
      *near = features_.on_body(f) && obstacles_.body_box(f).Overlaps(box);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::ExchangeFreeState(Vec x, Vec v, PetscReal dt,
                                                const StateNeeds &needs) {
  PetscFunctionBeginUser;
  if (needs.halo || needs.fixed_set) ++stats_.exchanges;
  PetscCall(state_.Exchange(x, v, dt, needs));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::BeginStep(const StepMotion &motion, Vec u0) {
  PetscFunctionBeginUser;
  Timing timing(this);
  friction_.Clear();
  constraints_.Clear(kBounceSpeedInGravitySteps * options_.gravity * motion.h);
  holding_ = false;
  held_.clear();
  if (!ground_ && !body_obstacles_) PetscFunctionReturn(PETSC_SUCCESS);
  if (body_obstacles_) PetscCall(KeepFixedRegion({{motion.start}, {motion.base, u0, motion.h}}));
  if (options_.restitution > 0) PetscCall(response_.RecordStart(u0));
  if (free_obstacles_ && !overlaps_checked_) PetscCall(FindOverlaps(motion.start));
  // Obstacles where they will be if they keep their velocity.
  PetscCall(Refresh(motion.base, u0, motion.h, true));
  PetscCall(ReaimRestingContacts(motion.base, u0, motion.h));
  PetscCall(constraints_.Combine(comm_, friction_.tangents()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::ReaimRestingContacts(Vec x0, Vec v0, PetscReal dt) {
  PetscFunctionBeginUser;
  const PetscScalar *x, *v;
  PetscCall(VecGetArrayRead(x0, &x));
  PetscCall(VecGetArrayRead(v0, &v));
  for (const auto &[local, contact] : resting_.entries())
    if (contact.feature < 0)
      ReaimVertexContact(local, contact, Point(&x[3 * local]), Point(&v[3 * local]), dt);
  if (!features_.empty()) {
    std::vector<std::array<int32_t, 2>> features;
    PetscCall(ShareRestingFeatures(&features));
    for (const auto &[feature, natural] : features) {
      const PetscInt local = layout_->LocalOfNatural(natural);
      ReaimFeatureContact(feature, natural, local,
                          local >= 0 ? Point(&v[3 * local]) : Point(Point::Zero()), dt);
    }
  }
  PetscCall(VecRestoreArrayRead(x0, &x));
  PetscCall(VecRestoreArrayRead(v0, &v));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Every rank's resting sharp-edge contacts as (feature, natural vertex),
// sorted: each rank re-aims them all for its own vertices of the face, so a
// face split between ranks is held as on one rank.
PetscErrorCode ContactSolver::ShareRestingFeatures(std::vector<std::array<int32_t, 2>> *all) const {
  PetscFunctionBeginUser;
  std::vector<std::array<int32_t, 2>> mine;
  for (const auto &[local, contact] : resting_.entries())
    if (contact.feature >= 0) mine.push_back({contact.feature, contact.natural});
  PetscCall(AllGatherRecords(comm_, mine, all));
  std::sort(all->begin(), all->end());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The feature point against the face now closest to it, once per step, when
// that face holds the resting vertex `natural`: all of this rank's vertices of
// the face, also those whose own contact was released (pushing only the
// resting one would let the edge sink into the face). local: the resting
// vertex's on this rank (-1: another rank's), velocity its velocity (m/s).
void ContactSolver::ReaimFeatureContact(int32_t feature, int32_t natural, PetscInt local,
                                        const Point &velocity, PetscReal dt) {
  SurfaceHit hit;
  if (constraints_.feature_held(feature) ||
      !obstacles_.ClosestOnBody(features_.point(feature), state_.body_of(natural), &hit))
    return;
  const auto &triangle = hit.face;
  if (std::find(triangle.begin(), triangle.begin() + 3, natural) == triangle.begin() + 3) return;
  constraints_.hold_feature(feature);
  const bool unconstrained = local >= 0 && constraints_.feature_contact(local) < 0;
  constraints_.ConstrainFeature(feature, hit, dt, false, true);
  const bool appended = unconstrained && constraints_.feature_contact(local) >= 0;
  SurfaceHit fixed_side = hit;  // the feature's side: immobile, facing the vertex
  fixed_side.normal = -hit.normal;
  fixed_side.velocity = Point::Zero();
  fixed_side.inverse_mass = 0;
  if (appended && options_.friction > 0)
    friction_.Stick(local, velocity, fixed_side, constraints_.feature_contact(local));
}

void ContactSolver::ReaimVertexContact(PetscInt local, const Contact &contact,
                                       const Point &position, const Point &velocity, PetscReal dt) {
  SurfaceHit hit;
  if (!obstacles_.ContactOnBody(position + dt * velocity, contact.natural, contact.body, &hit))
    return;
  constraints_.Constrain(local, contact.natural, position, position + dt * velocity, velocity, dt,
                         hit, false, contact.reaction);
  if (options_.friction > 0)
    friction_.Stick(local, velocity, hit, constraints_.contacts().size() - 1);
}

PetscErrorCode ContactSolver::AddPenetrations(const StepMotion &motion, Vec u, bool *added) {
  PetscFunctionBeginUser;
  Timing timing(this);
  *added = false;
  if (!ground_ && !body_obstacles_) PetscFunctionReturn(PETSC_SUCCESS);
  if (body_obstacles_) PetscCall(KeepFixedRegion({{motion.start}, {motion.base, u, motion.h}}));
  PetscCall(Refresh(motion.base, u, motion.h, true));
  PetscInt local_found[2] = {0, 0}, all_found[2];
  PetscCall(AddVertexPenetrations(motion.base, u, motion.h, &local_found[0]));
  // Feature points: every rank sees all (gathered positions) and constrains its own vertices.
  if (features_near_) local_found[1] = constraints_.AddFeaturePenetrations(motion.h);
  PetscCallMPI(MPIU_Allreduce(local_found, all_found, 2, MPIU_INT, MPI_SUM, comm_));
  stats_.collisions += all_found[0];
  stats_.feature_contacts += all_found[1];
  *added = all_found[0] + all_found[1] > 0;
  if (*added) PetscCall(constraints_.Combine(comm_, friction_.tangents()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// A vertex can be held by up to three obstacles (a corner); each adds one.
PetscErrorCode ContactSolver::AddVertexPenetrations(Vec x0, Vec v, PetscReal dt, PetscInt *found) {
  PetscFunctionBeginUser;
  const PetscScalar *x, *lv;
  PetscCall(VecGetArrayRead(x0, &x));
  PetscCall(VecGetArrayRead(v, &lv));
  for (const auto &[local, natural] : checked_vertices_)
    if (constraints_.AddVertexPenetration(local, natural, Point(&x[3 * local]),
                                          Point(&lv[3 * local]), dt))
      ++*found;
  if (options_.friction > 0) friction_.Observe(constraints_.normals(), constraints_.contacts(), lv);
  PetscCall(VecRestoreArrayRead(x0, &x));
  PetscCall(VecRestoreArrayRead(v, &lv));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::ReleaseSlipping(const std::vector<PetscReal> &reactions, Vec rhs,
                                              bool *released) {
  PetscFunctionBeginUser;
  Timing timing(this);
  // With friction, pulling contacts leave the solve: friction needs the true normal load.
  const std::vector<PetscReal> by_contact = constraints_.ByContact(reactions);
  PetscInt local_released = options_.friction > 0 ? constraints_.ReleasePulling(by_contact) : 0;
  PetscScalar *b;
  PetscCall(VecGetArray(rhs, &b));
  local_released += friction_.Update(by_contact, constraints_.contacts().size(), b);
  PetscCall(VecRestoreArray(rhs, &b));
  PetscInt all_released;
  PetscCallMPI(MPIU_Allreduce(&local_released, &all_released, 1, MPIU_INT, MPI_SUM, comm_));
  *released = all_released > 0;
  if (*released) PetscCall(constraints_.Combine(comm_, friction_.tangents()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::HoldGuardedVertices(const StepMotion &motion, Vec x,
                                                  const std::vector<PetscReal> &reactions,
                                                  bool *held) {
  PetscFunctionBeginUser;
  Timing timing(this);
  *held = false;
  if (!guard_on_) PetscFunctionReturn(PETSC_SUCCESS);
  bool moved;
  PetscCall(guard_.Probe(motion.start, x, &moved));
  if (moved) {
    const PetscScalar *base;
    PetscCall(VecGetArrayRead(motion.base, &base));
    for (const auto &[local, end, frozen] : guard_.MovedEnds()) {
      constraints_.Hold(local, (end - Point(&base[3 * local])) / motion.h, frozen);
      held_.push_back(local);
    }
    PetscCall(VecRestoreArrayRead(motion.base, &base));
    holding_ = true;
  }
  // Once vertices are held, contacts aimed at the first prediction may pull.
  PetscInt released = holding_ ? constraints_.ReleasePulling(constraints_.ByContact(reactions)) : 0;
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, &released, 1, MPIU_INT, MPI_SUM, comm_));
  *held = moved || released > 0;
  if (*held) PetscCall(constraints_.Combine(comm_, friction_.tangents()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The velocity change is uniform, not projected off each vertex's constraint
// directions: projected, it strained the bodies and the guard acted more
// (stack, 1 000 steps: kinetic energy 2.4e-2 J linear and 11.9 J corotational
// against 7.4e-3 and 3.1e-2 J uniform). Vertices it moves into an obstacle by
// |Delta P| / M dt (a few 1e-7 m) are the contacts' and the guard's again.
//
// Only Delta P's part that the bodies' supports cannot answer is taken back
// (UnsupportedPart): along a direction in which an immobile obstacle holds one
// of the bodies, that obstacle answers Delta P in the next solve, and taking
// it back as well lifted bodies off the ground. Fertility (two statues on the
// ground, 200 steps, 2 ranks), with the whole of Delta P taken back: guard
// passes 155 -> 725, time loop 14 -> 28 s.
PetscErrorCode ContactSolver::CancelHeldImpulse(const std::vector<PetscReal> &reactions, Vec mass,
                                                Vec u) {
  PetscFunctionBeginUser;
  if (!holding_) PetscFunctionReturn(PETSC_SUCCESS);
  Timing timing(this);
  HeldImpulse impulse;
  PetscCall(SumHeldImpulse(reactions, &impulse));
  const Point taken = UnsupportedPart(impulse.delta_p, impulse.supports);
  if (taken.isZero()) PetscFunctionReturn(PETSC_SUCCESS);
  const PetscInt owned = layout_->local_count();
  std::vector<char> involved(owned);
  for (PetscInt local = 0; local < owned; ++local)
    involved[local] = impulse.involved[BodyOf(local)];
  const PetscScalar *m;
  PetscCall(VecGetArrayRead(mass, &m));
  double total = 0;  // M (kg)
  for (PetscInt local = 0; local < owned; ++local)
    if (involved[local]) total += m[3 * local];
  PetscCall(VecRestoreArrayRead(mass, &m));
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, &total, 1, MPIU_REAL, MPI_SUM, comm_));
  PetscScalar *values;
  PetscCall(VecGetArray(u, &values));
  for (PetscInt local = 0; local < owned; ++local)
    if (involved[local])
      for (int k = 0; k < 3; ++k) values[3 * local + k] -= taken[k] / total;
  PetscCall(VecRestoreArray(u, &values));
  PetscFunctionReturn(PETSC_SUCCESS);
}

size_t ContactSolver::BodyOf(PetscInt local) const {
  const int32_t natural = static_cast<int32_t>(layout_->natural_of_owned[local]);
  size_t b = 0;
  while (b + 1 < scene_->bodies.size() && scene_->bodies[b + 1].first_vertex <= natural) ++b;
  return b;
}

// One reduction of Delta P (3), per body whether it has a held vertex of a
// zone that touched nothing immobile (1), and per body the sum of n n^T over
// its immobile constraints (9).
PetscErrorCode ContactSolver::SumHeldImpulse(const std::vector<PetscReal> &reactions,
                                             HeldImpulse *impulse) const {
  PetscFunctionBeginUser;
  const size_t bodies = scene_->bodies.size();
  std::vector<double> sums(3 + 10 * bodies, 0.0);
  double *involved = &sums[3], *supports = &sums[3 + bodies];
  const std::vector<VelocityConstraint> &constraints = velocity_constraints();
  for (size_t i = 0; i < constraints.size(); ++i) {
    const VelocityConstraint &c = constraints[i];
    const size_t b = BodyOf(c.vertex);
    if (c.immobile) {
      Eigen::Map<Eigen::Matrix3d>(&supports[9 * b]) += c.normal * c.normal.transpose();
    } else if (c.prescribes_all) {
      for (int k = 0; k < 3; ++k) sums[k] += reactions[i] * c.normal[k];
      involved[b] = 1;
    }
  }
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, sums.data(), static_cast<PetscMPIInt>(sums.size()),
                              MPIU_REAL, MPI_SUM, comm_));
  impulse->delta_p = Point(sums[0], sums[1], sums[2]);
  impulse->involved.assign(bodies, 0);
  impulse->supports.setZero();
  for (size_t b = 0; b < bodies; ++b)
    if (involved[b] > 0) {
      impulse->involved[b] = 1;
      impulse->supports += Eigen::Map<const Eigen::Matrix3d>(&supports[9 * b]);
    }
  PetscFunctionReturn(PETSC_SUCCESS);
}

Point ContactSolver::UnsupportedPart(const Point &delta_p, const Eigen::Matrix3d &supports) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(supports);
  const double largest = eigen.eigenvalues().maxCoeff();
  Point unsupported = delta_p;
  for (int k = 0; k < 3; ++k)
    if (largest > 0 && eigen.eigenvalues()[k] > kSupportedShare * largest) {
      const Point direction = eigen.eigenvectors().col(k);
      unsupported -= direction.dot(delta_p) * direction;
    }
  return unsupported;
}

PetscErrorCode ContactSolver::EndStep(const StepMotion &motion, Vec x, Vec v,
                                      const std::vector<PetscReal> &reactions, bool *changed) {
  PetscFunctionBeginUser;
  Timing timing(this);
  *changed = false;
  if (!active()) PetscFunctionReturn(PETSC_SUCCESS);
  if (motion.mean_velocity_differs && holding_) {
    PetscCall(EndHeldWithMeanVelocity(motion, x, v));
    *changed = true;
  }
  if (body_obstacles_) PetscCall(KeepFixedRegion({{x}}));
  if (ground_ || body_obstacles_) PetscCall(RespondToContacts(x, v, reactions, changed));
  if (!distance_.empty()) {
    PetscCall(ResolveDistanceConstraints(x, v, nullptr));
    *changed = true;
  }
  if (guard_on_) PetscCall(Guard(motion.start, x, v, motion.dt, changed));
  if (separation_.active()) PetscCall(SeparateOverlaps(x, changed));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::EndHeldWithMeanVelocity(const StepMotion &motion, Vec x, Vec v) {
  PetscFunctionBeginUser;
  const PetscScalar *start, *end;
  PetscScalar *velocity;
  PetscCall(VecGetArrayRead(motion.start, &start));
  PetscCall(VecGetArrayRead(x, &end));
  PetscCall(VecGetArray(v, &velocity));
  for (const PetscInt local : held_)
    for (int c = 0; c < 3; ++c)
      velocity[3 * local + c] = (end[3 * local + c] - start[3 * local + c]) / motion.dt;
  PetscCall(VecRestoreArrayRead(motion.start, &start));
  PetscCall(VecRestoreArrayRead(x, &end));
  PetscCall(VecRestoreArray(v, &velocity));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::FindOverlaps(Vec x0) {
  PetscFunctionBeginUser;
  overlaps_checked_ = true;
  size_t pairs;
  PetscCall(separation_.FindOverlaps(x0, &pairs));
  if (pairs > 0)
    PetscCall(PetscPrintf(
        comm_,
        "softbody: warning: %zu pair(s) of free bodies start with their surfaces crossing "
        "(placed overlapping): each pair is moved apart rigidly by %.3g x the "
        "mean boundary edge of its finer body per step, until its surfaces no "
        "longer cross; contact between them acts from then on\n",
        pairs, kSeparationPerStep));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::SeparateOverlaps(Vec x, bool *changed) {
  PetscFunctionBeginUser;
  bool moved;
  PetscCall(separation_.Step(x, &moved));
  *changed = *changed || moved;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::Guard(Vec x0, Vec x, Vec v, PetscReal dt, bool *changed) {
  PetscFunctionBeginUser;
  bool guarded;
  PetscCall(guard_.Apply(x0, x, v, dt, &guarded));
  *changed = *changed || guarded;
  std::vector<char> pinned;
  if (guarded && !distance_.empty()) pinned.assign(scene_->num_vertices(), 0);
  for (int round = 0; guarded && !distance_.empty() && round < kMaxGuardConstraintRounds; ++round) {
    guard_.MarkMoved(&pinned);
    PetscCall(ResolveDistanceConstraints(x, v, &pinned));
    PetscCall(guard_.Apply(x0, x, v, dt, &guarded));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::RespondToContacts(Vec x, Vec v,
                                                const std::vector<PetscReal> &reactions,
                                                bool *changed) {
  PetscFunctionBeginUser;
  PetscCall(Refresh(x, v, 0.0, false));
  PetscScalar *lx, *lv;
  PetscCall(VecGetArray(x, &lx));
  PetscCall(VecGetArray(v, &lv));
  resting_.Clear();
  const std::vector<PetscReal> by_contact = constraints_.ByContact(reactions);
  std::vector<Collision> collisions =
      response_.Respond(constraints_, friction_, by_contact, lx, lv, &resting_);
  stats_.projections +=
      response_.ProjectRemaining(checked_vertices_, constraints_, lx, lv, &collisions);
  if (!options_.impulse_spreading) response_.Apply(collisions, lv);
  PetscCall(VecRestoreArray(x, &lx));
  PetscCall(VecRestoreArray(v, &lv));
  if (options_.impulse_spreading) PetscCall(response_.SpreadImpulses(collisions, v));
  if (options_.restitution > 0) PetscCall(response_.Bounce(constraints_, by_contact, v));
  PetscInt local_changes = static_cast<PetscInt>(collisions.size()), changes;
  PetscCallMPI(MPIU_Allreduce(&local_changes, &changes, 1, MPIU_INT, MPI_SUM, comm_));
  *changed = *changed || changes > 0;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::ResolveDistanceConstraints(Vec x, Vec v,
                                                         const std::vector<char> *pinned) {
  PetscFunctionBeginUser;
  PetscCall(ExchangeFreeState(x, v, 0.0, {false, true}));
  const DistanceConstraints::Resolution resolution = distance_.Resolve(&state_, pinned);
  stats_.constraint_sweeps += resolution.sweeps;
  stats_.max_constraint_sweeps =
      std::max<PetscInt>(stats_.max_constraint_sweeps, resolution.sweeps);
  stats_.max_constraint_violation = std::max(stats_.max_constraint_violation, resolution.violation);
  PetscCall(state_.WriteOwned(x, v));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::GatherRestingContacts(std::vector<std::array<int32_t, 2>> *all,
                                                    std::vector<double> *reactions) const {
  PetscFunctionBeginUser;
  PetscCall(resting_.Gather(comm_, all, reactions));
  PetscFunctionReturn(PETSC_SUCCESS);
}

void ContactSolver::RestoreRestingContacts(const std::vector<std::array<int32_t, 2>> &all,
                                           const std::vector<double> &reactions) {
  resting_.Restore(all, reactions, *layout_, features_,
                   {ground_, body_obstacles_, scene_->bodies.size()});
}

}  // namespace softbody
