// libFuzzer target: the distance-constraints reader (ReadConstraints,
// src/contact/distance_constraints.hpp), against a fixed scene of two bodies (cube.mesh, tet.mesh
// of fuzz::WriteMeshes). An accepted constraint joins two distinct in-range vertices with 0 <=
// lower <= upper.
#include "contact/contact.hpp"
#include "fuzz_input.hpp"
#include "io/scene.hpp"

namespace {
softbody::Scene *scene = nullptr;
}

extern "C" int LLVMFuzzerInitialize(int *, char ***) {
  using namespace softbody;
  fuzz::WriteMeshes(fuzz::Folder());
  const std::string path = fuzz::Folder().Write(
      "constraints-scene.txt",
      "2\ncube.mesh 1000 1e5 0.3 0  0 0 0  1 0 0 0\ntet.mesh 1000 1e5 0.3 1  3 0 0  1 0 0 0\n");
  scene = new Scene(ReadScene(path));
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  using namespace softbody;
  fuzz::ParseOrReject([&] {
    const std::vector<DistanceConstraint> constraints =
        ReadConstraints(fuzz::Folder().Write("constraints.txt", data, size), *scene);
    for (const DistanceConstraint &c : constraints) {
      fuzz::Require(
          c.a >= 0 && c.a < scene->num_vertices() && c.b >= 0 && c.b < scene->num_vertices(),
          "vertex out of range");
      fuzz::Require(c.a != c.b, "constraint of a vertex with itself");
      fuzz::Require(c.lower >= 0 && c.lower <= c.upper, "bounds");
    }
  });
  return 0;
}
