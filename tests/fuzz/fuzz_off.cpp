// libFuzzer target: the OFF surface reader (ReadOffSurface, src/io/mesh_io.hpp), the
// part of ReadOff before TetGen runs (TetGen itself is not fuzzed here). An
// accepted surface must have >= 4 distinct finite vertices and >= 4 faces of >= 3
// distinct in-range vertices.
#include <array>
#include <set>

#include "fuzz_input.hpp"
#include "io/mesh_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  using namespace softbody;
  fuzz::ParseOrReject([&] {
    const OffSurface surface = ReadOffSurface(fuzz::Folder().Write("input.off", data, size));
    const size_t nv = surface.vertices.size();
    fuzz::Require(nv >= 4 && surface.faces.size() >= 4, "fewer than 4 vertices or faces");
    fuzz::Require(surface.vertex_lines.size() == nv, "one line per vertex");
    std::set<std::array<double, 3>> distinct;
    for (const Eigen::RowVector3d &x : surface.vertices) {
      fuzz::Require(x.allFinite(), "non-finite vertex");
      distinct.insert({x[0], x[1], x[2]});
    }
    fuzz::Require(distinct.size() == nv, "repeated vertex");
    for (const std::vector<int32_t> &face : surface.faces) {
      fuzz::Require(face.size() >= 3, "face of fewer than 3 vertices");
      for (int32_t v : face)
        fuzz::Require(v >= 0 && static_cast<size_t>(v) < nv, "face vertex out of range");
      fuzz::Require(std::set<int32_t>(face.begin(), face.end()).size() == face.size(),
                    "face repeats a vertex");
    }
  });
  return 0;
}
