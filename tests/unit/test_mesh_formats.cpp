// Unit tests of the OFF (TetGen) and gmsh readers (src/io/mesh_io.hpp) and of scenes
// that mix .off, .mesh and .msh files (src/io/scene.hpp).
//
// Files: tests/data/meshes/ (run from tests/, as ctest does; see tests/data/meshes/README.md).
// Every check of a tetrahedralisation is independent of the reader: this file
// parses the OFF surfaces itself and measures volumes with its own determinants.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "common/errors.hpp"
#include "fem/mesh.hpp"
#include "input_checks.hpp"
#include "io/mesh_io.hpp"
#include "io/scene.hpp"

namespace softbody {
namespace {

namespace fs = std::filesystem;

const std::string kMeshes = "meshes/";

using testing::At;
using testing::InputErrorOf;

// ------------------------------------------------ independent geometry

// An OFF surface read by this test's own parser: '#' comments, counts, vertex
// rows, face rows "k i1 .. ik [colour]".
struct Surface {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::vector<int>> faces;
};

Surface ReadSurface(const std::string &path) {
  std::ifstream file(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(file, line);) {
    line = line.substr(0, line.find('#'));
    if (line.find_first_not_of(" \t\r") != std::string::npos) lines.push_back(line);
  }
  Surface surface;
  std::istringstream counts(lines.at(1));
  int nv, nf;
  counts >> nv >> nf;
  for (int v = 0; v < nv; ++v) {
    std::istringstream row(lines.at(2 + v));
    Eigen::Vector3d x;
    row >> x[0] >> x[1] >> x[2];
    surface.vertices.push_back(x);
  }
  for (int f = 0; f < nf; ++f) {
    std::istringstream row(lines.at(2 + nv + f));
    int k;
    row >> k;
    std::vector<int> face(k);
    for (int &index : face) row >> index;
    surface.faces.push_back(face);
  }
  return surface;
}

// Divergence theorem: sum over triangles (a, b, c) of a . (b x c) / 6.
double TriangleVolume(const Eigen::Vector3d &a, const Eigen::Vector3d &b,
                      const Eigen::Vector3d &c) {
  return a.dot(b.cross(c)) / 6;
}

// Volume enclosed by the surface (polygons split into fans), of the sign of its
// orientation.
double EnclosedVolume(const Surface &surface) {
  double volume = 0;
  for (const std::vector<int> &face : surface.faces)
    for (size_t j = 1; j + 1 < face.size(); ++j)
      volume += TriangleVolume(surface.vertices[face[0]], surface.vertices[face[j]],
                               surface.vertices[face[j + 1]]);
  return volume;
}

Eigen::Vector3d Vertex(const TetMesh &mesh, int v) {
  return mesh.vertices.row(v).transpose();
}

double TetVolume(const TetMesh &mesh, int t) {
  const Eigen::Vector3d x0 = Vertex(mesh, mesh.tets(t, 0));
  Eigen::Matrix3d edges;
  for (int a = 1; a < 4; ++a) edges.col(a - 1) = Vertex(mesh, mesh.tets(t, a)) - x0;
  return edges.determinant() / 6;
}

double BoundaryVolume(const TetMesh &mesh) {
  const auto faces = BoundaryTriangles(mesh);
  double volume = 0;
  for (int f = 0; f < faces.rows(); ++f)
    volume += TriangleVolume(Vertex(mesh, faces(f, 0)), Vertex(mesh, faces(f, 1)),
                             Vertex(mesh, faces(f, 2)));
  return volume;
}

// The checks every tetrahedralisation of a closed OFF surface must pass: the OFF
// vertices first and unchanged, positive tets filling exactly the enclosed volume,
// the boundary enclosing it too. Returns the largest tet volume.
double ExpectFillsSurface(const std::string &off_path, const TetMesh &mesh) {
  const Surface surface = ReadSurface(off_path);
  const int nv = static_cast<int>(surface.vertices.size());
  EXPECT_GE(mesh.num_vertices(), nv) << off_path;
  for (int v = 0; v < std::min(nv, mesh.num_vertices()); ++v)
    EXPECT_EQ(Vertex(mesh, v), surface.vertices[v]) << off_path << ": vertex " << v;
  const double enclosed = std::abs(EnclosedVolume(surface));
  double total = 0, largest = 0;
  int non_positive = 0;
  for (int t = 0; t < mesh.num_tets(); ++t) {
    const double volume = TetVolume(mesh, t);
    if (!(volume > 0)) ++non_positive;
    total += volume;
    largest = std::max(largest, volume);
  }
  EXPECT_EQ(non_positive, 0) << off_path << ": tets of volume <= 0";
  EXPECT_NEAR(total / enclosed, 1.0, 1e-10)
      << off_path << ": tet volumes vs enclosed volume " << enclosed;
  EXPECT_NEAR(BoundaryVolume(mesh) / enclosed, 1.0, 1e-10)
      << off_path << ": boundary faces' volume";
  for (int t = 0; t < mesh.num_tets(); ++t)
    for (int a = 0; a < 4; ++a) EXPECT_LT(mesh.tets(t, a), mesh.num_vertices());
  return largest;
}

// TMPDIR set to a fresh folder for the test (ReadOff's temporary folders go there),
// so that the test can see that none is left behind.
class OffTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::random_device entropy;
    const auto *info = ::testing::UnitTest::GetInstance()->current_test_info();
    folder_ =
        fs::temp_directory_path() / ("softbody_test_mesh_formats_" + std::string(info->name()) +
                                     "_" + std::to_string(entropy()));
    fs::create_directories(folder_);
    const char *tmpdir = std::getenv("TMPDIR");
    had_tmpdir_ = tmpdir != nullptr;
    if (had_tmpdir_) old_tmpdir_ = tmpdir;
    setenv("TMPDIR", folder_.c_str(), 1);
  }
  void TearDown() override {
    EXPECT_TRUE(fs::is_empty(folder_)) << "ReadOff left files in " << folder_;
    if (had_tmpdir_)
      setenv("TMPDIR", old_tmpdir_.c_str(), 1);
    else
      unsetenv("TMPDIR");
    fs::remove_all(folder_);
  }

