// Unit tests of the MEDIT and scene readers (src/io/mesh_io.hpp, src/io/scene.hpp) and
// of the mesh queries (src/fem/mesh.hpp). Files are written to a fresh temporary
// folder per test; every error is an InputError naming "path:line:".
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <array>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <string>

#include "common/errors.hpp"
#include "fem/mesh.hpp"
#include "input_checks.hpp"
#include "io/mesh_io.hpp"
#include "io/scene.hpp"

namespace softbody {
namespace {

namespace fs = std::filesystem;

using TempFolder = testing::TempFolderTest;
using testing::At;
using testing::InputErrorOf;

// A unit cube in MEDIT format: 8 corners (corner i + 2j + 4k at (i, j, k)) and the
// 6 tets around the main diagonal.
const char kCubeMesh[] =
    "MeshVersionFormatted 2\nDimension 3\nVertices\n8\n"
    "0 0 0 0\n1 0 0 0\n0 1 0 0\n1 1 0 0\n0 0 1 0\n1 0 1 0\n0 1 1 0\n1 1 1 0\n"
    "Tetrahedra\n6\n"
    "1 2 4 8 0\n1 2 6 8 0\n1 3 4 8 0\n1 3 7 8 0\n1 5 6 8 0\n1 5 7 8 0\nEnd\n";

// The tet (-3, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1) cut by the plane x = 0 into
// two tets of volumes 1/6 and 1/2, the larger negatively oriented. Its centroid is
// the big tet's vertex mean (-0.5, 0.25, 0.25); neither the mean of the 5 vertices
// (-0.4, 0.2, 0.2) nor the unweighted mean of the tet centroids (-0.25, ...).
const char kSplitTetMesh[] =
    "MeshVersionFormatted 2\nDimension 3\nVertices 5\n"
    "0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n-3 0 0 1\n"
    "Tetrahedra 2\n1 2 3 4 1\n1 3 4 5 1\nEnd\n";
const double kSplitTetVertices[5][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {-3, 0, 0}};

TetMesh UnitCube() {
  TetMesh mesh;
  mesh.vertices.resize(8, 3);
  for (int v = 0; v < 8; ++v) mesh.vertices.row(v) << v % 2, (v / 2) % 2, v / 4;
  mesh.tets.resize(6, 4);
  mesh.tets << 0, 1, 3, 7, 0, 1, 5, 7, 0, 2, 3, 7, 0, 2, 6, 7, 0, 4, 5, 7, 0, 4, 6, 7;
  return mesh;
}

// ---------------------------------------------------------------- ReadMedit

using ReadMeditTest = TempFolder;

TEST_F(ReadMeditTest, ReadsSectionsCommentsTabsAndBlankLines) {
  const std::string path = Write("small.mesh",
                                 "# a hand-written MEDIT file\n"
                                 "MeshVersionFormatted 1\n"
                                 "\n"
                                 "Dimension\t3\n"
                                 "Vertices  # count on the next line\n"
                                 "5\n"
                                 "0.0\t0.0\t0.0\t7\n"
                                 "  1.5 0 0 7\n"
                                 "0 2.5e0 0 7   # trailing comment\n"
                                 "\n"
                                 "0 0 -3.25 7\n"
                                 "1 1 1 0\r\n"  // a Windows line end
                                 "Triangles 2\n"
                                 "1 2 3 4\n"
                                 "1 3 4 4\n"
                                 "Tetrahedra\n"
                                 "2\n"
                                 "1 2 3 4 9\n"
                                 "2\t3 4 5 9\n"
                                 "Edges 0\n"
                                 "End\n");
  const TetMesh mesh = ReadMedit(path);
  ASSERT_EQ(mesh.num_vertices(), 5);
  ASSERT_EQ(mesh.num_tets(), 2);
  Eigen::Matrix<double, 5, 3> vertices;
  vertices << 0, 0, 0, 1.5, 0, 0, 0, 2.5, 0, 0, 0, -3.25, 1, 1, 1;
  EXPECT_EQ((mesh.vertices - vertices).norm(), 0.0);
  Eigen::Matrix<int32_t, 2, 4> tets;
  tets << 0, 1, 2, 3, 1, 2, 3, 4;  // 1-based in the file, 0-based in memory
  EXPECT_EQ(mesh.tets, tets);
  EXPECT_EQ(ReadTetMesh(path).tets, tets);  // dispatch on the .mesh extension
}

TEST_F(ReadMeditTest, ContentAfterEndIsIgnored) {
  const std::string path = Write("after_end.mesh", std::string(kCubeMesh) + "anything at all\n");
  EXPECT_EQ(ReadMedit(path).num_tets(), 6);
}

// Lines 1-9 of a valid file with 4 vertices; tests append what follows.
const char kFourVertices[] =
    "MeshVersionFormatted 2\n"  // 1
    "Dimension 3\n"             // 2
    "# four corners\n"          // 3
    "Vertices\n"                // 4
    "4\n"                       // 5
    "0 0 0 0\n"                 // 6
    "1 0 0 0\n"                 // 7
    "0 1 0 0\n"                 // 8
    "0 0 1 0\n";                // 9

TEST_F(ReadMeditTest, IndexOutOfRangeNamesLine) {
  const std::string path = Write("range.mesh", std::string(kFourVertices) +
                                                   "Tetrahedra 2\n"  // 10
                                                   "1 2 3 4 0\n"     // 11
                                                   "1 2 3 5 0\n"     // 12
                                                   "End\n");
  const std::string message = InputErrorOf([&] { ReadMedit(path); });
  EXPECT_CONTAINS(message, At(path, 12));
  EXPECT_CONTAINS(message, "out of range");
}

TEST_F(ReadMeditTest, IndexZeroIsOutOfRange) {
  const std::string path = Write("zero.mesh", std::string(kFourVertices) +
                                                  "Tetrahedra 1\n"  // 10
                                                  "0 1 2 3 0\n"     // 11
                                                  "End\n");
  EXPECT_CONTAINS(InputErrorOf([&] { ReadMedit(path); }), At(path, 11));
}

TEST_F(ReadMeditTest, DegenerateTetNamesLine) {
  // Tet 2 repeats a vertex; tet 3 is flat (four coplanar corners 1, 2, 3, 5).
  const std::string repeated = Write("repeated.mesh", std::string(kFourVertices) +
                                                          "Tetrahedra 2\n"  // 10
                                                          "1 2 3 4 0\n"     // 11
                                                          "1 2 2 4 0\n"     // 12
                                                          "End\n");
  std::string message = InputErrorOf([&] { ReadMedit(repeated); });
  EXPECT_CONTAINS(message, At(repeated, 12));
  EXPECT_CONTAINS(message, "degenerate");

  const std::string flat = Write("flat.mesh",
                                 "MeshVersionFormatted 2\n"  // 1
                                 "Dimension 3\n"             // 2
                                 "Vertices 5\n"              // 3
                                 "0 0 0 0\n"                 // 4
                                 "1 0 0 0\n"                 // 5
                                 "0 1 0 0\n"                 // 6
                                 "0 0 1 0\n"                 // 7
                                 "1 1 0 0\n"                 // 8
                                 "Tetrahedra 3\n"            // 9
                                 "1 2 3 4 0\n"               // 10
                                 "2 3 4 5 0\n"               // 11
                                 "1 2 3 5 0\n"               // 12
                                 "End\n");
  message = InputErrorOf([&] { ReadMedit(flat); });
  EXPECT_CONTAINS(message, At(flat, 12));
  EXPECT_CONTAINS(message, "degenerate");
}

TEST_F(ReadMeditTest, RepeatedVerticesSectionIsRejected) {
  // A second Vertices section after the tets would leave them indexing vertices
  // that no longer exist (here 3 and 4 of 2), past the range check made on reading.
  const std::string path = Write("twice.mesh", std::string(kFourVertices) +
                                                   "Tetrahedra 1\n"  // 10
                                                   "1 2 3 4 0\n"     // 11
                                                   "Vertices 2\n"    // 12
                                                   "0 0 0 0\n"       // 13
                                                   "1 1 1 0\n"       // 14
                                                   "End\n");
  EXPECT_CONTAINS(InputErrorOf([&] { ReadMedit(path); }), At(path, 12));
}

TEST_F(ReadMeditTest, CountBeyondTheFileIsAnInputError) {
  // A count no file of this size can hold must be an InputError at its line, not a
  // failed allocation (std::bad_alloc escapes the InputError error model).
  const std::string path = Write("huge.mesh",
                                 "MeshVersionFormatted 2\n"  // 1
                                 "Dimension 3\n"             // 2
                                 "Vertices 100000000000\n"   // 3
                                 "0 0 0 0\n");               // 4
  std::string message;
  try {
    ReadMedit(path);
  } catch (const InputError &error) {
    message = error.what();
  } catch (const std::exception &error) {
    ADD_FAILURE() << "not an InputError: " << error.what();
  }
  EXPECT_CONTAINS(message, path + ":");
}

TEST_F(ReadMeditTest, TruncatedFileNamesLastLine) {
  // The file stops in the middle of the vertex rows (no newline at the end).
  const std::string path = Write("truncated.mesh",
                                 "MeshVersionFormatted 2\n"  // 1
                                 "Dimension 3\n"             // 2
                                 "Vertices 4\n"              // 3
                                 "0 0 0 0\n"                 // 4
                                 "1 0 0 0\n"                 // 5
                                 "0 1");                     // 6
  const std::string message = InputErrorOf([&] { ReadMedit(path); });
  EXPECT_CONTAINS(message, At(path, 6));
  EXPECT_CONTAINS(message, "end of file");
}

TEST_F(ReadMeditTest, TruncatedTetrahedraSection) {
  const std::string path = Write("short.mesh", std::string(kFourVertices) +
                                                   "Tetrahedra 2\n"  // 10
                                                   "1 2 3 4 0");     // 11
  const std::string message = InputErrorOf([&] { ReadMedit(path); });
  EXPECT_CONTAINS(message, At(path, 11));
  EXPECT_CONTAINS(message, "end of file");
}

TEST_F(ReadMeditTest, UnknownKeywordNamesLine) {
  const std::string path = Write("keyword.mesh", std::string(kFourVertices) +
                                                     "\n"              // 10
                                                     "Tetrahedra 1\n"  // 11
                                                     "1 2 3 4 0\n"     // 12
                                                     "Bogus 3\n"       // 13
                                                     "End\n");
  const std::string message = InputErrorOf([&] { ReadMedit(path); });
  EXPECT_CONTAINS(message, At(path, 13));
  EXPECT_CONTAINS(message, "Bogus");
}

TEST_F(ReadMeditTest, NonNumericCoordinateNamesLine) {
  const std::string path = Write("text.mesh",
                                 "MeshVersionFormatted 2\n"  // 1
                                 "Dimension 3\n"             // 2
                                 "Vertices 2\n"              // 3
                                 "0 0 0 0\n"                 // 4
                                 "1 x 0 0\n"                 // 5
                                 "End\n");
  EXPECT_CONTAINS(InputErrorOf([&] { ReadMedit(path); }), At(path, 5));
}

TEST_F(ReadMeditTest, NoTetrahedraIsAnError) {
  const std::string path = Write("empty.mesh", std::string(kFourVertices) + "End\n");
  const std::string message = InputErrorOf([&] { ReadMedit(path); });
  EXPECT_CONTAINS(message, path);
  EXPECT_CONTAINS(message, "no tetrahedra");
}

TEST_F(ReadMeditTest, MissingFileNamesPath) {
  const std::string path = (folder_ / "does_not_exist.mesh").string();
  const std::string message = InputErrorOf([&] { ReadMedit(path); });
  EXPECT_CONTAINS(message, path);
  EXPECT_CONTAINS(message, "cannot open");
}

TEST_F(ReadMeditTest, UnknownExtensionIsAnError) {
  const std::string path = Write("cube.obj", kCubeMesh);
  EXPECT_CONTAINS(InputErrorOf([&] { ReadTetMesh(path); }), path);
}

// ---------------------------------------------------------------- ReadScene

// Rotation of x by the unit quaternion (w, v), written out independently of Eigen's
// quaternion class: x + 2 w (v x x) + 2 v x (v x x).
Eigen::Vector3d Rotate(Eigen::Vector4d q_wxyz, const Eigen::Vector3d &x) {
  q_wxyz /= q_wxyz.norm();
  const double w = q_wxyz[0];
  const Eigen::Vector3d v = q_wxyz.tail<3>();
  return x + 2 * w * v.cross(x) + 2 * v.cross(v.cross(x));
}

class ReadSceneTest : public TempFolder {
 protected:
  void SetUp() override {
    TempFolder::SetUp();
    Write("meshes/split_tet.mesh", kSplitTetMesh);
    Write("meshes/cube.mesh", kCubeMesh);
  }
};

TEST_F(ReadSceneTest, PlacesBodiesAndReadsVelocities) {
  // Two bodies; mesh paths relative to scenes/, not to the working directory.
  const std::string path = Write("scenes/two.txt",
                                 "# two bodies\n"
                                 "2\n"
                                 "../meshes/split_tet.mesh 1000 1e5 0.3 0  1 2 3  2 0 0 2\n"
                                 "\n"
                                 "../meshes/cube.mesh\t500 2e6 -0.2 0  -1 0.5 4  1 2 3 4\n"
                                 "2  # velocities\n"
                                 "0 4  0.1 0.2 0.3\n"
                                 "1 7  -1 -2 -3\n");
  const Scene scene = ReadScene(path);
  ASSERT_EQ(scene.bodies.size(), 2u);
  const Body &split = scene.bodies[0], &cube = scene.bodies[1];
  EXPECT_EQ(split.mesh_path, (folder_ / "meshes" / "split_tet.mesh").string());
  EXPECT_EQ(cube.mesh_path, (folder_ / "meshes" / "cube.mesh").string());
  EXPECT_EQ(split.material.density, 1000.0);
  EXPECT_EQ(split.material.young, 1e5);
  EXPECT_EQ(split.material.poisson, 0.3);
  EXPECT_EQ(cube.material.poisson, -0.2);
  EXPECT_FALSE(split.fixed);
  EXPECT_EQ(split.first_vertex, 0);
  EXPECT_EQ(cube.first_vertex, 5);
  EXPECT_EQ(scene.num_vertices(), 13);
  EXPECT_EQ(scene.num_tets(), 8);

  // Split tet: centroid (-0.5, 0.25, 0.25) to the origin, q = (2, 0, 0, 2)
  // normalised is 90 degrees about z, (x, y, z) -> (-y, x, z), then p = (1, 2, 3).
  const Eigen::Vector3d split_centroid(-0.5, 0.25, 0.25);
  for (int v = 0; v < 5; ++v) {
    const Eigen::Vector3d r = Eigen::Vector3d(kSplitTetVertices[v]) - split_centroid;
    const Eigen::Vector3d expected =
        Eigen::Vector3d(-r.y(), r.x(), r.z()) + Eigen::Vector3d(1, 2, 3);
    EXPECT_LT((split.mesh.vertices.row(v).transpose() - expected).norm(), 1e-14) << "vertex " << v;
  }
  // Cube: centroid (0.5, 0.5, 0.5), q = (1, 2, 3, 4) normalised, p = (-1, 0.5, 4).
  for (int v = 0; v < 8; ++v) {
    const Eigen::Vector3d r =
        Eigen::Vector3d(v % 2, (v / 2) % 2, v / 4) - Eigen::Vector3d::Constant(0.5);
    const Eigen::Vector3d expected = Rotate({1, 2, 3, 4}, r) + Eigen::Vector3d(-1, 0.5, 4);
    EXPECT_LT((cube.mesh.vertices.row(v).transpose() - expected).norm(), 1e-14) << "vertex " << v;
  }
  // A rotation keeps volumes: the cube's is still 1, its centroid now at p.
  EXPECT_LT((VolumeWeightedCentroid(cube.mesh) - Eigen::Vector3d(-1, 0.5, 4)).norm(), 1e-14);

  // Velocities land at natural index first_vertex + vertex; all others stay zero.
  ASSERT_EQ(scene.num_vertices(), 13);
  EXPECT_EQ(scene.initial_velocities.size(), 2u);
  EXPECT_EQ(scene.num_velocity_entries, 2);
  EXPECT_EQ(scene.ignored_fixed_velocities, 0);
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> expected_velocities =
      Eigen::MatrixXd::Zero(13, 3);
  expected_velocities.row(4) << 0.1, 0.2, 0.3;
  expected_velocities.row(5 + 7) << -1, -2, -3;
  EXPECT_EQ(DenseInitialVelocities(scene), expected_velocities);
}

TEST_F(ReadSceneTest, MissingVelocitySectionMeansAtRest) {
  const std::string path = Write("rest.txt", "1\nmeshes/cube.mesh 1000 1e5 0.3 1 0 0 0 1 0 0 0\n");
  const Scene scene = ReadScene(path);
  ASSERT_EQ(scene.bodies.size(), 1u);
  EXPECT_TRUE(scene.bodies[0].fixed);
  EXPECT_EQ(scene.num_velocity_entries, 0);
  ASSERT_EQ(scene.num_vertices(), 8);
  EXPECT_TRUE(scene.initial_velocities.empty());
  // Identity rotation, zero translation: the cube is centred on the origin.
  EXPECT_LT((scene.bodies[0].mesh.vertices.row(7) - Eigen::RowVector3d(0.5, 0.5, 0.5)).norm(),
            1e-15);
}

// Entries are kept by vertex, one each: a vertex named twice takes its last line.
TEST_F(ReadSceneTest, LaterVelocityLineForAVertexWins) {
  const std::string path = Write("twice.txt",
                                 "1\n"
                                 "meshes/cube.mesh 1000 1e5 0.3 0 0 0 0 1 0 0 0\n"
                                 "4\n"
                                 "0 6 1 1 1\n"
                                 "0 2 0 0 -2\n"
                                 "0 6 3 0 0\n"
                                 "0 1 0 5 0\n");
  const Scene scene = ReadScene(path);
  EXPECT_EQ(scene.num_velocity_entries, 4);
  ASSERT_EQ(scene.initial_velocities.size(), 3u);
  EXPECT_EQ(scene.initial_velocities[0].vertex, 1);
  EXPECT_EQ(scene.initial_velocities[1].vertex, 2);
  EXPECT_EQ(scene.initial_velocities[2].vertex, 6);
  EXPECT_EQ(DenseInitialVelocities(scene).row(6), Eigen::RowVector3d(3, 0, 0));
}

TEST_F(ReadSceneTest, VelocitiesOfFixedBodiesAreCountedAndDropped) {
  const std::string path = Write("fixed.txt",
                                 "2\n"
                                 "meshes/cube.mesh 1000 1e5 0.3 1 0 0 0 1 0 0 0\n"
                                 "meshes/split_tet.mesh 1000 1e5 0.3 0 0 0 5 1 0 0 0\n"
                                 "2\n"
                                 "0 3 1 1 1\n"
                                 "1 0 0 0 -2\n");
  const Scene scene = ReadScene(path);
  EXPECT_EQ(scene.num_velocity_entries, 2);
  EXPECT_EQ(scene.ignored_fixed_velocities, 1);
  EXPECT_TRUE(DenseInitialVelocities(scene).topRows(8).isZero(0.0));
  EXPECT_EQ(DenseInitialVelocities(scene).row(8), Eigen::RowVector3d(0, 0, -2));
  EXPECT_EQ(scene.initial_velocities.size(), 1u);
}

TEST_F(ReadSceneTest, ErrorsNameFileAndLine) {
  // Each case replaces one line of a valid scene; the error must name that line.
  const std::string good_mesh_line = "meshes/cube.mesh 1000 1e5 0.3 0 0 0 0 1 0 0 0";
  struct Case {
    const char *name;
    int line;             // 1-based line at fault
    std::string replace;  // new text of that line
    const char *message;  // part of the expected message
  };
  // Valid layout: 1 comment, 2 num_meshes, 3 mesh line, 4 blank, 5 num_velocities,
  // 6 velocity line.
  const std::vector<Case> cases = {
      {"eleven_fields", 3, "meshes/cube.mesh 1000 1e5 0.3 0 0 0 0 1 0 0", "12 fields"},
      {"thirteen_fields", 3, good_mesh_line + " 7", "12 fields"},
      {"incompressible", 3, "meshes/cube.mesh 1000 1e5 0.5 0 0 0 0 1 0 0 0", "Poisson"},
      {"poisson_minus_one", 3, "meshes/cube.mesh 1000 1e5 -1 0 0 0 0 1 0 0 0", "Poisson"},
      {"young_zero", 3, "meshes/cube.mesh 1000 0 0.3 0 0 0 0 1 0 0 0", "Young"},
      {"young_negative", 3, "meshes/cube.mesh 1000 -1e5 0.3 0 0 0 0 1 0 0 0", "Young"},
      {"density_zero", 3, "meshes/cube.mesh 0 1e5 0.3 0 0 0 0 1 0 0 0", "density"},
      {"density_negative", 3, "meshes/cube.mesh -5 1e5 0.3 0 0 0 0 1 0 0 0", "density"},
      {"fixed_two", 3, "meshes/cube.mesh 1000 1e5 0.3 2 0 0 0 1 0 0 0", "is_fixed"},
      {"nan_position", 3, "meshes/cube.mesh 1000 1e5 0.3 0 0 nan 0 1 0 0 0", "position"},
      {"inf_density", 3, "meshes/cube.mesh inf 1e5 0.3 0 0 0 0 1 0 0 0", "density"},
      {"zero_quaternion", 3, "meshes/cube.mesh 1000 1e5 0.3 0 0 0 0 0 0 0 0", "quaternion"},
      {"vertex_out_of_range", 6, "0 8 1 2 3", "vertex index 8"},
      {"vertex_negative", 6, "0 -1 1 2 3", "vertex index -1"},
      {"mesh_out_of_range", 6, "1 0 1 2 3", "mesh index 1"},
      {"nan_velocity", 6, "0 1 1 NaN 3", "velocity"},
      {"velocity_fields", 6, "0 1 1 2", "5 fields"},
      {"num_meshes_text", 2, "one", "num_meshes"},
  };
  for (const Case &c : cases) {
    std::vector<std::string> lines = {"# scene", "1", good_mesh_line, "", "1", "0 7 1 2 3"};
    lines[c.line - 1] = c.replace;
    std::string text;
    for (const std::string &line : lines) text += line + "\n";
    const std::string path = Write(std::string(c.name) + ".txt", text);
    const std::string message = InputErrorOf([&] { ReadScene(path); });
    EXPECT_CONTAINS(message, At(path, c.line)) << c.name;
    EXPECT_CONTAINS(message, c.message) << c.name;
  }
}

TEST_F(ReadSceneTest, ExtraContentNamesLine) {
  const std::string path = Write("extra.txt",
                                 "1\n"                                              // 1
                                 "meshes/cube.mesh 1000 1e5 0.3 0 0 0 0 1 0 0 0\n"  // 2
                                 "1\n"                                              // 3
                                 "0 0 1 2 3\n"                                      // 4
                                 "\n"                                               // 5
                                 "# trailing comments are fine\n"                   // 6
                                 "0 1 1 2 3\n");                                    // 7
  const std::string message = InputErrorOf([&] { ReadScene(path); });
  EXPECT_CONTAINS(message, At(path, 7));
  EXPECT_CONTAINS(message, "unexpected content");
}

TEST_F(ReadSceneTest, MissingMeshLineNamesLine) {
  const std::string path = Write("short.txt", "2\nmeshes/cube.mesh 1000 1e5 0.3 0 0 0 0 1 0 0 0\n");
  EXPECT_CONTAINS(InputErrorOf([&] { ReadScene(path); }), path + ":");
}

TEST_F(ReadSceneTest, ErrorsInsideAMeshNameTheMeshFile) {
  const std::string mesh =
      Write("meshes/bad.mesh", std::string(kFourVertices) + "Tetrahedra 1\n1 2 3 9 0\nEnd\n");
  const std::string path = Write("bad.txt", "1\nmeshes/bad.mesh 1000 1e5 0.3 0 0 0 0 1 0 0 0\n");
  EXPECT_CONTAINS(InputErrorOf([&] { ReadScene(path); }), At(mesh, 11));
  const std::string missing =
      Write("missing.txt", "1\nmeshes/none.mesh 1000 1e5 0.3 0 0 0 0 1 0 0 0\n");
  EXPECT_CONTAINS(InputErrorOf([&] { ReadScene(missing); }),
                  (folder_ / "meshes" / "none.mesh").string());
}

TEST_F(ReadSceneTest, MissingSceneFileNamesPath) {
  const std::string path = (folder_ / "none.txt").string();
  EXPECT_CONTAINS(InputErrorOf([&] { ReadScene(path); }), path);
}

// ------------------------------------------------------------ mesh queries

// The first tet that contains all three vertices of `face`, or -1.
int OwningTet(const TetMesh &mesh, const std::array<int32_t, 3> &face) {
  for (int32_t t = 0; t < mesh.num_tets(); ++t) {
    const std::set<int32_t> tet(mesh.tets.row(t).data(), mesh.tets.row(t).data() + 4);
    if (tet.count(face[0]) && tet.count(face[1]) && tet.count(face[2])) return t;
  }
  return -1;
}

// Checks that every boundary face points away from the centroid of its tet.
void ExpectOutward(const TetMesh &mesh,
                   const Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor> &faces) {
  for (int f = 0; f < faces.rows(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(faces(f, 0)), b = mesh.vertices.row(faces(f, 1)),
                          c = mesh.vertices.row(faces(f, 2));
    const int t = OwningTet(mesh, {faces(f, 0), faces(f, 1), faces(f, 2)});
    ASSERT_GE(t, 0) << "face " << f;
    Eigen::Vector3d tet_centroid = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) tet_centroid += mesh.vertices.row(mesh.tets(t, k)).transpose() / 4;
    const Eigen::Vector3d normal = (b - a).cross(c - a);
    EXPECT_GT(normal.dot((a + b + c) / 3 - tet_centroid), 0.0) << "face " << f;
  }
}

TEST(BoundaryTriangles, SingleTetOfEitherOrientation) {
  TetMesh mesh;
  mesh.vertices.resize(4, 3);
  mesh.vertices << 0.1, 0, 0, 1, 0.2, 0, 0, 1, 0.3, 0.2, 0.1, 1;
  for (const bool swapped : {false, true}) {
    mesh.tets.resize(1, 4);
    mesh.tets << 0, 1, 2, 3;
    if (swapped) mesh.tets.row(0) << 0, 2, 1, 3;
    const auto faces = BoundaryTriangles(mesh);
    ASSERT_EQ(faces.rows(), 4) << "swapped " << swapped;
    ExpectOutward(mesh, faces);
    std::set<std::set<int32_t>> distinct;
    for (int f = 0; f < 4; ++f) distinct.insert({faces(f, 0), faces(f, 1), faces(f, 2)});
    EXPECT_EQ(distinct.size(), 4u);
  }
}

TEST(BoundaryTriangles, TwoTetsSharingAFace) {
  // Tets (0, 1, 2, 3) and (0, 2, 1, 4) on either side of the face {0, 1, 2}.
  TetMesh mesh;
  mesh.vertices.resize(5, 3);
  mesh.vertices << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0.2, 0.3, 1, 0.3, 0.2, -1;
  mesh.tets.resize(2, 4);
  mesh.tets << 0, 1, 2, 3, 0, 2, 1, 4;
  const auto faces = BoundaryTriangles(mesh);
  ASSERT_EQ(faces.rows(), 6);
  ExpectOutward(mesh, faces);
  for (int f = 0; f < 6; ++f) {
    const std::set<int32_t> face = {faces(f, 0), faces(f, 1), faces(f, 2)};
    EXPECT_NE(face, (std::set<int32_t>{0, 1, 2})) << "the shared face is interior";
  }
}

TEST(BoundaryTriangles, UnitCubeEnclosesItsVolume) {
  // 12 triangles on the cube's surface; by the divergence theorem,
  // sum a . ((b - a) x (c - a)) / 6 over outward faces is the volume, 1.
  const TetMesh mesh = UnitCube();
  const auto faces = BoundaryTriangles(mesh);
  ASSERT_EQ(faces.rows(), 12);
  ExpectOutward(mesh, faces);
  double volume = 0;
  for (int f = 0; f < faces.rows(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(faces(f, 0)), b = mesh.vertices.row(faces(f, 1)),
                          c = mesh.vertices.row(faces(f, 2));
    volume += a.dot((b - a).cross(c - a)) / 6;
    const Eigen::Vector3d centroid = (a + b + c) / 3;
    EXPECT_TRUE((centroid.array() < 1e-15).any() || (centroid.array() > 1 - 1e-15).any())
        << "face " << f << " is not on the cube's surface";
  }
  EXPECT_NEAR(volume, 1.0, 1e-14);
}

TEST(VolumeWeightedCentroid, UnitCubeAndSplitTet) {
  EXPECT_LT((VolumeWeightedCentroid(UnitCube()) - Eigen::Vector3d(0.5, 0.5, 0.5)).norm(), 1e-15);
  TetMesh split;
  split.vertices.resize(5, 3);
  for (int v = 0; v < 5; ++v) split.vertices.row(v) = Eigen::RowVector3d(kSplitTetVertices[v]);
  split.tets.resize(2, 4);
  split.tets << 0, 1, 2, 3, 0, 2, 3, 4;
  EXPECT_LT((VolumeWeightedCentroid(split) - Eigen::Vector3d(-0.5, 0.25, 0.25)).norm(), 1e-15);
}

}  // namespace
}  // namespace softbody
