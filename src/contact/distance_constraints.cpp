#include "contact/distance_constraints.hpp"

#include <algorithm>
#include <cmath>

#include "common/errors.hpp"
#include "common/text_reader.hpp"
#include "contact/contact_meshes.hpp"
#include "contact/geometry.hpp"

namespace softbody {

namespace {

// Sweeps stop once every constraint holds to this fraction of its upper bound:
// a few thousand times double round-off, as exact as the positions allow.
constexpr double kConstraintTolerance = 1e-12;
// At most this many sweeps per step: bounds the work of a set that converges
// slowly or contradicts itself (the run summary reports the sweeps and the
// violation left).
constexpr PetscInt kMaxConstraintSweeps = 500;

}  // namespace

std::vector<ConstraintLine> ParseConstraints(const std::string &path, const Scene &scene) {
  TextReader in(path);
  std::vector<std::string_view> fields;
  std::vector<ConstraintLine> lines;
  if (!in.NextLine(&fields)) return lines;  // an empty file: no constraints
  if (fields.size() != 1) in.Fail("expected one field, the number of constraints");
  const long n = in.ParseInteger(fields[0], "number of constraints");
  if (n < 0) in.Fail("number of constraints must be >= 0");
  auto vertex = [&](std::string_view mesh_field, std::string_view vertex_field) {
    const long m = in.ParseInteger(mesh_field, "mesh index");
    if (m < 0 || m >= static_cast<long>(scene.bodies.size()))
      in.Fail("mesh index " + std::to_string(m) + " out of range 0.." +
              std::to_string(scene.bodies.size() - 1));
    const long count = scene.bodies[m].num_vertices();
    const long v = in.ParseInteger(vertex_field, "vertex index");
    if (v < 0 || v >= count)
      in.Fail("vertex index " + std::to_string(v) + " out of range 0.." +
              std::to_string(count - 1) + " of mesh " + std::to_string(m));
    return scene.bodies[m].first_vertex + static_cast<int32_t>(v);
  };
  for (long i = 0; i < n; ++i) {
    if (!in.NextLine(&fields))
      in.Fail("expected " + std::to_string(n) + " constraint lines, found " + std::to_string(i));
    if (fields.size() != 4 && fields.size() != 6)
      in.Fail("expected 'm1 v1 m2 v2' or 'm1 v1 m2 v2 lo hi', found " +
              std::to_string(fields.size()) + " fields");
    ConstraintLine line;
    line.a = vertex(fields[0], fields[1]);
    line.b = vertex(fields[2], fields[3]);
    line.line = in.line();
    if (fields.size() == 6) {
      line.lo = in.ParseReal(fields[4], "lower bound");
      line.hi = in.ParseReal(fields[5], "upper bound");
      if (!(line.lo >= 0 && line.lo <= line.hi)) in.Fail("need 0 <= lo <= hi");
    }
    lines.push_back(line);
  }
  if (in.NextLine(&fields)) in.Fail("unexpected content after the constraints");
  return lines;
}

std::vector<DistanceConstraint> RestDistances(const std::string &path,
                                              const std::vector<ConstraintLine> &lines,
                                              const std::function<Point(int32_t)> &rest) {
  std::vector<DistanceConstraint> constraints;
  constraints.reserve(lines.size());
  for (const ConstraintLine &line : lines) {
    const Point xa = rest(line.a), xb = rest(line.b);
    const double distance = (xb - xa).norm();
    if (!(distance > 0))
      throw InputError(
          Where(path, line.line, "the two vertices coincide: no rest distance to keep"));
    constraints.push_back({line.a, line.b, line.lo * distance, line.hi * distance});
  }
  return constraints;
}

std::vector<DistanceConstraint> ReadConstraints(const std::string &path, const Scene &scene) {
  return RestDistances(path, ParseConstraints(path, scene), [&](int32_t natural) {
    const Body &body = scene.bodies[BodyOfNatural(scene, natural)];
    return Point(body.mesh.vertices.row(natural - body.first_vertex).transpose());
  });
}

PetscErrorCode DistanceConstraints::Setup(MPI_Comm comm, const Scene &scene, ContactMeshes *meshes,
                                          const ContactOptions &options) {
  PetscFunctionBeginUser;
  const std::string &path = options.constraints_path;
  std::vector<ConstraintLine> lines;
  if (!path.empty()) SOFTBODY_CATCH_INPUT(comm, lines = ParseConstraints(path, scene));
  std::vector<int32_t> ends;
  for (const ConstraintLine &line : lines) ends.insert(ends.end(), {line.a, line.b});
  PetscCall(meshes->FetchRest(ends));
  SOFTBODY_CATCH_INPUT(comm, constraints_ = RestDistances(path, lines, [&](int32_t natural) {
                               return meshes->rest(natural);
                             }));
  if (!options.edge_bounds) PetscFunctionReturn(PETSC_SUCCESS);
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    if (body.fixed) continue;
    const int32_t first = body.first_vertex;
    for (const auto &[a, c] : BoundaryEdges(meshes->boundary(b))) {
      const double rest = (meshes->rest_row(first + c) - meshes->rest_row(first + a)).norm();
      constraints_.push_back(
          {first + a, first + c, options.edge_lower * rest, options.edge_upper * rest});
    }
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

DistanceConstraints::Resolution DistanceConstraints::Resolve(
    FreeState *state, const std::vector<char> *pinned) const {
  double violation = 0;
  PetscInt sweep = 0;
  for (; sweep < kMaxConstraintSweeps; ++sweep) {
    violation = Sweep(state, pinned);
    if (violation < kConstraintTolerance) break;
  }
  return {sweep + 1, violation};
}

double DistanceConstraints::Sweep(FreeState *state, const std::vector<char> *pinned) const {
  double violation = 0;
  auto weight = [&](int32_t n) { return pinned && (*pinned)[n] ? 0.0 : state->inverse_mass(n); };
  for (const DistanceConstraint &c : constraints_) {
    const double wa = weight(c.a), wb = weight(c.b), w = wa + wb;
    Eigen::Map<Point> xa = state->position_ref(c.a), xb = state->position_ref(c.b);
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
    Eigen::Map<Point> va = state->velocity_ref(c.a), vb = state->velocity_ref(c.b);
    const double separating = (vb - va).dot(n);
    if ((target == c.upper && separating > 0 && length >= c.upper) ||
        (target == c.lower && separating < 0 && length <= c.lower)) {
      va += (wa / w) * separating * n;
      vb -= (wb / w) * separating * n;
    }
  }
  return violation;
}

}  // namespace softbody
