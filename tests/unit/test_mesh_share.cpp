// The ranks' shares of the meshes (mesh_share.hpp) and the boundary found from them
// (share_boundary.hpp), run on several ranks: every rank executes the same tests.
// Runs on ranks: 1 3 4
//
// Scene: three boxes of Kuhn tets, the second fixed and with every tet inverted
// (negative signed volume: the orientation must come from the tet, not the file order),
// the third moved away from the origin.
// - The slabs and tet shares of all ranks, put together, are the scene's vertices
//   (rest positions, initial velocities) and tets, each exactly once, in natural order.
// - The boundary triangles of all ranks, in rank order, are BoundaryTriangles of each
//   body in turn; independently of it, a box of nx x ny x nz cells has
//   4 (nx ny + ny nz + nz nx) of them, each facing away from the box's centre.
#include <gtest/gtest.h>
#include <petscsys.h>

#include <array>
#include <vector>

#include "box_mesh.hpp"
#include "fem/mesh.hpp"
#include "fem/mesh_share.hpp"
#include "fem/share_boundary.hpp"
#include "petsc_environment.hpp"

using namespace softbody;

namespace {

struct Box {
  int nx, ny, nz;
  bool fixed;
  Eigen::RowVector3d offset;
};
const Box kBoxes[] = {
    {6, 3, 2, false, {0, 0, 0}}, {2, 2, 2, true, {0, 1, 0}}, {3, 1, 4, false, {5, -2, 1}}};
constexpr double kEdge = 0.1;

Scene ThreeBoxes() {
  Scene scene;
  int32_t first = 0;
  for (const Box &box : kBoxes) {
    Body body;
    body.material = {1000.0, 1e6, 0.4};
    body.fixed = box.fixed;
    body.mesh = BoxMesh(box.nx, box.ny, box.nz, kEdge);
    body.mesh.vertices.rowwise() += box.offset;
    if (box.fixed) body.mesh.tets.col(1).swap(body.mesh.tets.col(2));  // inverted tets
    body.first_vertex = first;
    first += body.mesh.num_vertices();
    scene.bodies.push_back(body);
  }
  for (int32_t v = 0; v < first; ++v)
    scene.initial_velocities.push_back({v, {double(v), -double(v), 0.5 * v}});
  return scene;
}

TEST(ShareScene, SlabsAndSharesPutTogetherAreTheScene) {
  const Scene scene = ThreeBoxes();
  const MeshShare share = ShareScene(scene, Rank(), Size());
  std::vector<double> mine;
  for (PetscInt i = 0; i < share.slab_size(); ++i)
    for (int c = 0; c < 3; ++c) mine.insert(mine.end(), {share.rest(i, c), share.velocities(i, c)});
  const std::vector<double> all = AllGather(mine);
  ASSERT_EQ(all.size(), 6u * scene.num_vertices());
  for (const Body &body : scene.bodies)
    for (int32_t v = 0; v < body.mesh.num_vertices(); ++v)
      for (int c = 0; c < 3; ++c) {
        const size_t at = 6 * (body.first_vertex + v) + 2 * c;
        EXPECT_EQ(all[at], body.mesh.vertices(v, c));
        EXPECT_EQ(all[at + 1], scene.initial_velocities[body.first_vertex + v].velocity[c]);
      }
  std::vector<std::array<PetscInt, 5>> tets;  // natural vertices and body
  for (PetscInt t = 0; t < share.num_tets(); ++t)
    tets.push_back({share.tets[t][0], share.tets[t][1], share.tets[t][2], share.tets[t][3],
                    share.tet_body[t]});
  const auto all_tets = AllGather(tets);
  ASSERT_EQ(static_cast<int64_t>(all_tets.size()), scene.num_tets());
  size_t next = 0;
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    EXPECT_EQ(share.body_fixed[b] != 0, body.fixed);
    for (int32_t t = 0; t < body.mesh.num_tets(); ++t, ++next) {
      for (int a = 0; a < 4; ++a)
        EXPECT_EQ(all_tets[next][a], body.first_vertex + body.mesh.tets(t, a));
      EXPECT_EQ(all_tets[next][4], static_cast<PetscInt>(b));
    }
  }
}

TEST(ShareBoundaryTriangles, TheBodiesBoundariesInOrder) {
  const Scene scene = ThreeBoxes();
  const MeshShare share = ShareScene(scene, Rank(), Size());
  std::vector<std::array<PetscInt, 3>> mine;
  ASSERT_EQ(ShareBoundaryTriangles(PETSC_COMM_WORLD, share, &mine), 0);
  const auto all = AllGather(mine);
  size_t next = 0;
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    const Box &box = kBoxes[b];
    const auto serial = BoundaryTriangles(body.mesh);
    ASSERT_EQ(serial.rows(), 4 * (box.nx * box.ny + box.ny * box.nz + box.nz * box.nx));
    const Eigen::RowVector3d centre = body.mesh.vertices.colwise().mean();
    for (Eigen::Index f = 0; f < serial.rows(); ++f, ++next) {
      ASSERT_LT(next, all.size());
      for (int k = 0; k < 3; ++k) EXPECT_EQ(all[next][k], body.first_vertex + serial(f, k));
      Eigen::RowVector3d p[3];
      for (int k = 0; k < 3; ++k) p[k] = body.mesh.vertices.row(all[next][k] - body.first_vertex);
      const Eigen::RowVector3d normal = (p[1] - p[0]).cross(p[2] - p[0]);
      EXPECT_GT(normal.dot((p[0] + p[1] + p[2]) / 3 - centre), 0) << "body " << b << " face " << f;
    }
  }
  EXPECT_EQ(next, all.size());
}

}  // namespace
