// The distributed free-vertex graph and its partition (vertex_graph.hpp, partition.hpp),
// run on several ranks: every rank executes the same tests, collectively.
// Runs on ranks: 1 3 4
//
// Scene: two free boxes (a 24 x 6 x 6-cell beam and a 5 x 4 x 3-cell block) with a fixed
// box between them in natural order, so free and natural indices differ.
// - The rows built from each rank's share of the tets, put together, are the adjacency
//   computed here directly from the tets (sets of neighbours, serial).
// - METIS and PT-Scotch: every vertex gets a part in [0, P), no part is more than 10 %
//   above the mean (PT-Scotch's default imbalance bound is 1 %, METIS's 3 %), and the
//   partition cuts fewer edges than the trivial split of the natural order into P even
//   blocks (which cuts the beam across its long side: an independent, easily computed
//   baseline any partitioner must beat).
// - BuildDofLayout numbers the free vertices (those of free tets: a stray vertex is not)
//   as a serial count here does, part by part, natural order inside a part;
//   natural_of_owned and the slabs' lookups agree with the global arrays.
// - MigrateTets brings every free tet with an owned vertex, and only those, in tet
//   order, with its PETSc vertices and rest positions (checked against the scene).
#include <gtest/gtest.h>
#include <petscsys.h>

#include <algorithm>
#include <set>
#include <vector>

#include "box_mesh.hpp"
#include "fem/migration.hpp"
#include "fem/partition.hpp"
#include "fem/vertex_graph.hpp"
#include "io/scene.hpp"
#include "petsc_environment.hpp"

using namespace softbody;

