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
//   as a serial count here does, part by part, natural order inside a part with
//   -vertex_order natural; natural_of_owned and the slabs' lookups agree with the
//   global arrays.
// - With the Hilbert order (METIS, whose partition is reproducible, unlike
//   PT-Scotch's in Debian's build): the same parts, each rank's owned vertices renumbered
//   inside its block so that their Hilbert indices (in the bounding cube of the
//   rank's owned rest positions, computed here from the scene) never decrease; the
//   lookups agree as above.
// - MigrateTets brings every free tet with an owned vertex, and only those, with its
//   PETSc vertices and rest positions (checked against the scene): in tet order with
//   the natural order, sorted by their sorted PETSc vertices with the Hilbert order.
#include <gtest/gtest.h>
#include <petscsys.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <set>
#include <utility>
#include <vector>

#include "box_mesh.hpp"
#include "fem/migration.hpp"
#include "fem/partition.hpp"
#include "fem/vertex_graph.hpp"
#include "fem/vertex_order.hpp"
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

// From the replicated numbering: the PETSc vertices of the free vertices (those
// with one) in natural order, i.e. by free index.
std::vector<PetscInt> PetscOfFree(const DofLayout &layout) {
  std::vector<PetscInt> petsc;
  for (const PetscInt p : layout.petsc_of_natural)
    if (p >= 0) petsc.push_back(p);
  return petsc;
}

struct BuiltLayout {
  MeshShare share;
  DofLayout layout;
  PetscErrorCode status;
  BuiltLayout(const Scene &scene, Partitioner partitioner,
              VertexOrder order = VertexOrder::kNatural)
      : share(ShareScene(scene, Rank(), Size())),
        status(BuildDofLayout(PETSC_COMM_WORLD, PartitionOptions{partitioner, order}, &share,
                              &layout)) {
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
    ASSERT_EQ(layout.petsc_of_natural.size(), expected_free.size());
    for (size_t v = 0; v < expected_free.size(); ++v)
      ASSERT_EQ(layout.petsc_of_natural[v] >= 0, expected_free[v] >= 0) << "vertex " << v;
    const PetscInt n = layout.num_free();
    const std::vector<PetscInt> petsc_of_free = PetscOfFree(layout);
    ASSERT_EQ(static_cast<PetscInt>(petsc_of_free.size()), n);
    std::vector<PetscInt> sorted = petsc_of_free;
    std::sort(sorted.begin(), sorted.end());
    for (PetscInt i = 0; i < n; ++i) ASSERT_EQ(sorted[i], i) << "not a permutation";
    ASSERT_EQ(layout.vertex_start.back(), n);
    // Inside a rank's block, PETSc order follows the natural order.
    for (PetscInt f = 1; f < n; ++f) {
      const PetscInt a = petsc_of_free[f - 1], b = petsc_of_free[f];
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

// The rest position of a natural vertex of the scene.
std::array<double, 3> RestOfNatural(const Scene &scene, PetscInt natural) {
  const Body &body = scene.bodies[BodyOfNatural(scene, natural)];
  const auto row = body.mesh.vertices.row(natural - body.first_vertex);
  return {row(0), row(1), row(2)};
}

TEST(DofLayout, HilbertOrderInsideEachRanksBlock) {
  const Scene scene = ThreeBoxesWithStrayVertex();
  BuiltLayout natural(scene, Partitioner::kMetis, VertexOrder::kNatural);
  BuiltLayout hilbert(scene, Partitioner::kMetis, VertexOrder::kHilbert);
  ASSERT_EQ(natural.status, 0);
  ASSERT_EQ(hilbert.status, 0);
  const DofLayout &layout = hilbert.layout;
  EXPECT_EQ(layout.vertex_order, VertexOrder::kHilbert);
  EXPECT_EQ(layout.vertex_start, natural.layout.vertex_start) << "the parts changed";
  std::vector<PetscInt> mine = layout.natural_of_owned, before = natural.layout.natural_of_owned;
  std::sort(mine.begin(), mine.end());
  EXPECT_EQ(mine, before) << "another set of owned vertices";
  const PetscInt owned = layout.local_count();
  for (PetscInt i = 0; i < owned; ++i)
    EXPECT_EQ(layout.PetscVertexOfNatural(layout.natural_of_owned[i]), layout.local_begin() + i);
  for (PetscInt i = 0; i < hilbert.share.slab_size(); ++i)
    EXPECT_EQ(hilbert.share.petsc_vertex[i],
              layout.PetscVertexOfNatural(hilbert.share.first_vertex + i));
  // Hilbert indices of the owned vertices in the bounding cube of their rest positions.
  std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (PetscInt natural_vertex : layout.natural_of_owned)
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], RestOfNatural(scene, natural_vertex)[c]);
      hi[c] = std::max(hi[c], RestOfNatural(scene, natural_vertex)[c]);
    }
  const double side = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  const double cells_per_metre = ((1u << kCurveBits) - 1) / side;  // as CurveOrder scales
  uint64_t previous = 0;
  for (PetscInt i = 0; i < owned; ++i) {
    const std::array<double, 3> X = RestOfNatural(scene, layout.natural_of_owned[i]);
    std::array<uint32_t, 3> cell;
    for (int c = 0; c < 3; ++c) cell[c] = static_cast<uint32_t>((X[c] - lo[c]) * cells_per_metre);
    const uint64_t index = HilbertIndex(cell, kCurveBits);
    EXPECT_GE(index, previous) << "owned vertex " << i;
    previous = index;
  }
}