  fs::path folder_;
  bool had_tmpdir_ = false;
  std::string old_tmpdir_;
};

// -------------------------------------------------------------------- OFF

TEST_F(OffTest, QuadBoxFillsItsVolume) {
  const std::string path = kMeshes + "box_quads.off";
  const TetMesh mesh = ReadOff(path, MeshingOptions());
  EXPECT_GT(mesh.num_tets(), 0);
  ExpectFillsSurface(path, mesh);
  EXPECT_NEAR(std::abs(EnclosedVolume(ReadSurface(path))), 1.0, 1e-15);  // 2 x 1 x 0.5
  // The colours after the indices are not coordinates: corner 7 is (1, 1, 0.75).
  EXPECT_EQ(Vertex(mesh, 7), Eigen::Vector3d(1, 1, 0.75));
  EXPECT_EQ(ReadTetMesh(path).tets, mesh.tets);  // dispatch on .off, same default switches
}

TEST_F(OffTest, TriangleCubeFillsItsVolume) {
  const std::string path = kMeshes + "cube_triangles.off";
  const TetMesh mesh = ReadOff(path, MeshingOptions());
  ExpectFillsSurface(path, mesh);
}

TEST_F(OffTest, MaxVolumeBoundsEveryTet) {
  const std::string path = kMeshes + "box_quads.off";
  const int coarse = ReadOff(path, MeshingOptions()).num_tets();
  for (const double bound : {0.05, 0.004}) {
    MeshingOptions meshing;
    meshing.max_volume = bound;
    const TetMesh mesh = ReadOff(path, meshing);
    const double largest = ExpectFillsSurface(path, mesh);
    EXPECT_LE(largest, bound * (1 + 1e-12)) << "bound " << bound;
    EXPECT_GE(mesh.num_tets(), 1.0 / bound)
        << "bound " << bound << ": volume 1 needs that many tets";
    EXPECT_GT(mesh.num_tets(), coarse);
  }
}

TEST_F(OffTest, SwitchesReachTetgen) {
  // Y keeps the surface triangulation: no points added on the box's faces, so the
  // boundary is the 12 triangles of the 6 quads, on the 8 corners only.
  const std::string path = kMeshes + "box_quads.off";
  MeshingOptions meshing;
  meshing.tetgen_switches = "pq1.414Y";
  const TetMesh mesh = ReadOff(path, meshing);
  ExpectFillsSurface(path, mesh);
  const auto faces = BoundaryTriangles(mesh);
  EXPECT_EQ(faces.rows(), 12);
  EXPECT_LT(faces.maxCoeff(), 8);
  // Plain p (no quality bound) on a cube adds no point at all.
  meshing.tetgen_switches = "p";
  EXPECT_EQ(ReadOff(path, meshing).num_vertices(), 8);
}

