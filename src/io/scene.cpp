#include "io/scene.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>

#include "common/errors.hpp"
#include "common/number_format.hpp"
#include "common/options.hpp"
#include "common/text_reader.hpp"
#include "fem/element.hpp"
#include "io/mesh_io.hpp"

namespace softbody {

int32_t Scene::num_vertices() const {
  return static_cast<int32_t>(initial_velocities.rows());
}

int64_t Scene::num_tets() const {
  int64_t total = 0;
  for (const Body &body : bodies) total += body.mesh.num_tets();
  return total;
}

void PlaceMesh(const Eigen::Vector3d &position, const Eigen::Vector4d &quaternion_wxyz,
               TetMesh *mesh) {
  const Eigen::Vector3d centroid = VolumeWeightedCentroid(*mesh);
  // Scaled by its largest component first: normalising (1e200, 1e200, 0, 0) or
  // (1e-160, 1e-160, 0, 0) directly overflows or underflows the squared norm.
  const Eigen::Vector4d wxyz =
      (quaternion_wxyz / quaternion_wxyz.cwiseAbs().maxCoeff()).normalized();
  const Eigen::Quaterniond q(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
  const Eigen::Matrix3d rotation = q.toRotationMatrix();
  for (int32_t v = 0; v < mesh->num_vertices(); ++v) {
    const Eigen::Vector3d rest = mesh->vertices.row(v).transpose() - centroid;
    mesh->vertices.row(v) = (rotation * rest + position).transpose();
  }
}

namespace {

constexpr int kBodyFields = 12;

Body ReadBodyLine(TextReader &in, const std::vector<std::string_view> &fields,
                  const std::filesystem::path &folder, const MeshingOptions &meshing) {
  if (fields.size() != kBodyFields)
    in.Fail(
        "expected 12 fields 'file density young poisson is_fixed px py pz qw qx qy qz', found " +
        std::to_string(fields.size()));
  Body body;
  body.mesh_path = (folder / std::string(fields[0])).lexically_normal().string();
  Material &m = body.material;
  m.density = in.ParseReal(fields[1], "density");
  m.young = in.ParseReal(fields[2], "Young's modulus");
  m.poisson = in.ParseReal(fields[3], "Poisson ratio");
  if (!(m.density > 0)) in.Fail("density must be > 0 (got " + std::string(fields[1]) + ")");
  if (!(m.young > 0)) in.Fail("Young's modulus must be > 0 (got " + std::string(fields[2]) + ")");
  if (!(m.poisson > -1 && m.poisson < 0.5))
    in.Fail("Poisson ratio must lie in (-1, 0.5) (got " + std::string(fields[3]) + ")");
  const long fixed = in.ParseInteger(fields[4], "is_fixed");
  if (fixed != 0 && fixed != 1)
    in.Fail("is_fixed must be 0 or 1 (got " + std::string(fields[4]) + ")");
  body.fixed = fixed == 1;
  Eigen::Vector3d position;
  Eigen::Vector4d quaternion;
  for (int c = 0; c < 3; ++c) position[c] = in.ParseReal(fields[5 + c], "position");
  for (int c = 0; c < 4; ++c) quaternion[c] = in.ParseReal(fields[8 + c], "quaternion");
  if (!(quaternion.cwiseAbs().maxCoeff() > 0)) in.Fail("quaternion must be non-zero");
  try {
    body.mesh = ReadTetMesh(body.mesh_path, meshing);
  } catch (const InputError &error) {  // say which scene line named the mesh
    in.Fail(std::string("mesh: ") + error.what());
  }
  PlaceMesh(position, quaternion, &body.mesh);
  // Far from the origin (or with huge coordinates) a mesh loses its shape to
  // rounding, or its centroid overflows.
  if (!body.mesh.vertices.allFinite())
    in.Fail("mesh " + body.mesh_path +
            ": placing it overflows (position or coordinates too large)");
  for (int32_t t = 0; t < body.mesh.num_tets(); ++t) {
    TetPositions X;
    for (int a = 0; a < 4; ++a) X.row(a) = body.mesh.vertices.row(body.mesh.tets(t, a));
    const double length = LongestEdge(X);
    if (!(std::abs(SignedVolume(X)) > kDegenerateVolume * length * length * length))
      in.Fail("mesh " + body.mesh_path + ": tetrahedron " + std::to_string(t + 1) +
              " is degenerate once placed (position too far from the origin for the mesh's size)");
  }
  return body;
}

// The optional velocity section: num_velocities, then lines "mesh vertex vx vy
// vz"; velocities of fixed bodies are counted and then dropped.
void ReadVelocitySection(TextReader &in, const std::vector<std::string_view> &count_line,
                         Scene *scene) {
  std::vector<std::string_view> fields;
  if (count_line.size() != 1) in.Fail("expected one field, num_velocities");
  const long num_velocities = in.ParseInteger(count_line[0], "num_velocities");
  if (num_velocities < 0) in.Fail("num_velocities must be >= 0");
  const long num_meshes = static_cast<long>(scene->bodies.size());
  for (long i = 0; i < num_velocities; ++i) {
    if (!in.NextLine(&fields))
      in.Fail("expected " + std::to_string(num_velocities) + " velocity lines, found " +
              std::to_string(i));
    if (fields.size() != 5)
      in.Fail("expected 5 fields 'mesh vertex vx vy vz', found " + std::to_string(fields.size()));
    const long b = in.ParseInteger(fields[0], "mesh index");
    if (b < 0 || b >= num_meshes)
      in.Fail("mesh index " + std::to_string(b) + " out of range 0.." +
              std::to_string(num_meshes - 1));
    const Body &body = scene->bodies[b];
    const long v = in.ParseInteger(fields[1], "vertex index");
    if (v < 0 || v >= body.mesh.num_vertices())
      in.Fail("vertex index " + std::to_string(v) + " out of range 0.." +
              std::to_string(body.mesh.num_vertices() - 1) + " of mesh " + std::to_string(b));
    for (int c = 0; c < 3; ++c)
      scene->initial_velocities(body.first_vertex + v, c) = in.ParseReal(fields[2 + c], "velocity");
    ++scene->num_velocity_entries;
    if (body.fixed) ++scene->ignored_fixed_velocities;
  }
  if (in.NextLine(&fields)) in.Fail("unexpected content after the velocity section");
  for (const Body &body : scene->bodies)
    if (body.fixed)
      scene->initial_velocities.middleRows(body.first_vertex, body.mesh.num_vertices()).setZero();
}

}  // namespace

Scene ReadScene(const std::string &path, const MeshingOptions &meshing) {
  TextReader in(path);
  const std::filesystem::path folder = std::filesystem::path(path).parent_path();
  Scene scene;
  scene.path = path;
  std::vector<std::string_view> fields;

  if (!in.NextLine(&fields)) in.Fail("empty scene file (expected num_meshes)");
  if (fields.size() != 1) in.Fail("expected one field, num_meshes");
  const long num_meshes = in.ParseInteger(fields[0], "num_meshes");
  if (num_meshes < 1) in.Fail("num_meshes must be >= 1 (got " + std::to_string(num_meshes) + ")");

  int32_t first_vertex = 0;
  for (long b = 0; b < num_meshes; ++b) {
    if (!in.NextLine(&fields))
      in.Fail("expected " + std::to_string(num_meshes) + " mesh lines, found " + std::to_string(b));
    scene.bodies.push_back(ReadBodyLine(in, fields, folder, meshing));
    scene.bodies.back().first_vertex = first_vertex;
    first_vertex += scene.bodies.back().mesh.num_vertices();
  }
  scene.initial_velocities.setZero(first_vertex, 3);

  if (!in.NextLine(&fields)) return scene;  // no velocity section: all at rest
  ReadVelocitySection(in, fields, &scene);
  return scene;
}

}  // namespace softbody

namespace softbody {

PetscErrorCode ProcessSceneOptions(MPI_Comm comm, SceneOptions *options) {
  PetscFunctionBeginUser;
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kReal, "-tetgen_max_volume"}}));
  char path[PETSC_MAX_PATH_LEN] = "";
  char switches[256];
  MeshingOptions &meshing = options->meshing;
  PetscCall(PetscStrncpy(switches, meshing.tetgen_switches.c_str(), sizeof(switches)));
  PetscOptionsBegin(comm, nullptr, "Scene", nullptr);
  PetscCall(PetscOptionsString("-scene", "Scene file (num_meshes, mesh lines, optional velocities)",
                               nullptr, path, path, sizeof(path), nullptr));
  PetscCall(PetscOptionsString("-tetgen_switches",
                               "TetGen switches for .off surfaces, without '-' (p: mesh the "
                               "surface, required; q<r>: radius-edge ratio bound r; Y: keep the "
                               "surface triangles; softbody adds J and Q)",
                               nullptr, switches, switches, sizeof(switches), nullptr));
  PetscCall(PetscOptionsReal("-tetgen_max_volume",
                             "Largest tetrahedron volume for .off surfaces, in the OFF file's "
                             "units^3 (m^3; 0: no bound; TetGen's a switch)",
                             nullptr, meshing.max_volume, &meshing.max_volume, nullptr));
  PetscOptionsEnd();
  options->path = path;
  meshing.tetgen_switches = switches;
  const std::string bad_switches = CheckTetgenSwitches(meshing.tetgen_switches);
  PetscCheck(bad_switches.empty(), comm, PETSC_ERR_USER_INPUT, "option -tetgen_switches: %s",
             bad_switches.c_str());
  PetscCheck(meshing.max_volume >= 0 && std::isfinite(meshing.max_volume), comm,
             PETSC_ERR_USER_INPUT, "option -tetgen_max_volume: must be >= 0 (got %s)",
             FormatNumber(meshing.max_volume).c_str());
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// FNV-1a hash of every body's vertices and tets.
uint64_t HashMeshes(const Scene &scene) {
  constexpr uint64_t kFnvOffsetBasis = 14695981039346656037ull;  // FNV-1a, 64 bits
  constexpr uint64_t kFnvPrime = 1099511628211ull;
  uint64_t hash = kFnvOffsetBasis;
  const auto add = [&hash](const void *data, size_t bytes) {
    for (size_t i = 0; i < bytes; ++i)
      hash = (hash ^ static_cast<const unsigned char *>(data)[i]) * kFnvPrime;
  };
  for (const Body &body : scene.bodies) {
    add(body.mesh.vertices.data(), sizeof(double) * body.mesh.vertices.size());
    add(body.mesh.tets.data(), sizeof(int32_t) * body.mesh.tets.size());
  }
  return hash;
}

}  // namespace

PetscErrorCode LoadScene(MPI_Comm comm, const SceneOptions &options, Scene *scene) {
  PetscFunctionBeginUser;
  PetscCheck(!options.path.empty(), comm, PETSC_ERR_USER_INPUT,
             "option -scene: required (path to a scene file; see -help)");
  SOFTBODY_CATCH_INPUT(comm, *scene = ReadScene(options.path, options.meshing));
  // Every rank ran its own TetGen: check that they agree, max(h) == min(h) =
  // ~max(~h) over the ranks' mesh hashes h.
  const uint64_t hash = HashMeshes(*scene);
  uint64_t local[2] = {hash, ~hash}, largest[2];
  PetscCallMPI(MPI_Allreduce(local, largest, 2, MPI_UINT64_T, MPI_MAX, comm));
  PetscCheck(largest[0] == ~largest[1], comm, PETSC_ERR_PLIB,
             "the ranks hold different meshes for the scene %s (is the mesher not deterministic?)",
             options.path.c_str());
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
