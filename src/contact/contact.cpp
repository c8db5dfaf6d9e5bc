#include "contact/contact.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "common/errors.hpp"
#include "common/options.hpp"
#include "common/text_reader.hpp"

namespace softbody {

PetscErrorCode ProcessContactOptions(MPI_Comm comm, ContactOptions *o) {
  PetscFunctionBeginUser;
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kReal, "-ground"},
                                     {OptionSyntax::kReal, "-restitution"},
                                     {OptionSyntax::kReal, "-friction"},
                                     {OptionSyntax::kBool, "-sharp_edges"},
                                     {OptionSyntax::kBool, "-impulse_spreading"},
                                     {OptionSyntax::kRealList, "-edge_bounds"}}));
  char path[PETSC_MAX_PATH_LEN] = "";
  PetscReal bounds[2] = {o->edge_lower, o->edge_upper};
  PetscInt nbounds = 2;
  PetscOptionsBegin(comm, nullptr, "Collisions and constraints", nullptr);
  PetscCall(PetscOptionsReal("-ground",
                             "Ground plane height y0 (m): vertices stay at y >= y0 (off if unset)",
                             nullptr, o->ground_y, &o->ground_y, &o->ground));
  PetscCall(PetscOptionsReal(
      "-restitution", "Coefficient of restitution e of collisions, 0 (no bounce) to 1 (elastic)",
      nullptr, o->restitution, &o->restitution, nullptr));
  PetscCall(
      PetscOptionsReal("-friction",
                       "Coulomb friction coefficient mu of collisions (0: frictionless, as the "
                       "coursework)",
                       nullptr, o->friction, &o->friction, nullptr));
  PetscCall(PetscOptionsBool(
      "-sharp_edges",
      "Fixed bodies' sharp edges and corners push free bodies' faces (not only free "
      "vertices against fixed faces)",
      nullptr, o->sharp_edges, &o->sharp_edges, nullptr));
  PetscCall(
      PetscOptionsBool("-impulse_spreading",
                       "Share each collision impulse among all vertices of the body, by inverse "
                       "squared distance",
                       nullptr, o->impulse_spreading, &o->impulse_spreading, nullptr));
  PetscCall(PetscOptionsString("-constraints",
                               "Distance constraints file: n, then 'm1 v1 m2 v2 [lo hi]' per line",
                               nullptr, path, path, sizeof(path), nullptr));
  PetscCall(
      PetscOptionsRealArray("-edge_bounds",
                            "Keep every boundary edge of the free bodies within lo,hi x its rest "
                            "length (off if unset)",
                            nullptr, bounds, &nbounds, &o->edge_bounds));
  PetscOptionsEnd();
  o->constraints_path = path;
  PetscCheck(o->friction >= 0, comm, PETSC_ERR_USER_INPUT,
             "option -friction: must be >= 0 (got %g)", (double)o->friction);
  PetscCheck(o->restitution >= 0 && o->restitution <= 1, comm, PETSC_ERR_USER_INPUT,
             "option -restitution: must lie in [0, 1] (got %g)", (double)o->restitution);
  if (o->edge_bounds) {
    PetscCheck(nbounds == 2, comm, PETSC_ERR_USER_INPUT, "option -edge_bounds: expected lo,hi");
    o->edge_lower = bounds[0];
    o->edge_upper = bounds[1];
    PetscCheck(o->edge_lower > 0 && o->edge_lower <= 1 && o->edge_upper >= 1, comm,
               PETSC_ERR_USER_INPUT, "option -edge_bounds: need 0 < lo <= 1 <= hi (got %g,%g)",
               (double)o->edge_lower, (double)o->edge_upper);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

std::vector<DistanceConstraint> ReadConstraints(const std::string &path, const Scene &scene) {
  TextReader in(path);
  std::vector<std::string_view> fields;
  std::vector<DistanceConstraint> constraints;
  if (!in.NextLine(&fields)) return constraints;  // an empty file: no constraints
  if (fields.size() != 1) in.Fail("expected one field, the number of constraints");
  const long n = in.ParseInteger(fields[0], "number of constraints");
  if (n < 0) in.Fail("number of constraints must be >= 0");
  auto vertex = [&](std::string_view mesh_field, std::string_view vertex_field) {
    const long m = in.ParseInteger(mesh_field, "mesh index");
    if (m < 0 || m >= static_cast<long>(scene.bodies.size()))
      in.Fail("mesh index " + std::to_string(m) + " out of range 0.." +
              std::to_string(scene.bodies.size() - 1));
    const TetMesh &mesh = scene.bodies[m].mesh;
    const long v = in.ParseInteger(vertex_field, "vertex index");
    if (v < 0 || v >= mesh.num_vertices())
      in.Fail("vertex index " + std::to_string(v) + " out of range 0.." +
              std::to_string(mesh.num_vertices() - 1) + " of mesh " + std::to_string(m));
    return std::pair<int32_t, Point>(scene.bodies[m].first_vertex + static_cast<int32_t>(v),
                                     mesh.vertices.row(v).transpose());
  };
  for (long i = 0; i < n; ++i) {
    if (!in.NextLine(&fields))
      in.Fail("expected " + std::to_string(n) + " constraint lines, found " + std::to_string(i));
    if (fields.size() != 4 && fields.size() != 6)
      in.Fail("expected 'm1 v1 m2 v2' or 'm1 v1 m2 v2 lo hi', found " +
              std::to_string(fields.size()) + " fields");
    const auto [a, xa] = vertex(fields[0], fields[1]);
    const auto [b, xb] = vertex(fields[2], fields[3]);
    const double rest = (xb - xa).norm();
    if (!(rest > 0)) in.Fail("the two vertices coincide: no rest distance to keep");
    double lo = 1, hi = 1;
    if (fields.size() == 6) {
      lo = in.ParseReal(fields[4], "lower bound");
      hi = in.ParseReal(fields[5], "upper bound");
      if (!(lo >= 0 && lo <= hi)) in.Fail("need 0 <= lo <= hi");
    }
    constraints.push_back({a, b, lo * rest, hi * rest});
  }
  if (in.NextLine(&fields)) in.Fail("unexpected content after the constraints");
  return constraints;
}

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

ContactSolver::~ContactSolver() {
  VecScatterDestroy(&to_all_);
  VecDestroy(&all_x_);
  VecDestroy(&all_v_);
}

namespace {

// Edges of the boundary triangles of a mesh, each once (local vertex indices).
std::vector<std::pair<int32_t, int32_t>> BoundaryEdges(const TetMesh &mesh) {
  const auto triangles = BoundaryTriangles(mesh);
  std::vector<std::pair<int32_t, int32_t>> edges;
  for (Eigen::Index t = 0; t < triangles.rows(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int32_t a = triangles(t, k), b = triangles(t, (k + 1) % 3);
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  return edges;
}

// The sharp features of a body's surface as points: the vertices of its
// boundary edges whose two faces' outward normals differ by more than
// kFeatureAngle (or that border one face or more than two), and points along
// those edges at most `spacing` apart. World coordinates; each with the
// face normals of each edge it lies on (one pair per edge; an edge with one
// face or more than two: each face's normal twice).
constexpr double kFeatureAngle = 30.0 * M_PI / 180.0;
constexpr double kFeatureTolerance = 1e-3;
struct FeatureCandidate {
  Point point;
  std::vector<std::pair<Point, Point>> edges;
};
std::vector<FeatureCandidate> FeaturePoints(const TetMesh &mesh, double spacing) {
  const auto triangles = BoundaryTriangles(mesh);
  std::map<std::pair<int32_t, int32_t>, std::vector<Point>> faces_of_edge;
  for (Eigen::Index t = 0; t < triangles.rows(); ++t) {
    const Point a = mesh.vertices.row(triangles(t, 0)), b = mesh.vertices.row(triangles(t, 1)),
                c = mesh.vertices.row(triangles(t, 2));
    const Point normal = (b - a).cross(c - a).normalized();
    for (int k = 0; k < 3; ++k) {
      const int32_t u = triangles(t, k), w = triangles(t, (k + 1) % 3);
      faces_of_edge[{std::min(u, w), std::max(u, w)}].push_back(normal);
    }
  }
  std::map<int32_t, std::vector<std::pair<Point, Point>>> corners;
  std::vector<FeatureCandidate> points;
  for (const auto &[edge, normals] : faces_of_edge) {
    if (normals.size() == 2 && normals[0].dot(normals[1]) >= std::cos(kFeatureAngle)) continue;
    std::vector<std::pair<Point, Point>> pairs;
    if (normals.size() == 2)
      pairs.emplace_back(normals[0], normals[1]);
    else
      for (const Point &n : normals) pairs.emplace_back(n, n);
    for (const int32_t v : {edge.first, edge.second})
      corners[v].insert(corners[v].end(), pairs.begin(), pairs.end());
    const Point a = mesh.vertices.row(edge.first), b = mesh.vertices.row(edge.second);
    const int pieces = static_cast<int>(std::ceil((b - a).norm() / spacing));
    for (int k = 1; k < pieces; ++k) points.push_back({a + (b - a) * (double(k) / pieces), pairs});
  }
  for (const auto &[v, pairs] : corners)
    points.push_back({mesh.vertices.row(v).transpose(), pairs});
  return points;
}

}  // namespace

PetscErrorCode ContactSolver::Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                                    Vec lumped_mass, const ContactOptions &options) {
  PetscFunctionBeginUser;
  PetscClassId class_id;
  PetscCall(PetscClassIdRegister("softbody contact", &class_id));
  PetscCall(PetscLogEventRegister("Contact", class_id, &event_));
  comm_ = comm;
  scene_ = &scene;
  layout_ = &layout;
  options_ = options;
  int free_bodies = 0, fixed_bodies = 0;
  for (const Body &body : scene.bodies) (body.fixed ? fixed_bodies : free_bodies)++;
  ground_ = options.ground && layout.num_free() > 0;
  obstacles_ = free_bodies >= 1 && (fixed_bodies >= 1 || free_bodies >= 2) && layout.num_free() > 0;
  free_obstacles_ = obstacles_ && free_bodies >= 2;

  if (!options.constraints_path.empty())
    SOFTBODY_CATCH_INPUT(comm, constraints_ = ReadConstraints(options.constraints_path, scene));
  if (options.edge_bounds)
    for (const Body &body : scene.bodies) {
      if (body.fixed) continue;
      for (const auto &[a, b] : BoundaryEdges(body.mesh)) {
        const double rest = (body.mesh.vertices.row(b) - body.mesh.vertices.row(a)).norm();
        constraints_.push_back({body.first_vertex + a, body.first_vertex + b,
                                options.edge_lower * rest, options.edge_upper * rest});
      }
    }
  if (!active()) PetscFunctionReturn(PETSC_SUCCESS);

  const int32_t V = scene.num_vertices();
  body_of_.resize(V);
  world_x_.resize(3 * static_cast<size_t>(V));
  world_v_.assign(3 * static_cast<size_t>(V), 0.0);
  body_edge_.assign(scene.bodies.size(), 0.0);
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    for (int32_t v = 0; v < body.mesh.num_vertices(); ++v) {
      body_of_[body.first_vertex + v] = static_cast<int32_t>(b);
      for (int c = 0; c < 3; ++c)
        world_x_[3 * (body.first_vertex + v) + c] = body.mesh.vertices(v, c);
    }
    double length = 0;
    const auto edges = BoundaryEdges(body.mesh);
    for (const auto &[a, c] : edges)
      length += (body.mesh.vertices.row(c) - body.mesh.vertices.row(a)).norm();
    body_edge_[b] = edges.empty() ? 1.0 : length / edges.size();
  }
  // The fixed bodies' sharp features, sampled at half the finest free body's
  // mean boundary edge length (filtered below, once the fixed grids exist).
  std::map<size_t, std::vector<FeatureCandidate>> feature_candidates;
  if (obstacles_ && options.sharp_edges) {
    double spacing = 1e300;
    for (size_t b = 0; b < scene.bodies.size(); ++b)
      if (!scene.bodies[b].fixed) spacing = std::min(spacing, 0.5 * body_edge_[b]);
    for (size_t b = 0; b < scene.bodies.size(); ++b)
      if (scene.bodies[b].fixed)
        feature_candidates[b] = FeaturePoints(scene.bodies[b].mesh, spacing);
  }
  track_free_ = free_obstacles_ || !feature_candidates.empty();
  gather_always_ =
      free_obstacles_ || !constraints_.empty() || (options.impulse_spreading && active());
  gather_ = gather_always_ || track_free_;

  owned_natural_.resize(layout.local_count());
  for (PetscInt f = 0; f < layout.num_free(); ++f) {
    const PetscInt p = layout.petsc_of_free[f] - layout.local_begin();
    if (p >= 0 && p < layout.local_count())
      owned_natural_[p] = static_cast<int32_t>(layout.natural_of_free[f]);
  }

  // Inverse masses on every rank (natural order): fixed and stray vertices 0.
  inverse_mass_.assign(V, 0.0);
  if (gather_) {
    PetscCall(VecScatterCreateToAll(lumped_mass, &to_all_, &all_x_));
    PetscCall(VecDuplicate(all_x_, &all_v_));
    PetscCall(VecScatterBegin(to_all_, lumped_mass, all_x_, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecScatterEnd(to_all_, lumped_mass, all_x_, INSERT_VALUES, SCATTER_FORWARD));
    const PetscScalar *mass;
    PetscCall(VecGetArrayRead(all_x_, &mass));
    for (PetscInt f = 0; f < layout.num_free(); ++f)
      inverse_mass_[layout.natural_of_free[f]] = 1.0 / mass[3 * layout.petsc_of_free[f]];
    PetscCall(VecRestoreArrayRead(all_x_, &mass));
  } else {
    const PetscScalar *mass;
    PetscCall(VecGetArrayRead(lumped_mass, &mass));
    for (PetscInt f = 0; f < layout.num_free(); ++f) {
      const PetscInt p = layout.petsc_of_free[f] - layout.local_begin();
      if (p >= 0 && p < layout.local_count())
        inverse_mass_[layout.natural_of_free[f]] = 1.0 / mass[3 * p];
    }
    PetscCall(VecRestoreArrayRead(lumped_mass, &mass));
  }

  // Body masses: the owned vertices' lumped masses, summed over ranks.
  std::vector<double> owned_mass(scene.bodies.size(), 0.0);
  for (const int32_t natural : owned_natural_)
    owned_mass[body_of_[natural]] += 1.0 / inverse_mass_[natural];
  body_mass_.resize(scene.bodies.size());
  PetscCallMPI(MPI_Allreduce(owned_mass.data(), body_mass_.data(),
                             static_cast<int>(owned_mass.size()), MPI_DOUBLE, MPI_SUM, comm));

  if (obstacles_) {
    for (size_t b = 0; b < scene.bodies.size(); ++b) {
      const Body &body = scene.bodies[b];
      const auto boundary = BoundaryTriangles(body.mesh);
      if (!body.fixed)  // queries: this rank's vertices of free bodies (interior ones too:
                        // a soft body hitting hard can push them through its surface)
        for (int32_t v = 0; v < body.mesh.num_vertices(); ++v) {
          const int32_t natural = body.first_vertex + v;
          const PetscInt free = layout.free_of_natural[natural];
          const PetscInt p = free < 0 ? -1 : layout.petsc_of_free[free] - layout.local_begin();
          if (p >= 0 && p < layout.local_count()) query_vertices_.push_back({p, natural});
        }
      if (!body.fixed && !track_free_) continue;  // a lone free body away from sharp features
      auto &tets = body.fixed ? fixed_tets_ : free_tets_;
      auto &triangles = body.fixed ? fixed_triangles_ : free_triangles_;
      for (int32_t t = 0; t < body.mesh.num_tets(); ++t)
        tets.push_back({body.first_vertex + body.mesh.tets(t, 0),
                        body.first_vertex + body.mesh.tets(t, 1),
                        body.first_vertex + body.mesh.tets(t, 2),
                        body.first_vertex + body.mesh.tets(t, 3), static_cast<int32_t>(b)});
      for (Eigen::Index f = 0; f < boundary.rows(); ++f)
        triangles.push_back({body.first_vertex + boundary(f, 0), body.first_vertex + boundary(f, 1),
                             body.first_vertex + boundary(f, 2), static_cast<int32_t>(b)});
    }
    std::sort(query_vertices_.begin(), query_vertices_.end());
    query_vertices_.erase(std::unique(query_vertices_.begin(), query_vertices_.end()),
                          query_vertices_.end());
    BuildObstacleGrids(true);
    // A feature point is kept while one of its edges is a real edge of the
    // fixed bodies together: both of its faces free of other fixed bodies
    // there (a cube's top edge flush with its neighbour's top face is none).
    feature_begin_.assign(1, 0);
    for (size_t b = 0; b < scene.bodies.size(); ++b) {
      const double probe = 1e-6 * body_edge_[b];
      auto covered = [&](const Point &p) {
        for (size_t o = 0; o < scene.bodies.size(); ++o)
          if (o != b && scene.bodies[o].fixed && body_box_[o].Contains(p, probe) &&
              InsideBody(p, static_cast<int32_t>(o)))
            return true;
        return false;
      };
      for (const FeatureCandidate &candidate : feature_candidates[b]) {
        const bool real =
            std::any_of(candidate.edges.begin(), candidate.edges.end(), [&](const auto &faces) {
              return !covered(candidate.point + probe * faces.first) &&
                     !covered(candidate.point + probe * faces.second);
            });
        if (real) feature_point_.push_back(candidate.point);
      }
      feature_begin_.push_back(static_cast<int32_t>(feature_point_.size()));
    }
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

std::string ContactSolver::Description() const {
  std::string text;
  auto add = [&](const std::string &part) { text += (text.empty() ? "" : ", ") + part; };
  char buffer[64];
  if (ground_) {
    std::snprintf(buffer, sizeof(buffer), "ground at y = %g m", options_.ground_y);
    add(buffer);
  }
  if (obstacles_)
    add(std::to_string(fixed_tets_.size()) + " fixed and " + std::to_string(free_tets_.size()) +
        " moving obstacle tets in uniform grids");
  if (!feature_point_.empty())
    add(std::to_string(feature_point_.size()) + " points on fixed bodies' sharp edges");
  if (!constraints_.empty()) add(std::to_string(constraints_.size()) + " distance constraints");
  if (active() && options_.impulse_spreading) add("impulse spreading");
  if (active() && (ground_ || obstacles_)) {
    std::snprintf(buffer, sizeof(buffer), "restitution %g, friction %g", options_.restitution,
                  options_.friction);
    add(buffer);
  }
  return text;
}

void ContactSolver::BuildObstacleGrids(bool fixed_part) {
  const auto &tets = fixed_part ? fixed_tets_ : free_tets_;
  const auto &triangles = fixed_part ? fixed_triangles_ : free_triangles_;
  body_box_.resize(scene_->bodies.size());
  for (size_t b = 0; b < scene_->bodies.size(); ++b) {
    const Body &body = scene_->bodies[b];
    if (body.fixed != fixed_part) continue;
    body_box_[b] = Box();
    for (int32_t v = 0; v < body.mesh.num_vertices(); ++v)
      body_box_[b].Extend(WorldPoint(body.first_vertex + v));
  }
  if (!fixed_part) {
    free_grids_current_ = false;
    return;
  }
  BuildGrids(tets, triangles, &fixed_tet_box_, &fixed_tet_grid_, &fixed_triangle_grid_);
}

void ContactSolver::BuildGrids(const std::vector<std::array<int32_t, 5>> &tets,
                               const std::vector<std::array<int32_t, 4>> &triangles,
                               std::vector<Box> *tet_boxes, UniformGrid *tet_grid,
                               UniformGrid *triangle_grid) const {
  tet_boxes->assign(tets.size(), Box());
  for (size_t t = 0; t < tets.size(); ++t)
    for (int a = 0; a < 4; ++a) (*tet_boxes)[t].Extend(WorldPoint(tets[t][a]));
  tet_grid->Build(*tet_boxes);
  std::vector<Box> boxes(triangles.size(), Box());
  for (size_t t = 0; t < triangles.size(); ++t)
    for (int a = 0; a < 3; ++a) boxes[t].Extend(WorldPoint(triangles[t][a]));
  triangle_grid->Build(boxes);
}

void ContactSolver::EnsureFreeGrids() const {
  if (free_grids_current_) return;
  BuildGrids(free_tets_, free_triangles_, &free_tet_box_, &free_tet_grid_, &free_triangle_grid_);
  free_grids_current_ = true;
  ++free_grid_builds_;
}

PetscErrorCode ContactSolver::Refresh(Vec x, Vec v, PetscReal dt, bool features) {
  PetscFunctionBeginUser;
  features_near_ = false;
  if (features && !feature_point_.empty()) {
    // Each free body's box at x + dt v (the owned vertices' boxes, reduced:
    // -lower and upper by MPI_MAX) and whether any rank holds resting
    // sharp-edge contacts.
    const size_t bodies = scene_->bodies.size();
    std::vector<double> bounds(6 * bodies + 1, -1e300);
    const PetscScalar *ax, *av;
    PetscCall(VecGetArrayRead(x, &ax));
    PetscCall(VecGetArrayRead(v, &av));
    for (size_t p = 0; p < owned_natural_.size(); ++p) {
      const size_t b = body_of_[owned_natural_[p]];
      for (int c = 0; c < 3; ++c) {
        const double at = ax[3 * p + c] + dt * av[3 * p + c];
        bounds[6 * b + c] = std::max(bounds[6 * b + c], -at);
        bounds[6 * b + 3 + c] = std::max(bounds[6 * b + 3 + c], at);
      }
    }
    PetscCall(VecRestoreArrayRead(x, &ax));
    PetscCall(VecRestoreArrayRead(v, &av));
    for (const auto &[local, contact] : resting_)
      if (contact.feature >= 0) bounds[6 * bodies] = 1;
    PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, bounds.data(), static_cast<int>(bounds.size()),
                               MPI_DOUBLE, MPI_MAX, comm_));
    features_near_ = bounds[6 * bodies] > 0;
    for (size_t b = 0; b < bodies && !features_near_; ++b) {
      if (scene_->bodies[b].fixed) continue;
      Box box;
      box.lower = -Point(&bounds[6 * b]);
      box.upper = Point(&bounds[6 * b + 3]);
      for (size_t f = 0; f < bodies && !features_near_; ++f)
        features_near_ = feature_begin_[f] < feature_begin_[f + 1] && body_box_[f].Overlaps(box);
    }
  }
  if (gather_always_ || features_near_) PetscCall(Gather(x, v, dt));
  if (free_obstacles_ || features_near_) BuildObstacleGrids(false);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// World arrays of the free vertices at x + dt v (dt = 0: at x), velocities v.
PetscErrorCode ContactSolver::Gather(Vec x, Vec v, PetscReal dt) {
  PetscFunctionBeginUser;
  ++stats_.gathers;
  for (auto [from, to] : {std::pair<Vec, Vec>(x, all_x_), std::pair<Vec, Vec>(v, all_v_)}) {
    PetscCall(VecScatterBegin(to_all_, from, to, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecScatterEnd(to_all_, from, to, INSERT_VALUES, SCATTER_FORWARD));
  }
  const PetscScalar *ax, *av;
  PetscCall(VecGetArrayRead(all_x_, &ax));
  PetscCall(VecGetArrayRead(all_v_, &av));
  for (PetscInt f = 0; f < layout_->num_free(); ++f) {
    const PetscInt n = layout_->natural_of_free[f], p = layout_->petsc_of_free[f];
    for (int c = 0; c < 3; ++c) {
      world_x_[3 * n + c] = ax[3 * p + c] + dt * av[3 * p + c];
      world_v_[3 * n + c] = av[3 * p + c];
    }
  }
  PetscCall(VecRestoreArrayRead(all_x_, &ax));
  PetscCall(VecRestoreArrayRead(all_v_, &av));
  PetscFunctionReturn(PETSC_SUCCESS);
}

bool ContactSolver::ClosestOnBody(const Point &p, int32_t obstacle, SurfaceHit *hit) const {
  if (obstacle < 0) {  // the ground
    *hit = {Point(p[0], options_.ground_y, p[2]),
            Point(0, 1, 0),
            Point::Zero(),
            0.0,
            -1,
            -1,
            Eigen::Vector3d::Zero()};
    return true;
  }
  const bool fixed_part = scene_->bodies[obstacle].fixed;
  if (!fixed_part) EnsureFreeGrids();
  const auto &triangles = fixed_part ? fixed_triangles_ : free_triangles_;
  const UniformGrid &grid = fixed_part ? fixed_triangle_grid_ : free_triangle_grid_;
  if (grid.empty()) return false;
  const double limit = (grid.bounds().upper - grid.bounds().lower).norm() +
                       (grid.bounds().upper - p).norm() + (grid.bounds().lower - p).norm();
  double best = 1e300;
  // Growing neighbourhoods until the closest point found lies within the searched one.
  for (double radius = grid.cell_size(); best > radius && radius < 2 * limit; radius *= 2)
    grid.ForEachNear(p, radius, [&](int32_t t) {
      const auto &tri = triangles[t];
      if (tri[3] != obstacle) return;
      const Point a = WorldPoint(tri[0]), b = WorldPoint(tri[1]), c = WorldPoint(tri[2]);
      Eigen::Vector3d w;
      const Point q = ClosestPointOnTriangle(p, a, b, c, &w);
      const double distance = (q - p).norm();
      const Point normal = (b - a).cross(c - a);
      if (distance >= best || !(normal.norm() > 0)) return;
      best = distance;
      hit->point = q;
      hit->normal = normal.normalized();
      hit->velocity = w[0] * Point(&world_v_[3 * tri[0]]) + w[1] * Point(&world_v_[3 * tri[1]]) +
                      w[2] * Point(&world_v_[3 * tri[2]]);
      hit->inverse_mass = w[0] * inverse_mass_[tri[0]] + w[1] * inverse_mass_[tri[1]] +
                          w[2] * inverse_mass_[tri[2]];
      hit->body = obstacle;
      hit->triangle = t;
      hit->weights = w;
    });
  return best < 1e300;
}

bool ContactSolver::InsideBody(const Point &p, int32_t obstacle) const {
  const bool fixed_part = scene_->bodies[obstacle].fixed;
  if (!fixed_part) EnsureFreeGrids();
  const auto &tets = fixed_part ? fixed_tets_ : free_tets_;
  const auto &tet_boxes = fixed_part ? fixed_tet_box_ : free_tet_box_;
  bool inside = false;
  (fixed_part ? fixed_tet_grid_ : free_tet_grid_).ForEachNear(p, 0.0, [&](int32_t t) {
    const auto &tet = tets[t];
    if (inside || tet[4] != obstacle || !tet_boxes[t].Contains(p, 1e-12)) return;
    inside = Barycentric(p, WorldPoint(tet[0]), WorldPoint(tet[1]), WorldPoint(tet[2]),
                         WorldPoint(tet[3]))
                 .minCoeff() >= -1e-12;
  });
  return inside;
}

bool ContactSolver::LocateInFreeBody(const Point &p, int32_t body, double margin,
                                     Point *velocity) const {
  EnsureFreeGrids();
  bool found = false;
  free_tet_grid_.ForEachNear(p, 0.0, [&](int32_t t) {
    const auto &tet = free_tets_[t];
    if (found || tet[4] != body || !free_tet_box_[t].Contains(p, 1e-12)) return;
    const Eigen::Vector4d w = Barycentric(p, WorldPoint(tet[0]), WorldPoint(tet[1]),
                                          WorldPoint(tet[2]), WorldPoint(tet[3]));
    if (!(w.minCoeff() > margin)) return;
    found = true;
    *velocity = Point::Zero();
    for (int k = 0; k < 4; ++k) *velocity += w[k] * Point(&world_v_[3 * tet[k]]);
  });
  return found;
}

bool ContactSolver::EntryOnBody(const Point &start, const Point &end, int32_t obstacle,
                                SurfaceHit *hit) const {
  const bool fixed_part = scene_->bodies[obstacle].fixed;
  if (!fixed_part) EnsureFreeGrids();
  const auto &triangles = fixed_part ? fixed_triangles_ : free_triangles_;
  const UniformGrid &grid = fixed_part ? fixed_triangle_grid_ : free_triangle_grid_;
  const Point direction = end - start;
  double first = 2;
  grid.ForEachNear(0.5 * (start + end), 0.5 * direction.cwiseAbs().maxCoeff(), [&](int32_t t) {
    const auto &tri = triangles[t];
    if (tri[3] != obstacle) return;
    const Point a = WorldPoint(tri[0]), b = WorldPoint(tri[1]), c = WorldPoint(tri[2]);
    const Point normal = (b - a).cross(c - a);
    double along;
    Eigen::Vector3d w;
    if (normal.dot(direction) >= 0 || !SegmentCrossesTriangle(start, end, a, b, c, &along, &w) ||
        along >= first)
      return;
    first = along;
    hit->point = start + along * direction;
    hit->normal = normal.normalized();
    hit->velocity = w[0] * Point(&world_v_[3 * tri[0]]) + w[1] * Point(&world_v_[3 * tri[1]]) +
                    w[2] * Point(&world_v_[3 * tri[2]]);
    hit->inverse_mass =
        w[0] * inverse_mass_[tri[0]] + w[1] * inverse_mass_[tri[1]] + w[2] * inverse_mass_[tri[2]];
    hit->body = obstacle;
    hit->triangle = t;
    hit->weights = w;
  });
  return first <= 1;
}

bool ContactSolver::FindPenetration(const Point &p, int32_t body, const VertexObstacles &skip,
                                    SurfaceHit *hit) const {
  if (ground_ && p[1] < options_.ground_y && !skip.Has(-1)) return ClosestOnBody(p, -1, hit);
  // Broad phase: only bodies whose box holds p.
  bool near_fixed = false, near_free = false;
  for (size_t b = 0; b < body_box_.size(); ++b)
    if (static_cast<int32_t>(b) != body && body_box_[b].Contains(p))
      (scene_->bodies[b].fixed ? near_fixed : near_free) = true;
  if (!near_fixed && !near_free) return false;
  if (near_free) EnsureFreeGrids();
  for (const bool fixed_part : {true, false}) {
    if (!(fixed_part ? near_fixed : near_free)) continue;
    const auto &tets = fixed_part ? fixed_tets_ : free_tets_;
    const auto &tet_boxes = fixed_part ? fixed_tet_box_ : free_tet_box_;
    int32_t inside = -1;
    (fixed_part ? fixed_tet_grid_ : free_tet_grid_).ForEachNear(p, 0.0, [&](int32_t t) {
      const auto &tet = tets[t];
      if (inside >= 0 || tet[4] == body || skip.Has(tet[4]) || !tet_boxes[t].Contains(p, 1e-12))
        return;
      if (Barycentric(p, WorldPoint(tet[0]), WorldPoint(tet[1]), WorldPoint(tet[2]),
                      WorldPoint(tet[3]))
              .minCoeff() >= -1e-12)  // faces count: p may lie on one shared by two tets
        inside = tet[4];
    });
    if (inside >= 0) return ClosestOnBody(p, inside, hit);
  }
  return false;
}

void ContactSolver::Constrain(PetscInt local, int32_t natural, const Point &x0,
                              const Point &predicted, const Point &velocity, PetscReal dt,
                              const SurfaceHit &hit, bool fresh) {
  const Point &n = hit.normal;
  const double w = inverse_mass_[natural], w_obstacle = hit.inverse_mass;
  const double share = w / (w + w_obstacle);  // 1 against a fixed obstacle
  const Point target = predicted + share * (hit.point - predicted);
  const double approach = n.dot(velocity - hit.velocity);  // < 0: closing
  const double common = (w_obstacle * n.dot(velocity) + w * n.dot(hit.velocity)) / (w + w_obstacle);
  // A vertex already inside at the start of the step (a body placed in the
  // ground, say) comes out gradually: at most a tenth of its body's edge length
  // per step faster than the obstacle, not all the depth at once. Deeper than
  // that inside another free body, it only stops sinking: there closest-point
  // normals point every way, and pushing along them strained both bodies
  // without separating them (the fertility scene's statues: 5.8e12 J to 2e13 J
  // in 4 s, overlap growing).
  const double edge = body_edge_[body_of_[natural]];
  const bool deep_in_free_body =
      hit.body >= 0 && !scene_->bodies[hit.body].fixed && n.dot(hit.point - x0) > 0.1 * edge;
  const double recovery = n.dot(hit.velocity) + (deep_in_free_body ? 0.0 : 0.1 * edge / dt);
  double normal_velocity = n.dot(target - x0) / dt;
  if (n.dot(hit.point - x0) > 0) normal_velocity = std::min(normal_velocity, recovery);
  velocity_constraints_.push_back({local, n, normal_velocity, w_obstacle == 0});
  contacts_.push_back({natural, hit.body, common, fresh && approach < -bounce_speed_});
  VertexObstacles &obstacles = constrained_[local];
  obstacles.obstacle[obstacles.count++] = hit.body;
}

PetscInt ContactSolver::LocalOf(int32_t natural) const {
  const PetscInt free = layout_->free_of_natural[natural];
  const PetscInt local = free < 0 ? -1 : layout_->petsc_of_free[free] - layout_->local_begin();
  return local >= 0 && local < layout_->local_count() ? local : -1;
}

PetscInt ContactSolver::ConstrainFeature(int32_t feature, const SurfaceHit &hit, PetscReal dt,
                                         bool fresh, bool limit) {
  const Point m = -hit.normal;
  const auto &triangle = free_triangles_[hit.triangle];
  const int32_t obstacle = FeatureBody(feature);
  double depth = m.dot(feature_point_[feature] - hit.point);
  if (limit) depth = std::min(depth, 0.1 * body_edge_[triangle[3]]);
  // The vertices that move: those with weight, but not one lying on a fixed
  // surface that faces within kFeatureAngle of m (its own contact holds it
  // along nearly m; both held exactly would need a sideways velocity of
  // (c_1 - c_2) / sin(angle): a cube overhanging a fixed one's edge by a
  // tenth was thrown off at 3 m/s), unless all do. (Leaving every vertex on
  // a fixed surface alone pushed the others by up to d / w_k: the edge sank
  // deeper into the stairway's bunny.)
  std::array<bool, 3> moves;
  for (int k = 0; k < 3; ++k)
    moves[k] = hit.weights[k] >= 1e-3 && !OnFixedSurface(WorldPoint(triangle[k]), m);
  if (std::none_of(moves.begin(), moves.end(), [](bool b) { return b; }))
    for (int k = 0; k < 3; ++k) moves[k] = hit.weights[k] >= 1e-3;
  double squares = 0;
  for (int k = 0; k < 3; ++k)
    if (moves[k]) squares += hit.weights[k] * hit.weights[k];
  PetscInt changed = 0;
  for (int k = 0; k < 3; ++k) {
    const int32_t natural = triangle[k];
    const PetscInt local = LocalOf(natural);
    if (!moves[k] || local < 0) continue;
    const Point velocity(&world_v_[3 * natural]);
    const double push = hit.weights[k] * depth / squares / dt;  // d_k / dt
    const VelocityConstraint constraint{local, m, m.dot(velocity) + push, true};
    const Contact contact{natural, obstacle, 0.0, fresh && m.dot(velocity) < -bounce_speed_,
                          feature};
    ptrdiff_t &slot = feature_contact_[local];
    if (slot >= 0) {  // the vertex's larger push stays
      const VelocityConstraint &held = velocity_constraints_[slot];
      if (push > held.velocity - held.normal.dot(velocity)) {
        velocity_constraints_[slot] = constraint;
        contacts_[slot] = contact;
        ++changed;
      }
      continue;
    }
    slot = static_cast<ptrdiff_t>(contacts_.size());
    velocity_constraints_.push_back(constraint);
    contacts_.push_back(contact);
    ++changed;
  }
  return changed;
}

bool ContactSolver::OnFixedSurface(const Point &x, const Point &direction) const {
  const double cosine = std::cos(kFeatureAngle);
  if (ground_ && x[1] <= options_.ground_y && direction[1] >= cosine) return true;
  for (size_t b = 0; b < scene_->bodies.size(); ++b) {
    SurfaceHit hit;
    const int32_t body = static_cast<int32_t>(b);
    if (scene_->bodies[b].fixed && body_box_[b].Contains(x, 1e-12) && InsideBody(x, body) &&
        ClosestOnBody(x, body, &hit) && hit.normal.dot(direction) >= cosine)
      return true;
  }
  return false;
}

PetscInt ContactSolver::AddFeaturePenetrations(PetscReal dt) {
  PetscInt found = 0;
  for (size_t b = 0; b < scene_->bodies.size(); ++b) {
    if (scene_->bodies[b].fixed || body_box_[b].Empty()) continue;
    const int32_t body = static_cast<int32_t>(b);
    for (size_t f = 0; f + 1 < feature_begin_.size(); ++f) {
      // Broad phase: the fixed body's box meets the free one's.
      if (feature_begin_[f] == feature_begin_[f + 1] || !body_box_[f].Overlaps(body_box_[b]))
        continue;
      for (int32_t i = feature_begin_[f]; i < feature_begin_[f + 1]; ++i) {
        const Point &p = feature_point_[i];
        Point velocity;
        if (feature_held_[i] || !body_box_[b].Contains(p) ||
            !LocateInFreeBody(p, body, 1e-6, &velocity))
          continue;
        // Touching (within kFeatureTolerance edge lengths of the surface, e.g.
        // a fixed edge flush with a free face) is no penetration. Else p
        // pushes the triangle it entered through, on its path relative to the
        // body (p + dt v -> p, v the body's velocity at p); if it was inside
        // already, the closest one, and it comes out gradually.
        SurfaceHit hit;
        if (!ClosestOnBody(p, body, &hit) ||
            (hit.point - p).norm() < kFeatureTolerance * body_edge_[b])
          continue;
        const bool entered = EntryOnBody(p + dt * velocity, p, body, &hit);
        feature_held_[i] = 1;
        found += ConstrainFeature(i, hit, dt, true, !entered);
      }
    }
  }
  return found;
}

PetscErrorCode ContactSolver::BeginStep(Vec x0, Vec v0, PetscReal dt) {
  PetscFunctionBeginUser;
  Timing timing(this);
  velocity_constraints_.clear();
  tangent_constraints_.clear();
  sticking_contact_.clear();
  friction_in_solve_.clear();
  slips_.clear();
  solve_constraints_.clear();
  contacts_.clear();
  constrained_.assign(owned_natural_.size(), VertexObstacles());
  feature_held_.assign(feature_point_.size(), 0);
  feature_contact_.assign(owned_natural_.size(), -1);
  global_constraints_ = 0;
  bounce_speed_ = 2 * options_.gravity * dt;
  if (!ground_ && !obstacles_) PetscFunctionReturn(PETSC_SUCCESS);
  // Obstacles where they will be if they keep their velocity.
  PetscCall(Refresh(x0, v0, dt, true));
  const PetscScalar *x, *v;
  PetscCall(VecGetArrayRead(x0, &x));
  PetscCall(VecGetArrayRead(v0, &v));
  for (const auto &[local, contact] : resting_) {
    const Point position(&x[3 * local]), velocity(&v[3 * local]);
    SurfaceHit hit;
    if (contact.feature >= 0) {
      // The feature point against the face now closest to it, once per step:
      // all of this rank's vertices of that face (the other ranks do theirs
      // as new contacts), also those whose own contact was released (pushing
      // only the resting one, a vertex of weight 0.1, let the stairway's edge
      // sink 0.16 m into the bunny).
      if (feature_held_[contact.feature] ||
          !ClosestOnBody(feature_point_[contact.feature], body_of_[contact.natural], &hit))
        continue;
      const auto &triangle = free_triangles_[hit.triangle];
      if (std::find(triangle.begin(), triangle.begin() + 3, contact.natural) ==
          triangle.begin() + 3)
        continue;
      feature_held_[contact.feature] = 1;
      const bool unconstrained = feature_contact_[local] < 0;
      ConstrainFeature(contact.feature, hit, dt, false, true);
      const bool appended = unconstrained && feature_contact_[local] >= 0;
      SurfaceHit fixed_side = hit;  // the feature's side: immobile, facing the vertex
      fixed_side.normal = -hit.normal;
      fixed_side.velocity = Point::Zero();
      fixed_side.inverse_mass = 0;
      if (appended && options_.friction > 0)
        Stick(local, velocity, fixed_side, feature_contact_[local]);
    } else if (ClosestOnBody(position + dt * velocity, contact.body, &hit)) {
      Constrain(local, contact.natural, position, position + dt * velocity, velocity, dt, hit,
                false);
      if (options_.friction > 0) Stick(local, velocity, hit, contacts_.size() - 1);
    }
  }
  PetscCall(VecRestoreArrayRead(x0, &x));
  PetscCall(VecRestoreArrayRead(v0, &v));
  PetscCall(CountConstraints());
  PetscFunctionReturn(PETSC_SUCCESS);
}

void ContactSolver::Stick(PetscInt local, const Point &velocity, const SurfaceHit &hit,
                          size_t contact) {
  const Point &n = hit.normal;
  const Point relative = velocity - hit.velocity;
  // The friction response of a sticking step leaves exactly no tangential
  // relative velocity (up to round-off).
  if ((relative - n.dot(relative) * n).norm() > 1e-9 * (velocity.norm() + hit.velocity.norm()))
    return;
  const Point t1 = n.unitOrthogonal(), t2 = n.cross(t1);
  tangent_constraints_.push_back({local, t1, t1.dot(hit.velocity), hit.inverse_mass == 0});
  tangent_constraints_.push_back({local, t2, t2.dot(hit.velocity), hit.inverse_mass == 0});
  sticking_contact_.push_back(contact);
}

PetscErrorCode ContactSolver::ReleaseSlipping(const std::vector<PetscReal> &reactions, Vec rhs,
                                              bool *released) {
  PetscFunctionBeginUser;
  Timing timing(this);
  friction_in_solve_.resize(contacts_.size(), 0);
  PetscInt local_released = 0;
  std::vector<VelocityConstraint> kept_tangents;
  std::vector<size_t> kept_contacts;
  PetscScalar *b;
  PetscCall(VecGetArray(rhs, &b));
  // Contacts released in earlier rounds: their impulse follows the normal
  // reaction of the latest solve (a fixed point over the rounds).
  for (Slip &slip : slips_) {
    const double limit = options_.friction * std::max(reactions[slip.contact], 0.0);
    if (std::abs(limit - slip.magnitude) <= 1e-6 * std::max(limit, slip.magnitude)) continue;
    for (int c = 0; c < 3; ++c)
      b[3 * slip.vertex + c] += (limit - slip.magnitude) * slip.direction[c];
    slip.magnitude = limit;
    ++local_released;
  }
  for (size_t k = 0; k < sticking_contact_.size(); ++k) {
    const size_t contact = sticking_contact_[k], first = velocity_constraints_.size() + 2 * k;
    const VelocityConstraint &t1 = solve_constraints_[first], &t2 = solve_constraints_[first + 1];
    const Point impulse = reactions[first] * t1.normal + reactions[first + 1] * t2.normal;
    const double limit = options_.friction * std::max(reactions[contact], 0.0);
    if (impulse.norm() <= limit * (1 + 1e-9)) {
      kept_tangents.insert(kept_tangents.end(), {t1, t2});
      kept_contacts.push_back(contact);
      continue;
    }
    // Kinetic friction for this step: mu lambda_n along the sticking reaction.
    const Point direction = impulse / impulse.norm();
    for (int c = 0; c < 3; ++c) b[3 * t1.vertex + c] += limit * direction[c];
    slips_.push_back({contact, t1.vertex, direction, limit});
    friction_in_solve_[contact] = 1;
    ++local_released;
  }
  PetscCall(VecRestoreArray(rhs, &b));
  tangent_constraints_.swap(kept_tangents);
  sticking_contact_.swap(kept_contacts);
  PetscInt all_released;
  PetscCallMPI(MPIU_Allreduce(&local_released, &all_released, 1, MPIU_INT, MPI_SUM, comm_));
  *released = all_released > 0;
  if (*released) PetscCall(CountConstraints());
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::CountConstraints() {
  PetscFunctionBeginUser;
  solve_constraints_ = velocity_constraints_;
  solve_constraints_.insert(solve_constraints_.end(), tangent_constraints_.begin(),
                            tangent_constraints_.end());
  const PetscInt local = static_cast<PetscInt>(solve_constraints_.size());
  PetscCallMPI(MPIU_Allreduce(&local, &global_constraints_, 1, MPIU_INT, MPI_SUM, comm_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::AddPenetrations(Vec x0, Vec v, PetscReal dt, bool *added) {
  PetscFunctionBeginUser;
  Timing timing(this);
  *added = false;
  if (!ground_ && !obstacles_) PetscFunctionReturn(PETSC_SUCCESS);
  PetscCall(Refresh(x0, v, dt, true));
  const PetscScalar *x, *lv;
  PetscCall(VecGetArrayRead(x0, &x));
  PetscCall(VecGetArrayRead(v, &lv));
  PetscInt found = 0;
  // A vertex can be held by up to three obstacles (a corner); each adds one.
  auto check = [&](PetscInt local, int32_t natural) {
    const VertexObstacles &held = constrained_[local];
    if (held.count == 3) return;
    const Point start(&x[3 * local]), velocity(&lv[3 * local]);
    const Point predicted = start + dt * velocity;
    SurfaceHit hit;
    if (!FindPenetration(predicted, body_of_[natural], held, &hit)) return;
    // A vertex that starts the step outside a fixed obstacle meets the face it
    // enters through: near an edge or across a thin part the closest surface
    // point of the end point can be another face. (Against a free body the
    // path relative to its surface is only estimated; there, two cubes thrown
    // at each other met worse with the entry face, 2.4e-2 barycentric depth
    // instead of 4.5e-3: the closest point stays.)
    if (hit.body >= 0 && scene_->bodies[hit.body].fixed) {
      SurfaceHit entry;
      if (!InsideBody(start, hit.body) && EntryOnBody(start, predicted, hit.body, &entry))
        hit = entry;
    }
    Constrain(local, natural, start, predicted, velocity, dt, hit, true);
    ++found;
  };
  if (obstacles_)  // every free vertex, against bodies and the ground
    for (const auto &[local, natural] : query_vertices_) check(local, natural);
  else  // the ground alone
    for (PetscInt local = 0; local < static_cast<PetscInt>(owned_natural_.size()); ++local)
      check(local, owned_natural_[local]);
  PetscCall(VecRestoreArrayRead(x0, &x));
  PetscCall(VecRestoreArrayRead(v, &lv));
  // Feature points: every rank sees all (gathered positions) and constrains its own vertices.
  PetscInt local_found[2] = {found, features_near_ ? AddFeaturePenetrations(dt) : 0}, all_found[2];
  PetscCallMPI(MPIU_Allreduce(local_found, all_found, 2, MPIU_INT, MPI_SUM, comm_));
  stats_.collisions += all_found[0];
  stats_.feature_contacts += all_found[1];
  *added = all_found[0] + all_found[1] > 0;
  if (*added) PetscCall(CountConstraints());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Last resort: vertices still inside an obstacle after the step go to its surface.
PetscErrorCode ContactSolver::ProjectRemaining(PetscScalar *x, PetscScalar *v,
                                               std::vector<Collision> *collisions) {
  PetscFunctionBeginUser;
  PetscInt projected = 0;
  auto project = [&](PetscInt local, int32_t natural) {
    const Point position(&x[3 * local]);
    SurfaceHit hit;
    if (!FindPenetration(position, body_of_[natural], VertexObstacles(), &hit)) return;
    // Deeper than a tenth of an edge: left to the next step's constraints, which
    // bring it out gradually (a jump of that size would be a huge strain). A
    // constrained vertex ends on the surface (to round-off) unless its
    // constraints could not all hold (more than three directions, e.g. a
    // sticking contact's and a sharp edge's); it is projected out of fixed
    // bodies and the ground only (out of a free body, one side's projection
    // would change the momentum of the pair).
    const double depth = (hit.point - position).norm(), edge = body_edge_[body_of_[natural]];
    const bool immobile = hit.body < 0 || scene_->bodies[hit.body].fixed;
    if (depth > 0.1 * edge || (constrained_[local].count && (depth < 1e-6 * edge || !immobile)))
      return;
    const Point velocity(&v[3 * local]);
    const double approach = hit.normal.dot(velocity - hit.velocity);
    const Point target = hit.point + 1e-9 * body_edge_[body_of_[natural]] * hit.normal;
    for (int c = 0; c < 3; ++c) x[3 * local + c] = target[c];
    if (approach < 0)
      collisions->push_back({natural, body_of_[natural], target,
                             -(1 + options_.restitution) * approach * hit.normal});
    ++projected;
  };
  if (obstacles_)
    for (const auto &[local, natural] : query_vertices_) project(local, natural);
  else
    for (PetscInt local = 0; local < static_cast<PetscInt>(owned_natural_.size()); ++local)
      project(local, owned_natural_[local]);
  stats_.projections += projected;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::EndStep(Vec x, Vec v, const std::vector<PetscReal> &reactions,
                                      bool *changed) {
  PetscFunctionBeginUser;
  Timing timing(this);
  *changed = false;
  if (!active()) PetscFunctionReturn(PETSC_SUCCESS);
  std::vector<Collision> collisions;
  if (ground_ || obstacles_) {
    PetscCall(Refresh(x, v, 0.0, false));
    PetscScalar *lx, *lv;
    PetscCall(VecGetArray(x, &lx));
    PetscCall(VecGetArray(v, &lv));
    // Velocity response of the constrained vertices: relative normal velocity
    // -e times the approach for a new contact, 0 for a resting one.
    resting_.clear();
    // Sticking contacts: where their tangent pair's reactions sit.
    std::vector<ptrdiff_t> tangent_reaction(contacts_.size(), -1);
    for (size_t k = 0; k < sticking_contact_.size(); ++k)
      tangent_reaction[sticking_contact_[k]] =
          static_cast<ptrdiff_t>(velocity_constraints_.size() + 2 * k);
    for (size_t i = 0; i < contacts_.size(); ++i) {
      const Contact &contact = contacts_[i];
      const VelocityConstraint &constraint = velocity_constraints_[i];
      const Point &n = constraint.normal;
      const Point velocity(&lv[3 * constraint.vertex]);
      Point dv = (contact.normal_velocity - n.dot(velocity)) * n;
      // Coulomb friction. A sticking contact was held in the solve, or slipped
      // with mu lambda in it (ReleaseSlipping). A sliding one loses at most
      // mu lambda / m of its tangential velocity relative to the obstacle here.
      SurfaceHit hit;
      const double limit = options_.friction * std::max(reactions[i], 0.0);
      const bool in_solve =
          tangent_reaction[i] >= 0 || (i < friction_in_solve_.size() && friction_in_solve_[i]);
      if (!in_solve && options_.friction > 0 &&
          ClosestOnBody(Point(&lx[3 * constraint.vertex]), contact.body, &hit)) {
        const Point relative = velocity - hit.velocity;
        const Point tangential = relative - n.dot(relative) * n;
        const double slip = tangential.norm(), grip = limit * inverse_mass_[contact.natural];
        if (slip > 0) dv -= std::min(1.0, grip / slip) * tangential;
      }
      collisions.push_back(
          {contact.natural, body_of_[contact.natural], Point(&lx[3 * constraint.vertex]), dv});
      // Resting contacts stay constrained while the obstacle pushes; bouncing ones leave.
      if (reactions[i] >= 0 && !(options_.restitution > 0 && contact.impact))
        resting_.push_back({constraint.vertex, contact});
    }
    PetscCall(ProjectRemaining(lx, lv, &collisions));
    if (!options_.impulse_spreading)
      for (const Collision &c : collisions) {
        const PetscInt local =
            layout_->petsc_of_free[layout_->free_of_natural[c.vertex]] - layout_->local_begin();
        for (int k = 0; k < 3; ++k) lv[3 * local + k] += c.dv[k];
      }
    PetscCall(VecRestoreArray(x, &lx));
    PetscCall(VecRestoreArray(v, &lv));
    if (options_.impulse_spreading) PetscCall(SpreadImpulses(collisions, v));
    if (options_.restitution > 0) PetscCall(Bounce(reactions, v));
    PetscInt local_changes = static_cast<PetscInt>(collisions.size()), changes;
    PetscCallMPI(MPIU_Allreduce(&local_changes, &changes, 1, MPIU_INT, MPI_SUM, comm_));
    *changed = changes > 0;
  }
  if (!constraints_.empty()) {
    PetscCall(Gather(x, v, 0.0));
    const double violation = ResolveConstraints();
    stats_.max_constraint_violation = std::max(stats_.max_constraint_violation, violation);
    PetscScalar *lx, *lv;
    PetscCall(VecGetArray(x, &lx));
    PetscCall(VecGetArray(v, &lv));
    for (PetscInt p = 0; p < static_cast<PetscInt>(owned_natural_.size()); ++p)
      for (int c = 0; c < 3; ++c) {
        lx[3 * p + c] = world_x_[3 * owned_natural_[p] + c];
        lv[3 * p + c] = world_v_[3 * owned_natural_[p] + c];
      }
    PetscCall(VecRestoreArray(x, &lx));
    PetscCall(VecRestoreArray(v, &lv));
    *changed = true;
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Restitution: body b gets e J_b / M_b, J_b the normal impulse of its impacts.
PetscErrorCode ContactSolver::Bounce(const std::vector<PetscReal> &reactions, Vec v) {
  PetscFunctionBeginUser;
  const size_t bodies = scene_->bodies.size();
  std::vector<double> local(3 * bodies, 0.0), impulse(3 * bodies);
  for (size_t i = 0; i < contacts_.size(); ++i) {
    if (!contacts_[i].impact || reactions[i] <= 0) continue;
    const int32_t body = body_of_[contacts_[i].natural];
    for (int k = 0; k < 3; ++k)
      local[3 * body + k] += reactions[i] * velocity_constraints_[i].normal[k];
  }
  PetscCallMPI(MPI_Allreduce(local.data(), impulse.data(), static_cast<int>(local.size()),
                             MPI_DOUBLE, MPI_SUM, comm_));
  PetscScalar *lv;
  PetscCall(VecGetArray(v, &lv));
  for (PetscInt p = 0; p < static_cast<PetscInt>(owned_natural_.size()); ++p) {
    const int32_t body = body_of_[owned_natural_[p]];
    for (int k = 0; k < 3; ++k)
      lv[3 * p + k] += options_.restitution * impulse[3 * body + k] / body_mass_[body];
  }
  PetscCall(VecRestoreArray(v, &lv));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ContactSolver::SpreadImpulses(const std::vector<Collision> &local, Vec v) {
  PetscFunctionBeginUser;
  // Every rank gets every collision: 8 numbers each (vertex, body, position, dv).
  std::vector<double> packed;
  for (const Collision &c : local) {
    packed.insert(packed.end(), {double(c.vertex), double(c.body)});
    packed.insert(packed.end(), c.position.data(), c.position.data() + 3);
    packed.insert(packed.end(), c.dv.data(), c.dv.data() + 3);
  }
  PetscMPIInt size, count = static_cast<PetscMPIInt>(packed.size());
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  std::vector<PetscMPIInt> counts(size), offsets(size + 1, 0);
  PetscCallMPI(MPI_Allgather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, comm_));
  for (int r = 0; r < size; ++r) offsets[r + 1] = offsets[r] + counts[r];
  std::vector<double> all(offsets[size]);
  PetscCallMPI(MPI_Allgatherv(packed.data(), count, MPI_DOUBLE, all.data(), counts.data(),
                              offsets.data(), MPI_DOUBLE, comm_));
  PetscScalar *lv;
  PetscCall(VecGetArray(v, &lv));
  for (size_t i = 0; i < all.size(); i += 8) {
    const int32_t vertex = static_cast<int32_t>(all[i]), body = static_cast<int32_t>(all[i + 1]);
    const Point at(all[i + 2], all[i + 3], all[i + 4]), dv(all[i + 5], all[i + 6], all[i + 7]);
    const Body &b = scene_->bodies[body];
    const double l = body_edge_[body];
    // Weights over the body's free vertices; the impulse m_c dv shared by them.
    double total = 0;
    for (int32_t k = 0; k < b.mesh.num_vertices(); ++k) {
      const int32_t n = b.first_vertex + k;
      if (inverse_mass_[n] > 0 || n == vertex)
        total += 1 / std::pow(l + (WorldPoint(n) - at).norm(), 2);
    }
    const Point impulse = dv / inverse_mass_[vertex];
    for (PetscInt p = 0; p < static_cast<PetscInt>(owned_natural_.size()); ++p) {
      const int32_t n = owned_natural_[p];
      if (body_of_[n] != body) continue;
      const double share = 1 / std::pow(l + (WorldPoint(n) - at).norm(), 2) / total;
      for (int c = 0; c < 3; ++c) lv[3 * p + c] += share * inverse_mass_[n] * impulse[c];
    }
  }
  PetscCall(VecRestoreArray(v, &lv));
  PetscFunctionReturn(PETSC_SUCCESS);
}

double ContactSolver::ResolveConstraints() {
  auto point = [](std::vector<double> &a, int32_t n) { return Eigen::Map<Point>(&a[3 * n]); };
  double violation = 0;
  PetscInt sweep = 0;
  for (; sweep < 500; ++sweep) {
    violation = 0;
    for (const DistanceConstraint &c : constraints_) {
      const double wa = inverse_mass_[c.a], wb = inverse_mass_[c.b], w = wa + wb;
      Eigen::Map<Point> xa = point(world_x_, c.a), xb = point(world_x_, c.b);
      const Point d = xb - xa;
      const double length = d.norm();
      if (w == 0 || !(length > 0)) continue;
      const double target = std::clamp(length, c.lower, c.upper);
      violation = std::max(violation, std::abs(length - target) / c.upper);
      const Point n = d / length;
      // Positions: both ends move along n, inversely to their masses.
      const double error = length - target;
      xa += (wa / w) * error * n;
      xb -= (wb / w) * error * n;
      // Velocities: no relative motion further out of the bounds.
      Eigen::Map<Point> va = point(world_v_, c.a), vb = point(world_v_, c.b);
      const double separating = (vb - va).dot(n);
      if ((target == c.upper && separating > 0 && length >= c.upper) ||
          (target == c.lower && separating < 0 && length <= c.lower)) {
        va += (wa / w) * separating * n;
        vb -= (wb / w) * separating * n;
      }
    }
    if (violation < 1e-12) break;
  }
  stats_.constraint_sweeps += sweep + 1;
  stats_.max_constraint_sweeps = std::max<PetscInt>(stats_.max_constraint_sweeps, sweep + 1);
  return violation;
}

PetscErrorCode ContactSolver::GatherRestingContacts(
    std::vector<std::array<int32_t, 2>> *all) const {
  PetscFunctionBeginUser;
  std::vector<int32_t> local;
  for (const auto &[vertex, contact] :
       resting_)  // a feature contact's obstacle is written -2 - feature
    local.insert(local.end(),
                 {contact.natural, contact.feature >= 0 ? -2 - contact.feature : contact.body});
  PetscMPIInt rank, size, count = static_cast<PetscMPIInt>(local.size());
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  std::vector<PetscMPIInt> counts(size), offsets(size + 1, 0);
  PetscCallMPI(MPI_Gather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, comm_));
  for (int r = 0; r < size; ++r) offsets[r + 1] = offsets[r] + (rank == 0 ? counts[r] : 0);
  std::vector<int32_t> gathered(offsets[size]);
  PetscCallMPI(MPI_Gatherv(local.data(), count, MPI_INT32_T, gathered.data(), counts.data(),
                           offsets.data(), MPI_INT32_T, 0, comm_));
  all->resize(gathered.size() / 2);
  for (size_t i = 0; i < all->size(); ++i) (*all)[i] = {gathered[2 * i], gathered[2 * i + 1]};
  PetscFunctionReturn(PETSC_SUCCESS);
}

void ContactSolver::RestoreRestingContacts(const std::vector<std::array<int32_t, 2>> &all) {
  resting_.clear();
  for (const auto &[natural, entry] : all) {
    const int32_t feature = entry <= -2 ? -2 - entry : -1;
    if (feature >= 0  ? static_cast<size_t>(feature) >= feature_point_.size()
        : entry == -1 ? !ground_
                      : !obstacles_ || static_cast<size_t>(entry) >= scene_->bodies.size())
      continue;
    if (natural < 0 || static_cast<size_t>(natural) >= layout_->free_of_natural.size()) continue;
    const PetscInt local = LocalOf(natural);
    if (local < 0) continue;
    resting_.push_back({local, Contact{natural, feature >= 0 ? FeatureBody(feature) : entry, 0.0,
                                       false, feature}});
  }
}

}  // namespace softbody
