#include "io/scene.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>

#include "common/errors.hpp"
#include "common/held_bytes.hpp"
#include "common/number_format.hpp"
#include "common/options.hpp"
#include "common/text_reader.hpp"
#include "fem/element.hpp"
#include "io/mesh_h5.hpp"
#include "io/mesh_io.hpp"

namespace softbody {

int32_t Scene::num_vertices() const {
  return bodies.empty() ? 0 : bodies.back().first_vertex + bodies.back().num_vertices();
}

int64_t Scene::num_tets() const {
  int64_t total = 0;
  for (const Body &body : bodies) total += body.num_tets();
  return total;
}

int64_t Scene::MeshBytes() const {
  int64_t bytes = HeldBytes(initial_velocities);
  for (const Body &body : bodies)
    bytes += HeldBytes(body.mesh.vertices) + HeldBytes(body.mesh.tets);
  return bytes;
}

void Scene::DropMeshes() {
  for (Body &body : bodies) {
    body.count_vertices = body.num_vertices();
    body.count_tets = body.num_tets();
    body.mesh = TetMesh();
  }
  initial_velocities = std::vector<InitialVelocity>();
  meshes_held = false;
}

Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> DenseInitialVelocities(
    const Scene &scene) {
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> dense =
      Eigen::MatrixXd::Zero(scene.num_vertices(), 3);
  for (const InitialVelocity &entry : scene.initial_velocities)
    for (int c = 0; c < 3; ++c) dense(entry.vertex, c) = entry.velocity[c];
  return dense;
}

void PlaceMesh(const Eigen::Vector3d &position, const Eigen::Vector4d &quaternion_wxyz,
               TetMesh *mesh) {
  PlaceVertices(VolumeWeightedCentroid(*mesh), position, quaternion_wxyz, &mesh->vertices);
}

void PlaceVertices(const Eigen::Vector3d &centroid, const Eigen::Vector3d &position,
                   const Eigen::Vector4d &quaternion_wxyz,
                   Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> *vertices) {
  // Scaled by its largest component first: normalising (1e200, 1e200, 0, 0) or
  // (1e-160, 1e-160, 0, 0) directly overflows or underflows the squared norm.
  const Eigen::Vector4d wxyz =
      (quaternion_wxyz / quaternion_wxyz.cwiseAbs().maxCoeff()).normalized();
  const Eigen::Quaterniond q(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
  const Eigen::Matrix3d rotation = q.toRotationMatrix();
  for (Eigen::Index v = 0; v < vertices->rows(); ++v) {
    const Eigen::Vector3d rest = vertices->row(v).transpose() - centroid;
    vertices->row(v) = (rotation * rest + position).transpose();
  }
}

namespace {

constexpr int kBodyFields = 12;

// Reads body->mesh_path, places it and checks the placed tets; throws InputError
// (without a location: the caller adds it).
void LoadPlacedMesh(const MeshingOptions &meshing, Body *body) {
  try {
    body->mesh = ReadTetMesh(body->mesh_path, meshing);
  } catch (const InputError &error) {
    throw InputError(std::string("mesh: ") + error.what());
  }
  body->mesh_deferred = false;
  PlaceMesh(body->position, body->quaternion, &body->mesh);
  // Far from the origin (or with huge coordinates) a mesh loses its shape to
  // rounding, or its centroid overflows.
  if (!body->mesh.vertices.allFinite())
    throw InputError("mesh " + body->mesh_path +
                     ": placing it overflows (position or coordinates too large)");
  for (int32_t t = 0; t < body->mesh.num_tets(); ++t) {
    TetPositions X;
    for (int a = 0; a < 4; ++a) X.row(a) = body->mesh.vertices.row(body->mesh.tets(t, a));
    if (IsDegenerateTet(X))
      throw InputError("mesh " + body->mesh_path + ": tetrahedron " + std::to_string(t + 1) +
                       " is degenerate once placed (position too far from the origin for the "
                       "mesh's size)");
  }
}

// Only the counts of a softbody .h5 mesh (read later, in slabs).
void DeferMesh(Body *body) {
  MeshCounts counts;
  try {
    counts = ReadMeshH5Counts(body->mesh_path);
  } catch (const InputError &error) {
    throw InputError(std::string("mesh: ") + error.what());
  }
  body->count_vertices = static_cast<int32_t>(counts.vertices);
  body->count_tets = counts.tets;
  body->mesh_deferred = true;
}

Body ReadBodyLine(TextReader &in, const std::vector<std::string_view> &fields,
                  const std::filesystem::path &folder, const MeshingOptions &meshing,
                  bool defer_h5) {
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
  for (int c = 0; c < 3; ++c) body.position[c] = in.ParseReal(fields[5 + c], "position");
  for (int c = 0; c < 4; ++c) body.quaternion[c] = in.ParseReal(fields[8 + c], "quaternion");
  if (!(body.quaternion.cwiseAbs().maxCoeff() > 0)) in.Fail("quaternion must be non-zero");
  try {
    if (defer_h5 && IsMeshH5Path(body.mesh_path)) {
      DeferMesh(&body);
    } else {
      LoadPlacedMesh(meshing, &body);
    }
  } catch (const InputError &error) {  // say which scene line named the mesh
    in.Fail(error.what());
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
    if (v < 0 || v >= body.num_vertices())
      in.Fail("vertex index " + std::to_string(v) + " out of range 0.." +
              std::to_string(body.num_vertices() - 1) + " of mesh " + std::to_string(b));
    InitialVelocity entry{body.first_vertex + v, {}};
    for (int c = 0; c < 3; ++c) entry.velocity[c] = in.ParseReal(fields[2 + c], "velocity");
    ++scene->num_velocity_entries;
    if (body.fixed)
      ++scene->ignored_fixed_velocities;
    else
      scene->initial_velocities.push_back(entry);
  }
  if (in.NextLine(&fields)) in.Fail("unexpected content after the velocity section");
  // By vertex, the file's last line for a vertex kept.
  std::vector<InitialVelocity> &entries = scene->initial_velocities;
  std::stable_sort(
      entries.begin(), entries.end(),
      [](const InitialVelocity &a, const InitialVelocity &b) { return a.vertex < b.vertex; });
  std::vector<InitialVelocity> unique;
  for (size_t i = 0; i < entries.size(); ++i)
    if (i + 1 == entries.size() || entries[i + 1].vertex != entries[i].vertex)
      unique.push_back(entries[i]);
  entries.swap(unique);
}

}  // namespace

bool IsMeshH5Path(const std::string &path) {
  const std::string suffix = ".h5";  // as ReadTetMesh tells the formats apart
  return path.size() >= suffix.size() &&
         path.compare(path.size() - suffix.size(), suffix.size(), suffix) == 0;
}

void LoadDeferredMeshes(const MeshingOptions &meshing, Scene *scene) {
  for (Body &body : scene->bodies) {
    if (!body.mesh_deferred) continue;
    try {
      LoadPlacedMesh(meshing, &body);
    } catch (const InputError &error) {
      throw InputError(Where(scene->path, 0, error.what()));
    }
    body.count_vertices = -1;
    body.count_tets = -1;
  }
}

Scene ReadScene(const std::string &path, const MeshingOptions &meshing, bool defer_h5_meshes) {
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
    scene.bodies.push_back(ReadBodyLine(in, fields, folder, meshing, defer_h5_meshes));
    scene.bodies.back().first_vertex = first_vertex;
    first_vertex += scene.bodies.back().num_vertices();
  }
  if (!in.NextLine(&fields)) return scene;  // no velocity section: all at rest
  ReadVelocitySection(in, fields, &scene);
  return scene;
}

}  // namespace softbody