TEST_F(OffTest, OpenSurfaceIsRejected) {
  const std::string path = kMeshes + "open_box.off";
  const std::string message = InputErrorOf([&] { ReadOff(path, MeshingOptions()); });
  EXPECT_CONTAINS(message, path + ": ");
  EXPECT_CONTAINS(message, "encloses no volume");
}

TEST_F(OffTest, PartlyOpenSurfaceIsRejected) {
  // A closed cube (vertices 0-7) and, beside it, a box without its top (8-15):
  // TetGen meshes the cube and leaves the open box's vertices out of every tet.
  const fs::path path = folder_ / "partly_open.off";
  std::ofstream file(path);
  file << "OFF\n16 11 0\n";
  for (const double shift : {0.0, 3.0})
    for (int v = 0; v < 8; ++v) file << v % 2 + shift << ' ' << (v / 2) % 2 << ' ' << v / 4 << '\n';
  file << "4 0 2 3 1\n4 4 5 7 6\n4 0 1 5 4\n4 2 6 7 3\n4 0 4 6 2\n4 1 3 7 5\n";
  for (const char *quad : {"0 2 3 1", "0 1 5 4", "2 6 7 3", "0 4 6 2", "1 3 7 5"}) {
    std::istringstream corners(quad);
    file << 4;
    for (int corner; corners >> corner;) file << ' ' << corner + 8;
    file << '\n';
  }
  file.close();
  const std::string message = InputErrorOf([&] { ReadOff(path.string(), MeshingOptions()); });
  fs::remove(path);
  EXPECT_CONTAINS(message, "surface vertex 8 (line 11)");
  EXPECT_CONTAINS(message, "encloses no volume");
}

TEST_F(OffTest, SelfIntersectingSurfaceIsRejected) {
  // Face 1 (z = 1 of the first cube) crosses face 8 (y = 0.5 of the second).
  const std::string path = kMeshes + "overlapping_cubes.off";
  const std::string message = InputErrorOf([&] { ReadOff(path, MeshingOptions()); });
  EXPECT_CONTAINS(message, path + ": ");
  EXPECT_CONTAINS(message, "TetGen");
  EXPECT_CONTAINS(message, "intersects itself");
  EXPECT_CONTAINS(message, "faces 1 and 8");
}

TEST_F(OffTest, MissingTetgenIsAnInputError) {
  const std::string path = kMeshes + "box_quads.off";
  const std::string old_path = std::getenv("PATH");
  setenv("PATH", folder_.c_str(), 1);  // a folder without tetgen
  const std::string message = InputErrorOf([&] { ReadOff(path, MeshingOptions()); });
  setenv("PATH", old_path.c_str(), 1);
  EXPECT_CONTAINS(message, path + ": ");
  EXPECT_CONTAINS(message, "'tetgen' is not on PATH");
}

TEST_F(OffTest, MalformedFilesNameTheLine) {
  struct Case {
    const char *file;
    int line;
    const char *message;
  };
  const Case cases[] = {
      {"bad_header.off", 1, "expected the header 'OFF'"},
      {"huge_count.off", 2, "more than the rest of the file holds"},
      {"nan_vertex.off", 6, "not finite"},
      {"duplicate_vertex.off", 9, "vertex 6 repeats the position of vertex 4 (line 7)"},
      {"short_face.off", 13, "face 2 has 2 vertices"},
      {"bad_index.off", 16, "vertex index 8 out of range 0..7"},
      {"truncated.off", 18, "expected 12 face rows, found 8"},
  };
  for (const Case &c : cases) {
    const std::string path = kMeshes + c.file;
    const std::string message = InputErrorOf([&] { ReadOff(path, MeshingOptions()); });
    EXPECT_CONTAINS(message, At(path, c.line)) << c.file;
    EXPECT_CONTAINS(message, c.message) << c.file;
  }
}

