#include "scene.hpp"

#include <Eigen/Geometry>
#include <filesystem>

#include "errors.hpp"
#include "mesh_io.hpp"
#include "text_reader.hpp"

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
  const Eigen::Quaterniond q(quaternion_wxyz[0], quaternion_wxyz[1], quaternion_wxyz[2],
                             quaternion_wxyz[3]);
  const Eigen::Matrix3d rotation = q.normalized().toRotationMatrix();
  for (int32_t v = 0; v < mesh->num_vertices(); ++v) {
    const Eigen::Vector3d rest = mesh->vertices.row(v).transpose() - centroid;
    mesh->vertices.row(v) = (rotation * rest + position).transpose();
  }
}

namespace {

constexpr int kBodyFields = 12;

Body ReadBodyLine(TextReader &in, const std::vector<std::string_view> &fields,
                  const std::filesystem::path &folder) {
  if (fields.size() != kBodyFields)
    in.Fail("expected 12 fields 'file density young poisson is_fixed px py pz qw qx qy qz', found " +
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
  if (fixed != 0 && fixed != 1) in.Fail("is_fixed must be 0 or 1 (got " + std::string(fields[4]) + ")");
  body.fixed = fixed == 1;
  Eigen::Vector3d position;
  Eigen::Vector4d quaternion;
  for (int c = 0; c < 3; ++c) position[c] = in.ParseReal(fields[5 + c], "position");
  for (int c = 0; c < 4; ++c) quaternion[c] = in.ParseReal(fields[8 + c], "quaternion");
  if (!(quaternion.norm() > 0)) in.Fail("quaternion must be non-zero");
  try {
    body.mesh = ReadTetMesh(body.mesh_path);
  } catch (const InputError &error) {  // say which scene line named the mesh
    in.Fail(std::string("mesh: ") + error.what());
  }
  PlaceMesh(position, quaternion, &body.mesh);
  return body;
}

}  // namespace

Scene ReadScene(const std::string &path) {
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
    scene.bodies.push_back(ReadBodyLine(in, fields, folder));
    scene.bodies.back().first_vertex = first_vertex;
    first_vertex += scene.bodies.back().mesh.num_vertices();
  }
  scene.initial_velocities.setZero(first_vertex, 3);

  if (!in.NextLine(&fields)) return scene;  // no velocity section: all at rest
  if (fields.size() != 1) in.Fail("expected one field, num_velocities");
  const long num_velocities = in.ParseInteger(fields[0], "num_velocities");
  if (num_velocities < 0) in.Fail("num_velocities must be >= 0");
  for (long i = 0; i < num_velocities; ++i) {
    if (!in.NextLine(&fields))
      in.Fail("expected " + std::to_string(num_velocities) + " velocity lines, found " +
              std::to_string(i));
    if (fields.size() != 5) in.Fail("expected 5 fields 'mesh vertex vx vy vz', found " +
                                    std::to_string(fields.size()));
    const long b = in.ParseInteger(fields[0], "mesh index");
    if (b < 0 || b >= num_meshes)
      in.Fail("mesh index " + std::to_string(b) + " out of range 0.." + std::to_string(num_meshes - 1));
    const Body &body = scene.bodies[b];
    const long v = in.ParseInteger(fields[1], "vertex index");
    if (v < 0 || v >= body.mesh.num_vertices())
      in.Fail("vertex index " + std::to_string(v) + " out of range 0.." +
              std::to_string(body.mesh.num_vertices() - 1) + " of mesh " + std::to_string(b));
    for (int c = 0; c < 3; ++c)
      scene.initial_velocities(body.first_vertex + v, c) = in.ParseReal(fields[2 + c], "velocity");
    ++scene.num_velocity_entries;
    if (body.fixed) ++scene.ignored_fixed_velocities;
  }
  if (in.NextLine(&fields)) in.Fail("unexpected content after the velocity section");
  for (const Body &body : scene.bodies)
    if (body.fixed)
      scene.initial_velocities.middleRows(body.first_vertex, body.mesh.num_vertices()).setZero();
  return scene;
}

}  // namespace softbody

namespace softbody {

PetscErrorCode ProcessSceneOptions(MPI_Comm comm, std::string *path) {
  PetscFunctionBeginUser;
  char buffer[PETSC_MAX_PATH_LEN] = "";
  PetscOptionsBegin(comm, nullptr, "Scene", nullptr);
  PetscCall(PetscOptionsString("-scene", "Scene file (num_meshes, mesh lines, optional velocities)",
                               nullptr, buffer, buffer, sizeof(buffer), nullptr));
  PetscOptionsEnd();
  *path = buffer;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode LoadScene(MPI_Comm comm, const std::string &path, Scene *scene) {
  PetscFunctionBeginUser;
  PetscCheck(!path.empty(), comm, PETSC_ERR_USER_INPUT,
             "option -scene: required (path to a scene file; see -help)");
  SOFTBODY_CATCH_INPUT(comm, *scene = ReadScene(path));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
