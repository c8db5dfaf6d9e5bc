// libFuzzer target: the MEDIT .mesh reader (ReadMedit, src/io/mesh_io.hpp).
// An accepted mesh must have tets, finite vertices and in-range corners.
#include <cmath>

#include "fuzz_input.hpp"
#include "io/mesh_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  using namespace softbody;
  fuzz::ParseOrReject([&] {
    const TetMesh mesh = ReadMedit(fuzz::Folder().Write("input.mesh", data, size));
    fuzz::Require(mesh.num_tets() > 0, "no tets");
    fuzz::Require(mesh.vertices.allFinite(), "non-finite vertex");
    fuzz::Require(mesh.tets.minCoeff() >= 0 && mesh.tets.maxCoeff() < mesh.num_vertices(),
                  "tet corner out of range");
  });
  return 0;
}