TEST_F(OffTest, HeaderVariants) {
  // Counts on the header's line, no edge count, comments, a face row with 5
  // indices for a pentagon would also do; here a tetrahedron.
  const fs::path path = folder_ / "tet.off";
  std::ofstream(path) << "OFF 4 4\n# corners\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
                         "3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n";
  MeshingOptions meshing;
  meshing.tetgen_switches = "p";
  const TetMesh mesh = ReadOff(path.string(), meshing);
  fs::remove(path);
  ASSERT_EQ(mesh.num_tets(), 1);
  EXPECT_NEAR(std::abs(TetVolume(mesh, 0)), 1.0 / 6, 1e-16);

  const fs::path extra = folder_ / "extra.off";
  std::ofstream(extra) << "OFF\n4 4 6\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
                          "3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n3 0 1 2\n";  // line 11
  EXPECT_CONTAINS(InputErrorOf([&] { ReadOff(extra.string(), meshing); }), At(extra.string(), 11));
  fs::remove(extra);
}

TEST(TetgenSwitches, Checked) {
  for (const char *good : {"pq1.414", "p", "pq1.2/10a0.5Y", "pYA", "pq1.414T1e-8", "pzO2"})
    EXPECT_EQ(CheckTetgenSwitches(good), "") << good;
  const std::pair<const char *, const char *> bad[] = {{"", "must start with a switch letter"},
                                                       {"-pq", "must start with a switch letter"},
                                                       {"q1.414", "lacks p"},
                                                       {"pQ", "'Q' is not allowed"},
                                                       {"pV", "'V' is not allowed"},
                                                       {"pr", "'r' is not allowed"},
                                                       {"pE", "'E' is not allowed"},
                                                       {"p q", "' ' is not a TetGen switch"},
                                                       {"p;ls", "';' is not a TetGen switch"}};
  for (const auto &[switches, reason] : bad) EXPECT_CONTAINS(CheckTetgenSwitches(switches), reason);
  MeshingOptions meshing;
  meshing.tetgen_switches = "pV";
  const std::string path = kMeshes + "box_quads.off";
  EXPECT_CONTAINS(InputErrorOf([&] { ReadOff(path, meshing); }), "'V' is not allowed");
}

TEST_F(OffTest, CurvedSurfaceOfGenusOneFillsItsVolume) {
  // tests/data/meshes/torus.off: 576 triangles on a torus; the tets must fill the
  // tube and leave the hole empty (their volumes sum to the enclosed volume).
  const std::string path = kMeshes + "torus.off";
  const TetMesh mesh = ReadOff(path, MeshingOptions());
  ExpectFillsSurface(path, mesh);
  EXPECT_GT(mesh.num_vertices(), 288) << "the quality switch adds interior points";
}

// Seed data only (skipped without ../shared): the coursework's own bunny.off. The
// reader is checked on the project's surfaces above.
TEST_F(OffTest, SeedBunny) {
  const std::string path = "../../../shared/seed-data/infomgp-p3/bunny.off";
  if (!fs::exists(path))
    GTEST_SKIP() << path << " not found (tests that need ../shared skip without it)";
  const auto start = std::chrono::steady_clock::now();
  const TetMesh mesh = ReadOff(path, MeshingOptions());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::cout << "bunny.off: " << mesh.num_vertices() << " vertices, " << mesh.num_tets()
            << " tets with the default switches, in " << seconds << " s\n";
  ExpectFillsSurface(path, mesh);
}

// -------------------------------------------------------------------- gmsh

TEST(ReadGmsh, Versions22And41GiveTheSameMesh) {
  // tests/data/meshes/cube-4.1.msh: gmsh 4.8.4 on cube.geo; cube-2.2.msh: the same
  // mesh saved again as 2.2 (see tests/data/meshes/README.md).
  const TetMesh mesh41 = ReadGmsh(kMeshes + "cube-4.1.msh");
  const TetMesh mesh22 = ReadTetMesh(kMeshes + "cube-2.2.msh");  // dispatch on .msh
  EXPECT_EQ(mesh41.num_vertices(), 45);
  EXPECT_EQ(mesh41.num_tets(), 100);  // the 116 points, lines and triangles are skipped
  EXPECT_EQ(mesh22.vertices, mesh41.vertices);
  EXPECT_EQ(mesh22.tets, mesh41.tets);
  double total = 0;
  for (int t = 0; t < mesh41.num_tets(); ++t) total += std::abs(TetVolume(mesh41, t));
  EXPECT_NEAR(total, 1.0, 1e-13);
  EXPECT_NEAR(std::abs(BoundaryVolume(mesh41)), 1.0, 1e-13);
  EXPECT_EQ(Vertex(mesh41, 0), Eigen::Vector3d(0, 0, 0));  // node 1
  EXPECT_EQ(Vertex(mesh41, 1), Eigen::Vector3d(1, 0, 0));  // node 2
}

