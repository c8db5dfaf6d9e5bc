// libFuzzer target: the scene reader (ReadScene, src/io/scene.hpp). The fuzzed scene
// sits next to the small meshes of fuzz::WriteMeshes, so mesh lines that name them
// load a mesh and the velocity section is reached. OFF bodies are parsed but never
// meshed: the TetGen switches given are refused, which ReadOff checks after parsing
// the surface and before running TetGen (a process per input would be slow).
// An accepted scene must have consistent vertex numbering, finite values and
// bodies placed by a rigid motion.
#include <cmath>

#include "fuzz_input.hpp"
#include "io/scene.hpp"

extern "C" int LLVMFuzzerInitialize(int *, char ***) {
  softbody::fuzz::WriteMeshes(softbody::fuzz::Folder());
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  using namespace softbody;
  MeshingOptions no_tetgen;
  no_tetgen.tetgen_switches = "-";  // refused: not a switch letter
  fuzz::ParseOrReject([&] {
    const Scene scene = ReadScene(fuzz::Folder().Write("scene.txt", data, size), no_tetgen);
    fuzz::Require(!scene.bodies.empty(), "no bodies");
    int64_t vertices = 0;
    for (const Body &body : scene.bodies) {
      fuzz::Require(body.first_vertex == vertices, "first_vertex numbering");
      fuzz::Require(body.mesh.num_tets() > 0, "body without tets");
      fuzz::Require(body.mesh.vertices.allFinite(), "non-finite placed vertex");
      fuzz::Require(body.material.density > 0 && body.material.young > 0, "material");
      fuzz::Require(body.material.poisson > -1 && body.material.poisson < 0.5, "Poisson ratio");
      // Placement is a rigid motion: distances from vertex 0 as in the mesh file, up
      // to rounding of the placed coordinates.
      const TetMesh file = ReadTetMesh(body.mesh_path, no_tetgen);
      fuzz::Require(file.num_vertices() == body.mesh.num_vertices(), "vertex count");
      const double extent = body.mesh.vertices.cwiseAbs().maxCoeff();
      for (int32_t v = 1; v < file.num_vertices(); ++v) {
        const double d_file = (file.vertices.row(v) - file.vertices.row(0)).norm();
        const double d_placed = (body.mesh.vertices.row(v) - body.mesh.vertices.row(0)).norm();
        fuzz::Require(std::abs(d_placed - d_file) <= 1e-9 * d_file + 1e-14 * extent,
                      "placement is not rigid");
      }
      vertices += body.mesh.num_vertices();
    }
    fuzz::Require(scene.num_vertices() == vertices, "velocity rows");
    int64_t previous = -1;  // entries by increasing vertex, one each, finite, in range
    for (const softbody::InitialVelocity &entry : scene.initial_velocities) {
      fuzz::Require(entry.vertex > previous && entry.vertex < scene.num_vertices(),
                    "velocity entries out of order or range");
      previous = entry.vertex;
      for (double component : entry.velocity)
        fuzz::Require(std::isfinite(component), "non-finite velocity");
    }
    fuzz::Require(scene.initial_velocities.size() + scene.ignored_fixed_velocities <=
                      static_cast<size_t>(scene.num_velocity_entries),
                  "velocity entries");
    fuzz::Require(scene.ignored_fixed_velocities <= scene.num_velocity_entries, "velocity counts");
  });
  return 0;
}