namespace softbody {

PetscErrorCode ProcessMeshingOptions(MPI_Comm comm, MeshingOptions *meshing) {
  PetscFunctionBeginUser;
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kReal, "-tetgen_max_volume"}}));
  char switches[256];
  PetscCall(PetscStrncpy(switches, meshing->tetgen_switches.c_str(), sizeof(switches)));
  PetscOptionsBegin(comm, nullptr, "Meshing of .off surfaces (TetGen)", nullptr);
  PetscCall(PetscOptionsString("-tetgen_switches",
                               "TetGen switches for .off surfaces, without '-' (p: mesh the "
                               "surface, required; q<r>: radius-edge ratio bound r; Y: keep the "
                               "surface triangles; softbody adds J and Q)",
                               nullptr, switches, switches, sizeof(switches), nullptr));
  PetscCall(PetscOptionsReal("-tetgen_max_volume",
                             "Largest tetrahedron volume for .off surfaces, in the OFF file's "
                             "units^3 (m^3; 0: no bound; TetGen's a switch)",
                             nullptr, meshing->max_volume, &meshing->max_volume, nullptr));
  PetscOptionsEnd();
  meshing->tetgen_switches = switches;
  const std::string bad_switches = CheckTetgenSwitches(meshing->tetgen_switches);
  PetscCheck(bad_switches.empty(), comm, PETSC_ERR_USER_INPUT, "option -tetgen_switches: %s",
             bad_switches.c_str());
  PetscCheck(meshing->max_volume >= 0 && std::isfinite(meshing->max_volume), comm,
             PETSC_ERR_USER_INPUT, "option -tetgen_max_volume: must be >= 0 (got %s)",
             FormatNumber(meshing->max_volume).c_str());
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ProcessSceneOptions(MPI_Comm comm, SceneOptions *options) {
  PetscFunctionBeginUser;
  char path[PETSC_MAX_PATH_LEN] = "";
  PetscOptionsBegin(comm, nullptr, "Scene", nullptr);
  PetscCall(PetscOptionsString("-scene", "Scene file (num_meshes, mesh lines, optional velocities)",
                               nullptr, path, path, sizeof(path), nullptr));
  PetscCall(PetscOptionsBool("-scene_replicate",
                             "Hold every mesh whole on every rank (by default each rank holds its "
                             "slabs, and with contact the fixed bodies' meshes whole until "
                             "contact's set-up)",
                             nullptr, options->replicate, &options->replicate, nullptr));
  PetscOptionsEnd();
  options->path = path;
  PetscCall(ProcessMeshingOptions(comm, &options->meshing));
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// MPI counts are ints: larger arrays travel in pieces of at most this many bytes.
constexpr size_t kBroadcastPieceBytes = size_t(1) << 30;

template <typename T>
PetscErrorCode BroadcastArray(MPI_Comm comm, T *data, size_t count) {
  PetscFunctionBeginUser;
  const size_t piece = kBroadcastPieceBytes / sizeof(T);  // elements
  for (size_t begin = 0; begin < count; begin += piece) {
    const int bytes = static_cast<int>(std::min(piece, count - begin) * sizeof(T));
    PetscCallMPI(MPI_Bcast(data + begin, bytes, MPI_BYTE, 0, comm));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode BroadcastString(MPI_Comm comm, std::string *text) {
  PetscFunctionBeginUser;
  uint64_t size = text->size();
  PetscCallMPI(MPI_Bcast(&size, 1, MPI_UINT64_T, 0, comm));
  text->resize(size);
  PetscCall(BroadcastArray(comm, text->data(), size));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Rank 0's body header (path, material, flags, counts) on every rank.
PetscErrorCode BroadcastBodyHeader(MPI_Comm comm, Body *body) {
  PetscFunctionBeginUser;
  PetscCall(BroadcastString(comm, &body->mesh_path));
  PetscCall(BroadcastArray(comm, &body->material, 1));
  PetscCall(BroadcastArray(comm, body->position.data(), 3));
  PetscCall(BroadcastArray(comm, body->quaternion.data(), 4));
  int64_t sizes[6] = {body->fixed,          body->at_rest,    body->first_vertex,
                      body->num_vertices(), body->num_tets(), body->mesh_deferred};
  PetscCallMPI(MPI_Bcast(sizes, 6, MPI_INT64_T, 0, comm));
  body->fixed = sizes[0];
  body->at_rest = sizes[1];
  body->first_vertex = static_cast<int32_t>(sizes[2]);
  body->mesh_deferred = sizes[5];
  if (body->mesh.num_vertices() != sizes[3] || body->mesh.num_tets() != sizes[4]) {
    body->count_vertices = static_cast<int32_t>(sizes[3]);  // the mesh stays on rank 0
    body->count_tets = sizes[4];
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Rank 0's scene header (bodies' headers and the velocity counts) on every rank.
PetscErrorCode BroadcastSceneHeader(MPI_Comm comm, Scene *scene) {
  PetscFunctionBeginUser;
  PetscCall(BroadcastString(comm, &scene->path));
  int64_t sizes[3] = {static_cast<int64_t>(scene->bodies.size()), scene->num_velocity_entries,
                      scene->ignored_fixed_velocities};
  PetscCallMPI(MPI_Bcast(sizes, 3, MPI_INT64_T, 0, comm));
  scene->bodies.resize(sizes[0]);
  for (Body &body : scene->bodies) PetscCall(BroadcastBodyHeader(comm, &body));
  scene->num_velocity_entries = static_cast<int>(sizes[1]);
  scene->ignored_fixed_velocities = static_cast<int>(sizes[2]);
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  scene->meshes_held = rank == 0;
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode BroadcastMeshes(MPI_Comm comm, Scene *scene) {
  PetscFunctionBeginUser;
  for (Body &body : scene->bodies) {
    body.mesh.vertices.resize(body.num_vertices(), 3);
    body.mesh.tets.resize(body.num_tets(), 4);
    body.count_vertices = -1;
    body.count_tets = -1;
    PetscCall(BroadcastArray(comm, body.mesh.vertices.data(), body.mesh.vertices.size()));
    PetscCall(BroadcastArray(comm, body.mesh.tets.data(), body.mesh.tets.size()));
  }
  uint64_t entries = scene->initial_velocities.size();
  PetscCallMPI(MPI_Bcast(&entries, 1, MPI_UINT64_T, 0, comm));
  scene->initial_velocities.resize(entries);
  PetscCall(BroadcastArray(comm, scene->initial_velocities.data(), entries));
  scene->meshes_held = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode LoadScene(MPI_Comm comm, const SceneOptions &options, bool defer_h5_meshes,
                         Scene *scene) {
  PetscFunctionBeginUser;
  PetscCheck(!options.path.empty(), comm, PETSC_ERR_USER_INPUT,
             "option -scene: required (path to a scene file; see -help)");
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  // Rank 0 reads (and runs TetGen) alone; an input error reaches every rank.
  std::string error;
  if (rank == 0) {
    try {
      *scene = ReadScene(options.path, options.meshing, defer_h5_meshes);
    } catch (const InputError &input_error) {
      error = input_error.what();
    } catch (const std::bad_alloc &) {
      error = "out of memory while reading input";
    }
  }
  PetscCall(BroadcastString(comm, &error));
  PetscCheck(error.empty(), comm, PETSC_ERR_USER_INPUT, "%s", error.c_str());
  PetscCall(BroadcastSceneHeader(comm, scene));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