using GmshTest = testing::TempFolderTest;

// Two tets sharing the face {0, 1, 2}, their 5 nodes tagged 10, 20, 30, 40, 50,
// and a stray node 60 that no tet uses (kept: it stays where it is).
const double kTwoTetNodes[6][3] = {{0, 0, 0}, {1, 0, 0},  {0, 1, 0},
                                   {0, 0, 1}, {0, 0, -1}, {5, 5, 5}};
const int kTwoTets[2][4] = {{0, 1, 2, 3}, {0, 2, 1, 4}};

void ExpectTwoTets(const TetMesh &mesh) {
  ASSERT_EQ(mesh.num_vertices(), 6);
  ASSERT_EQ(mesh.num_tets(), 2);
  for (int v = 0; v < 6; ++v)
    EXPECT_EQ(Vertex(mesh, v),
              Eigen::Vector3d(kTwoTetNodes[v][0], kTwoTetNodes[v][1], kTwoTetNodes[v][2]));
  for (int t = 0; t < 2; ++t)
    for (int a = 0; a < 4; ++a) EXPECT_EQ(mesh.tets(t, a), kTwoTets[t][a]);
}

const char kTwoTets22[] =
    "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n"                         // 1-3
    "$PhysicalNames\n1\n3 7 \"body # one\"\n$EndPhysicalNames\n"     // 4-7
    "$Nodes\n6\n"                                                    // 8-9
    "10 0 0 0\n20 1 0 0\n30 0 1 0\n40 0 0 1\n50 0 0 -1\n60 5 5 5\n"  // 10-15
    "$EndNodes\n"                                                    // 16
    "$Elements\n4\n"                                                 // 17-18
    "1 2 2 7 1 10 20 30\n"                                           // 19: a triangle
    "2 4 2 7 1 10 20 30 40\n"                                        // 20
    "3 15 2 7 1 60\n"                                                // 21: a point
    "4 4 2 7 1 10 30 20 50\n"                                        // 22
    "$EndElements\n";

const char kTwoTets41[] =
    "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n"
    "$Entities\n0 0 1 1\n1 0 0 0 1 1 0 0 0\n1 0 0 -1 1 1 1 0 0\n$EndEntities\n"
    "$Nodes\n3 6 10 60\n"
    "2 1 1 2\n10\n20\n0 0 0 0.5 0.5\n1 0 0 1 0\n"  // parametric: u v after x y z
    "3 1 0 3\n30\n40\n50\n0 1 0\n0 0 1\n0 0 -1\n"
    "0 2 0 1\n60\n5 5 5\n"
    "$EndNodes\n"
    "$Elements\n2 3 1 3\n"
    "2 1 2 1\n1 10 20 30\n"
    "3 1 4 2\n2 10 20 30 40\n3 10 30 20 50\n"
    "$EndElements\n"
    "$Periodic\n0\n$EndPeriodic\n";

TEST_F(GmshTest, HandWrittenFilesOfBothVersions) {
  ExpectTwoTets(ReadGmsh(Write("two22.msh", kTwoTets22)));
  ExpectTwoTets(ReadGmsh(Write("two41.msh", kTwoTets41)));
}

