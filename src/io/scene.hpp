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
#include <array>
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
  TetMesh mesh;          // placed: the rest positions in the world; empty where not held
  int32_t first_vertex;  // natural index of the body's vertex 0
  // The mesh's counts where the mesh is not held (-1: it is).
  int32_t count_vertices = -1;
  int64_t count_tets = -1;
  // The placement as the scene gives it (m; w, x, y, z; see PlaceMesh).
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector4d quaternion = Eigen::Vector4d(1, 0, 0, 0);
  // A softbody .h5 mesh not read yet (ReadScene with defer_h5_meshes): only its
  // counts are known; it is read in slabs (DistributeScene) or by LoadDeferredMeshes.
  bool mesh_deferred = false;

  int32_t num_vertices() const {
    return count_vertices >= 0 ? count_vertices : mesh.num_vertices();
  }
  int64_t num_tets() const { return count_tets >= 0 ? count_tets : mesh.num_tets(); }
};

// A vertex's initial velocity, from a line of the scene's velocity section.
struct InitialVelocity {
  int64_t vertex;                  // natural index
  std::array<double, 3> velocity;  // m/s
};

struct Scene {
  std::string path;
  std::vector<Body> bodies;
  // The velocity section's entries on bodies that are not fixed, by increasing
  // natural vertex, one per vertex (a later line for a vertex replaces an
  // earlier one); every other vertex starts at rest. O(entries), not O(vertices):
  // held where the meshes are (DropMeshes frees it).
  std::vector<InitialVelocity> initial_velocities;
  int num_velocity_entries = 0;      // entries in the file's velocity section
  int ignored_fixed_velocities = 0;  // of which on fixed bodies (they never move)
  // Whether this rank holds the bodies' meshes and the initial velocities
  // (DistributeScene); the counts are known either way.
  bool meshes_held = true;
  // Whether the meshes were whole on every rank for contact's set-up and
  // released after it (ReleaseMeshes).
  bool meshes_released = false;
  // Bytes of the meshes and initial velocities this rank held when contact was
  // set up (ReleaseMeshes; 0 before).
  int64_t contact_setup_mesh_bytes = 0;
  // Bodies whose mesh file every rank read in slabs (deferred .h5 meshes)
  // instead of receiving them from rank 0 (DistributeScene).
  int meshes_read_in_slabs = 0;

  int32_t num_vertices() const;
  int64_t num_tets() const;
  // Not collective. Frees the meshes and initial velocities, keeping the counts.
  void DropMeshes();
  // Not collective. Bytes of the meshes and initial velocities this rank holds.
  int64_t MeshBytes() const;
  // Not collective. DropMeshes once contact has built its structures from the
  // meshes it holds (meshes_released, contact_setup_mesh_bytes).
  void ReleaseMeshes() {
    meshes_released = meshes_held;
    contact_setup_mesh_bytes = MeshBytes();
    DropMeshes();
  }
};

// Not collective. The initial velocities as a #V x 3 matrix in natural order (m/s),
// zero where none is given: for small scenes and tests.
Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> DenseInitialVelocities(
    const Scene &scene);

// Reads and validates a scene and its meshes (OFF surfaces meshed with `meshing`);
// with defer_h5_meshes, softbody .h5 meshes are only opened for their counts
// (Body::mesh_deferred). Not collective; throws InputError.
Scene ReadScene(const std::string &path, const MeshingOptions &meshing = MeshingOptions(),
                bool defer_h5_meshes = false);

// Not collective. Reads and places the deferred meshes (throws InputError "scene: ...").
void LoadDeferredMeshes(const MeshingOptions &meshing, Scene *scene);

// Not collective. Whether `path` names a softbody .h5 mesh file (by its extension).
bool IsMeshH5Path(const std::string &path);

// Moves the volume-weighted centroid to the origin, rotates by the quaternion
// (w, x, y, z; normalised here, must be non-zero), then translates by position.
void PlaceMesh(const Eigen::Vector3d &position, const Eigen::Vector4d &quaternion_wxyz,
               TetMesh *mesh);
// The same placement of rows of a mesh's vertices, given the mesh's
// volume-weighted centroid (VolumeWeightedCentroid): rotation (rest - centroid) + position.
void PlaceVertices(const Eigen::Vector3d &centroid, const Eigen::Vector3d &position,
                   const Eigen::Vector4d &quaternion_wxyz,
                   Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> *vertices);

}  // namespace softbody

#include <petscsys.h>

namespace softbody {

struct SceneOptions {
  std::string path;        // -scene: the scene file
  MeshingOptions meshing;  // -tetgen_switches, -tetgen_max_volume: for .off meshes
  // -scene_replicate: every rank holds every mesh, also when contact does not need them.
  PetscBool replicate = PETSC_FALSE;
};

// Collective. Reads -tetgen_switches and -tetgen_max_volume (how .off surfaces
// are meshed) and checks them.
PetscErrorCode ProcessMeshingOptions(MPI_Comm comm, MeshingOptions *meshing);

// Collective. Reads -scene (the scene file path; required unless -help) and the
// meshing options (ProcessMeshingOptions).
PetscErrorCode ProcessSceneOptions(MPI_Comm comm, SceneOptions *options);

// Collective: rank 0 reads the scene and its meshes (TetGen runs once, there;
// .h5 meshes only for their counts with defer_h5_meshes) and broadcasts the
// bodies' materials, flags, placements and counts; the meshes stay on rank 0
// until DistributeScene. Input errors become one PETSC_ERR_USER_INPUT error on
// every rank.
PetscErrorCode LoadScene(MPI_Comm comm, const SceneOptions &options, bool defer_h5_meshes,
                         Scene *scene);

// Collective. Rank 0's meshes and initial velocities on every rank (after LoadScene).
PetscErrorCode BroadcastMeshes(MPI_Comm comm, Scene *scene);

}  // namespace softbody
