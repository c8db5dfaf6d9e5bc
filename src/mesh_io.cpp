#include "mesh_io.hpp"

#include <cmath>
#include <map>

#include "element.hpp"
#include "errors.hpp"
#include "text_reader.hpp"

namespace softbody {

static bool EndsWith(const std::string &s, const std::string &suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

TetMesh ReadTetMesh(const std::string &path) {
  if (EndsWith(path, ".mesh")) return ReadMedit(path);
  throw InputError(Where(path, 0, "unknown mesh format (expected a MEDIT .mesh file)"));
}

namespace {

// Sections of MEDIT files that we skip: number of integers per row.
const std::map<std::string, int> kSkippedSections = {
    {"Edges", 3},           {"Triangles", 4},       {"Quadrilaterals", 5},
    {"Hexahedra", 9},       {"Prisms", 7},          {"Corners", 1},
    {"Ridges", 1},          {"RequiredVertices", 1}, {"RequiredEdges", 1},
    {"RequiredTriangles", 1}, {"Normals", 3},       {"Tangents", 3},
    {"NormalAtVertices", 2}, {"TangentAtEdges", 3}};

// A section's row count. A row takes at least one byte, so a count beyond the
// bytes left is rejected before anything is allocated (a short section is
// reported where the file ends).
long ExpectCount(TextReader &in, const char *section) {
  const long count = in.ExpectInteger((std::string("number of ") + section).c_str());
  if (count < 0) in.Fail(std::string("negative number of ") + section);
  if (static_cast<size_t>(count) > in.remaining_bytes())
    in.Fail(std::to_string(count) + " " + section + " announced, more than the rest of the file holds");
  return count;
}

void CheckTet(const TetMesh &mesh, int32_t t, TextReader &in) {
  TetPositions X;
  for (int a = 0; a < 4; ++a) X.row(a) = mesh.vertices.row(mesh.tets(t, a));
  const double length = LongestEdge(X);
  if (!(std::abs(SignedVolume(X)) > kDegenerateVolume * length * length * length))
    in.Fail("tetrahedron " + std::to_string(t + 1) + " is degenerate (zero volume)");
}

}  // namespace

TetMesh ReadMedit(const std::string &path) {
  TextReader in(path);
  TetMesh mesh;
  bool have_vertices = false, have_tets = false;
  std::string_view keyword;
  while (in.NextToken(&keyword)) {
    if (keyword == "End") break;
    if (keyword == "MeshVersionFormatted") {
      in.ExpectInteger("mesh version");
    } else if (keyword == "Dimension") {
      if (in.ExpectInteger("dimension") != 3) in.Fail("only 3-dimensional meshes are supported");
    } else if (keyword == "Vertices") {
      if (have_vertices) in.Fail("second Vertices section");
      const long n = ExpectCount(in, "vertices");
      mesh.vertices.resize(n, 3);
      for (long v = 0; v < n; ++v) {
        for (int c = 0; c < 3; ++c) mesh.vertices(v, c) = in.ExpectReal("vertex coordinate");
        in.ExpectInteger("vertex reference");
      }
      have_vertices = true;
    } else if (keyword == "Tetrahedra") {
      if (!have_vertices) in.Fail("Tetrahedra before Vertices");
      if (have_tets) in.Fail("second Tetrahedra section");
      const long n = ExpectCount(in, "tetrahedra");
      mesh.tets.resize(n, 4);
      for (long t = 0; t < n; ++t) {
        for (int a = 0; a < 4; ++a) {
          const long index = in.ExpectInteger("tetrahedron vertex index");
          if (index < 1 || index > mesh.num_vertices())
            in.Fail("tetrahedron " + std::to_string(t + 1) + ": vertex index " +
                    std::to_string(index) + " out of range 1.." +
                    std::to_string(mesh.num_vertices()));
          mesh.tets(t, a) = static_cast<int32_t>(index - 1);
        }
        in.ExpectInteger("tetrahedron reference");
        CheckTet(mesh, static_cast<int32_t>(t), in);
      }
      have_tets = true;
    } else {
      const auto section = kSkippedSections.find(std::string(keyword));
      if (section == kSkippedSections.end())
        in.Fail("unknown MEDIT keyword '" + std::string(keyword) + "'");
      const long n = ExpectCount(in, section->first.c_str());
      for (long row = 0; row < n * section->second; ++row) in.ExpectToken(section->first.c_str());
    }
  }
  if (!have_tets || mesh.num_tets() == 0) in.Fail("no tetrahedra in the mesh");
  return mesh;
}

}  // namespace softbody