// The tets of the Hilbert order: those of the natural order, each once, sorted by
// their sorted PETSc vertices (ties by tet index), with the new PETSc vertices.
TEST(MigrateTets, SortedByTheirVerticesInTheHilbertOrder) {
  const Scene scene = ThreeBoxesWithStrayVertex();
  BuiltLayout natural(scene, Partitioner::kMetis, VertexOrder::kNatural);
  BuiltLayout hilbert(scene, Partitioner::kMetis, VertexOrder::kHilbert);
  ASSERT_EQ(natural.status, 0);
  ASSERT_EQ(hilbert.status, 0);
  LocalTets by_index, sorted;
  ASSERT_EQ(MigrateTets(PETSC_COMM_WORLD, natural.share, natural.layout, &by_index), 0);
  ASSERT_EQ(MigrateTets(PETSC_COMM_WORLD, hilbert.share, hilbert.layout, &sorted), 0);
  ASSERT_EQ(sorted.size(), by_index.size());
  std::vector<std::pair<std::array<PetscInt, 4>, int64_t>> keys;
  for (size_t t = 0; t < sorted.size(); ++t) {
    // The same tet, found by its index, with the vertices renumbered.
    const size_t k =
        std::lower_bound(by_index.index.begin(), by_index.index.end(), sorted.index[t]) -
        by_index.index.begin();
    ASSERT_LT(k, by_index.size());
    ASSERT_EQ(by_index.index[k], sorted.index[t]);
    EXPECT_EQ(sorted.body[t], by_index.body[k]);
    for (int a = 0; a < 4; ++a) {
      const PetscInt natural_vertex =
          std::find(natural.layout.petsc_of_natural.begin(), natural.layout.petsc_of_natural.end(),
                    by_index.vertices[k][a]) -
          natural.layout.petsc_of_natural.begin();
      EXPECT_EQ(sorted.vertices[t][a], hilbert.layout.PetscVertexOfNatural(natural_vertex));
      EXPECT_EQ(sorted.rest[t].row(a), by_index.rest[k].row(a));
    }
    std::array<PetscInt, 4> v = sorted.vertices[t];
    std::sort(v.begin(), v.end());
    keys.emplace_back(v, sorted.index[t]);
  }
  EXPECT_TRUE(std::is_sorted(keys.begin(), keys.end()));
  std::vector<int64_t> indices = sorted.index;
  std::sort(indices.begin(), indices.end());
  EXPECT_EQ(indices, by_index.index) << "repeated or missing tets";
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