TEST_F(GmshTest, ErrorsNameFileAndLine) {
  struct Case {
    const char *name;
    std::string text;
    int line;
    const char *message;
  };
  const std::string head =
      "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n"  // 1-5
      "1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n";   // 6-10
  const Case cases[] = {
      {"binary", "$MeshFormat\n4.1 1 8\n\x01\x02\x03\x04\n$EndMeshFormat\n", 2, "binary"},
      {"version", "$MeshFormat\n3.0 0 8\n$EndMeshFormat\n", 2, "MSH version 3.0 is not supported"},
      {"no_header", "$Nodes\n0\n$EndNodes\n", 1, "expected $MeshFormat"},
      {"unknown_tag", head + "$Elements\n1\n1 4 0 1 2 3 5\n$EndElements\n", 13,
       "node tag 5 unknown"},
      {"degenerate", head + "$Elements\n1\n7 4 0 1 2 3 3\n$EndElements\n", 13,
       "element 7 (tetrahedron) is degenerate"},
      {"truncated", head + "$Elements\n2\n1 4 0 1 2 3 4\n2 4 0 1", 14, "end of file"},
      {"huge_count", head + "$Elements\n99999999999\n", 12, "more than the rest of the file holds"},
      {"repeated_tag", "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n2\n1 0 0 0\n1 1 0 0\n", 7,
       "node tag 1 appears twice"},
      {"short_nodes", "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n2\n1 0 0 0\n$EndNodes\n", 7,
       "node tag: '$EndNodes' is not an integer"},
      {"unclosed", head + "$Comments\nhello\n", 11, "has no $EndComments"},
      {"no_tets", head + "$Elements\n1\n1 2 0 1 2 3\n$EndElements\n", 14, "no tetrahedra"},
      {"unknown_type", head + "$Elements\n1\n1 99 0 1 2 3\n$EndElements\n", 13,
       "unknown element type 99"},
      {"blocks_41", "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 2 1 2\n3 1 0 3\n1\n2\n3\n", 6,
       "hold more than the 2 nodes"},
  };
  for (const Case &c : cases) {
    const std::string path = Write(std::string(c.name) + ".msh", c.text);
    const std::string message = InputErrorOf([&] { ReadGmsh(path); });
    EXPECT_CONTAINS(message, At(path, c.line)) << c.name;
    EXPECT_CONTAINS(message, c.message) << c.name;
  }
}

TEST_F(GmshTest, UnknownExtensionListsTheFormats) {
  const std::string path = Write("cube.stl", "solid\n");
  const std::string message = InputErrorOf([&] { ReadTetMesh(path); });
  EXPECT_CONTAINS(message, path);
  for (const char *extension : {".mesh", ".off", ".msh"}) EXPECT_CONTAINS(message, extension);
}

// --------------------------------------------------------- mixed scenes

TEST_F(OffTest, SceneMixesFormats) {
  // tests/data/meshes/mixed-scene.txt: box_quads.off, cube.mesh, cube-4.1.msh,
  // cube-2.2.msh (fixed); velocities on OFF vertex 7 and gmsh node 45.
  const std::string path = kMeshes + "mixed-scene.txt";
  const Scene scene = ReadScene(path, MeshingOptions());
  ASSERT_EQ(scene.bodies.size(), 4u);
  const TetMesh box = ReadOff(kMeshes + "box_quads.off", MeshingOptions());
  const int counts[4] = {box.num_vertices(), 8, 45, 45};
  for (int b = 0; b < 4; ++b)
    EXPECT_EQ(scene.bodies[b].mesh.num_vertices(), counts[b]) << "body " << b;
  EXPECT_EQ(scene.num_vertices(), counts[0] + 8 + 45 + 45);
  // Placement is rigid (identity rotation): OFF vertex 7 keeps its offset from vertex 0.
  const Body &off = scene.bodies[0];
  EXPECT_LT((Vertex(off.mesh, 7) - Vertex(off.mesh, 0) - Eigen::Vector3d(2, 1, 0.5)).norm(), 1e-14);
  const auto velocities = DenseInitialVelocities(scene);
  EXPECT_EQ(velocities.row(off.first_vertex + 7), Eigen::RowVector3d(0, 0, 1));
  EXPECT_EQ(velocities.row(scene.bodies[2].first_vertex + 44), Eigen::RowVector3d(0, 1, 0));
  EXPECT_EQ(velocities.cwiseAbs().sum(), 2.0);
  EXPECT_TRUE(scene.bodies[3].fixed);

  // The meshing options reach the OFF body only.
  MeshingOptions fine;
  fine.max_volume = 0.01;
  const Scene refined = ReadScene(path, fine);
  EXPECT_GT(refined.bodies[0].mesh.num_tets(), 100);
  for (int b = 1; b < 4; ++b) EXPECT_EQ(refined.bodies[b].mesh.tets, scene.bodies[b].mesh.tets);
}

TEST_F(OffTest, SceneErrorInsideAnOffNamesBothFiles) {
  const fs::path scene = folder_ / "scene.txt";
  const std::string off = fs::absolute(kMeshes + "open_box.off").string();
  std::ofstream(scene) << "1\n" << off << " 1000 1e5 0.3 0 0 0 0 1 0 0 0\n";
  const std::string message = InputErrorOf([&] { ReadScene(scene.string()); });
  fs::remove(scene);
  EXPECT_CONTAINS(message, At(scene.string(), 2));
  EXPECT_CONTAINS(message, off + ": ");
}

}  // namespace
}  // namespace softbody
