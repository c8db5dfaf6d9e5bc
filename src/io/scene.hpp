// Scenes: bodies with material, placement and initial velocities.
//
// File format (whitespace-separated, '#' starts a comment, blank lines ignored):
//   num_meshes
//   file density young poisson is_fixed  px py pz  qw qx qy qz     (num_meshes lines)
//   num_velocities                                                  (optional section)
//   mesh_index vertex_index vx vy vz                                (0-based indices)
// Units: density kg/m^3, young Pa, positions m, velocities m/s. Mesh paths are
// relative to the scene file; a mesh is a MEDIT .mesh, a gmsh .msh or an OFF
// surface .off, tetrahedralised by TetGen on load (see mesh_io.hpp; the OFF
// vertices stay the mesh's first vertices, so velocity indices refer to them).
// Placement: the mesh's volume-weighted centroid is moved to the origin, rotated
// by the normalised quaternion (w, x, y, z), then translated by p.
//
// Natural vertex order: body 0's vertices in file order, then body 1's, ...
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "fem/mesh.hpp"
#include "io/mesh_io.hpp"

namespace softbody {

struct Material {
  double density;  // kg/m^3, > 0
  double young;    // Pa, > 0
  double poisson;  // in (-1, 0.5)
};

struct Body {
  std::string mesh_path;  // as resolved against the scene's folder
  Material material;
  bool fixed;            // immobile: contributes no unknowns
  bool at_rest = false;  // free in the file, but nothing can set it in motion: treated as fixed
  TetMesh mesh;          // placed: vertices are the rest positions in the world
  int32_t first_vertex;  // natural index of the body's vertex 0
};

struct Scene {
  std::string path;
  std::vector<Body> bodies;
  // Natural order, #V x 3 initial velocities (m/s), zero where none is given.
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> initial_velocities;
  int num_velocity_entries = 0;      // entries in the file's velocity section
  int ignored_fixed_velocities = 0;  // of which on fixed bodies (they never move)

  int32_t num_vertices() const;
  int64_t num_tets() const;
};

// Reads and validates a scene and its meshes (OFF surfaces meshed with `meshing`).
// Not collective; throws InputError.
Scene ReadScene(const std::string &path, const MeshingOptions &meshing = MeshingOptions());

// Moves the volume-weighted centroid to the origin, rotates by the quaternion
// (w, x, y, z; normalised here, must be non-zero), then translates by position.
void PlaceMesh(const Eigen::Vector3d &position, const Eigen::Vector4d &quaternion_wxyz,
               TetMesh *mesh);

}  // namespace softbody

#include <petscsys.h>

namespace softbody {

struct SceneOptions {
  std::string path;        // -scene: the scene file
  MeshingOptions meshing;  // -tetgen_switches, -tetgen_max_volume: for .off meshes
};

// Collective. Reads -tetgen_switches and -tetgen_max_volume (how .off surfaces
// are meshed) and checks them.
PetscErrorCode ProcessMeshingOptions(MPI_Comm comm, MeshingOptions *meshing);

// Collective. Reads -scene (the scene file path; required unless -help) and the
// meshing options (ProcessMeshingOptions).
PetscErrorCode ProcessSceneOptions(MPI_Comm comm, SceneOptions *options);

// Collective: rank 0 reads the scene and its meshes (TetGen runs once, there) and
// broadcasts them, so every rank holds the whole scene. Input errors become one
// PETSC_ERR_USER_INPUT error on every rank.
PetscErrorCode LoadScene(MPI_Comm comm, const SceneOptions &options, Scene *scene);

}  // namespace softbody