namespace {

constexpr double kLargestPartOverMean = 1.10;

Scene ThreeBoxes() {
  Scene scene;
  const struct {
    int nx, ny, nz;
    bool fixed;
  } boxes[] = {{24, 6, 6, false}, {3, 3, 3, true}, {5, 4, 3, false}};
  int32_t first = 0;
  for (const auto &box : boxes) {
    Body body;
    body.material = {1000.0, 1e6, 0.4};
    body.fixed = box.fixed;
    body.mesh = BoxMesh(box.nx, box.ny, box.nz, 0.1);
    body.first_vertex = first;
    first += body.mesh.num_vertices();
    scene.bodies.push_back(body);
  }
  scene.initial_velocities.setZero(first, 3);
  return scene;
}

// Natural vertex -> free index (the vertices of free bodies, in natural order), or -1.
std::vector<PetscInt> FreeOfNatural(const Scene &scene, PetscInt *num_free) {
  std::vector<PetscInt> free_of_natural(scene.num_vertices(), -1);
  *num_free = 0;
  for (const Body &body : scene.bodies)
    for (int32_t v = 0; v < body.mesh.num_vertices(); ++v)
      if (!body.fixed) free_of_natural[body.first_vertex + v] = (*num_free)++;
  return free_of_natural;
}

std::vector<std::set<PetscInt>> SerialAdjacency(const Scene &scene,
                                                const std::vector<PetscInt> &free_of_natural,
                                                PetscInt num_free) {
  std::vector<std::set<PetscInt>> adjacency(num_free);
  for (const Body &body : scene.bodies) {
    if (body.fixed) continue;
    for (int32_t t = 0; t < body.mesh.num_tets(); ++t)
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
          if (a != b)
            adjacency[free_of_natural[body.first_vertex + body.mesh.tets(t, a)]].insert(
                free_of_natural[body.first_vertex + body.mesh.tets(t, b)]);
  }
  return adjacency;
}

long CutEdges(const std::vector<std::set<PetscInt>> &adjacency, const std::vector<PetscInt> &part) {
  long cut = 0;
  for (size_t v = 0; v < adjacency.size(); ++v)
    for (PetscInt w : adjacency[v]) cut += part[v] != part[w];
  return cut / 2;
}

// The free tets of this rank's even share of the tets, as free indices.
std::vector<std::array<PetscInt, 4>> FreeTetShare(const Scene &scene,
                                                  const std::vector<PetscInt> &free_of_natural) {
  const MeshShare share = ShareScene(scene, Rank(), Size());
  std::vector<std::array<PetscInt, 4>> tets;
  for (size_t t = 0; t < share.tets.size(); ++t)
    if (share.TetIsFree(t)) {
      const auto &natural = share.tets[t];
      tets.push_back({free_of_natural[natural[0]], free_of_natural[natural[1]],
                      free_of_natural[natural[2]], free_of_natural[natural[3]]});
    }
  return tets;
}

// The scene, its free numbering and this rank's graph rows.
struct ThreeBoxGraph {
  Scene scene = ThreeBoxes();
  PetscInt n = 0;
  std::vector<PetscInt> free_of_natural = FreeOfNatural(scene, &n);
  VertexGraphRows graph;
  PetscErrorCode status =
      BuildVertexGraphRows(PETSC_COMM_WORLD, FreeTetShare(scene, free_of_natural), n, &graph);
};

TEST(VertexGraph, RowsPutTogetherAreTheAdjacencyOfTheTets) {
  const ThreeBoxGraph built;
  ASSERT_EQ(built.status, 0);
  const Scene &scene = built.scene;
  const PetscInt n = built.n;
  const std::vector<PetscInt> &free_of_natural = built.free_of_natural;
  const VertexGraphRows &graph = built.graph;
  EXPECT_EQ(graph.num_vertices, n);
  EXPECT_EQ(graph.row_begin, EvenShareBegin(n, Size(), Rank()));
  EXPECT_EQ(graph.num_rows(), EvenShareBegin(n, Size(), Rank() + 1) - graph.row_begin);
  std::vector<PetscInt> lengths(graph.num_rows());
  for (PetscInt i = 0; i < graph.num_rows(); ++i)
    lengths[i] = graph.offsets[i + 1] - graph.offsets[i];
  const std::vector<PetscInt> all_lengths = AllGather(lengths);
  const std::vector<PetscInt> all_neighbours = AllGather(graph.neighbours);
  const auto expected = SerialAdjacency(scene, free_of_natural, n);
  ASSERT_EQ(static_cast<PetscInt>(all_lengths.size()), n);
  size_t at = 0;
  for (PetscInt v = 0; v < n; ++v) {
    const std::vector<PetscInt> row(all_neighbours.begin() + at,
                                    all_neighbours.begin() + at + all_lengths[v]);
    at += all_lengths[v];
    EXPECT_EQ(row, std::vector<PetscInt>(expected[v].begin(), expected[v].end())) << "row " << v;
  }
}

class Partitioners : public ::testing::TestWithParam<Partitioner> {};

TEST_P(Partitioners, BalancedAndBetterThanNaturalBlocks) {
  ThreeBoxGraph built;
  ASSERT_EQ(built.status, 0);
  const PetscInt n = built.n;
  std::vector<PetscInt> part;
  Partitioner used;
  ASSERT_EQ(PartitionVertexGraph(PETSC_COMM_WORLD, &built.graph, GetParam(), &part, &used), 0);
  const PetscMPIInt size = Size();
  EXPECT_EQ(used, size == 1 ? Partitioner::kAuto : GetParam());
  const std::vector<PetscInt> all = AllGather(part);
  ASSERT_EQ(static_cast<PetscInt>(all.size()), n);
  std::vector<long> count(size, 0);
  for (PetscInt p : all) {
    ASSERT_TRUE(p >= 0 && p < size) << "part " << p;
    ++count[p];
  }
  const double mean = static_cast<double>(n) / size;
  EXPECT_LE(*std::max_element(count.begin(), count.end()), kLargestPartOverMean * mean);
  if (size == 1) return;
  std::vector<PetscInt> blocks(n);
  for (PetscMPIInt q = 0; q < size; ++q)
    std::fill(blocks.begin() + EvenShareBegin(n, size, q),
              blocks.begin() + EvenShareBegin(n, size, q + 1), q);
  const auto adjacency = SerialAdjacency(built.scene, built.free_of_natural, n);
  EXPECT_LT(CutEdges(adjacency, all), CutEdges(adjacency, blocks));
}

INSTANTIATE_TEST_SUITE_P(MetisAndPtScotch, Partitioners,
                         ::testing::Values(Partitioner::kMetis, Partitioner::kPtScotch));

// ThreeBoxes with a vertex in no tet (a stray vertex: not free) appended to the
// first box, so that the later bodies' natural numbers shift by one.
Scene ThreeBoxesWithStrayVertex() {
  Scene scene = ThreeBoxes();
  TetMesh &mesh = scene.bodies[0].mesh;
  mesh.vertices.conservativeResize(mesh.num_vertices() + 1, 3);
  mesh.vertices.row(mesh.num_vertices() - 1) << 9, 9, 9;
  for (size_t b = 1; b < scene.bodies.size(); ++b) ++scene.bodies[b].first_vertex;
  scene.initial_velocities.setZero(scene.initial_velocities.rows() + 1, 3);
  return scene;
}

// Natural vertex -> free index, serially: the vertices of free tets, natural order.
std::vector<PetscInt> FreeOfNaturalByTets(const Scene &scene) {
  std::vector<PetscInt> free_of_natural(scene.num_vertices(), -1);
  for (const Body &body : scene.bodies)
    if (!body.fixed)
      for (int32_t t = 0; t < body.mesh.num_tets(); ++t)
        for (int a = 0; a < 4; ++a) free_of_natural[body.first_vertex + body.mesh.tets(t, a)] = 0;
  PetscInt next = 0;
  for (PetscInt &f : free_of_natural)
    if (f == 0) f = next++;
  return free_of_natural;
}

struct BuiltLayout {
  MeshShare share;
  DofLayout layout;
  PetscErrorCode status;
  BuiltLayout(const Scene &scene, Partitioner partitioner)
      : share(ShareScene(scene, Rank(), Size())),
        status(BuildDofLayout(PETSC_COMM_WORLD, PartitionOptions{partitioner}, &share, &layout)) {
    if (status == 0) status = ReplicateNumbering(PETSC_COMM_WORLD, share, &layout);
  }
};

TEST(DofLayout, NumberedPartByPartInNaturalOrder) {
  const Scene scene = ThreeBoxesWithStrayVertex();
  const std::vector<PetscInt> expected_free = FreeOfNaturalByTets(scene);
  for (Partitioner partitioner : {Partitioner::kAuto, Partitioner::kPtScotch}) {
    BuiltLayout built(scene, partitioner);
    ASSERT_EQ(built.status, 0);
    const DofLayout &layout = built.layout;
    ASSERT_EQ(layout.free_of_natural, expected_free);
    const PetscInt n = layout.num_free();
    std::vector<PetscInt> sorted = layout.petsc_of_free;
    std::sort(sorted.begin(), sorted.end());
    for (PetscInt i = 0; i < n; ++i) ASSERT_EQ(sorted[i], i) << "not a permutation";
    ASSERT_EQ(layout.vertex_start.back(), n);
    // Inside a rank's block, PETSc order follows the natural order.
    for (PetscInt f = 1; f < n; ++f) {
      const PetscInt a = layout.petsc_of_free[f - 1], b = layout.petsc_of_free[f];
      const auto owner = [&layout](PetscInt p) {
        return std::upper_bound(layout.vertex_start.begin(), layout.vertex_start.end(), p) -
               layout.vertex_start.begin();
      };
      if (owner(a) == owner(b)) EXPECT_LT(a, b) << "free vertices " << f - 1 << ", " << f;
    }
    ASSERT_EQ(static_cast<PetscInt>(layout.natural_of_owned.size()), layout.local_count());
    for (PetscInt i = 0; i < layout.local_count(); ++i)
      EXPECT_EQ(layout.PetscVertexOfNatural(layout.natural_of_owned[i]), layout.local_begin() + i);
    // The slab's own lookups agree with the replicated arrays.
    for (PetscInt i = 0; i < built.share.slab_size(); ++i) {
      const PetscInt natural = built.share.first_vertex + i;
      EXPECT_EQ(built.share.free_index[i], expected_free[natural]);
      EXPECT_EQ(built.share.petsc_vertex[i], layout.PetscVertexOfNatural(natural));
    }
  }
}

// Every free tet with an owned vertex arrives once, in tet order, with its
// PETSc vertices and the scene's rest positions; no other tet arrives.
TEST(MigrateTets, TheTetsOfTheOwnedVertices) {
  const Scene scene = ThreeBoxesWithStrayVertex();
  BuiltLayout built(scene, Partitioner::kAuto);
  ASSERT_EQ(built.status, 0);
  const DofLayout &layout = built.layout;
  LocalTets tets;
  ASSERT_EQ(MigrateTets(PETSC_COMM_WORLD, built.share, layout, &tets), 0);
  size_t next = 0;
  int64_t index = 0;
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    if (body.fixed) {
      index += body.mesh.num_tets();
      continue;
    }
    for (int32_t t = 0; t < body.mesh.num_tets(); ++t, ++index) {
      std::array<PetscInt, 4> petsc;
      bool touches = false;
      for (int a = 0; a < 4; ++a) {
        petsc[a] = layout.PetscVertexOfNatural(body.first_vertex + body.mesh.tets(t, a));
        touches = touches || layout.OwnsPetscVertex(petsc[a]);
      }
      if (!touches) continue;
      ASSERT_LT(next, tets.size()) << "tet " << index << " missing";
      ASSERT_EQ(tets.index[next], index);
      EXPECT_EQ(tets.body[next], static_cast<int32_t>(b));
      EXPECT_EQ(tets.vertices[next], petsc);
      for (int a = 0; a < 4; ++a)
        EXPECT_EQ(tets.rest[next].row(a), body.mesh.vertices.row(body.mesh.tets(t, a)));
      ++next;
    }
  }
  EXPECT_EQ(next, tets.size()) << "tets that touch no owned vertex arrived";
}

}  // namespace
