#include "fem/partition.hpp"

#include <petscis.h>
#include <petscsf.h>

#include <algorithm>
#include <limits>
#include <numeric>
#include <utility>

#include "common/exchange.hpp"
#include "common/options.hpp"

namespace softbody {

namespace {

// Per body, over all ranks' slabs: the bounding box of its rest positions and
// whether any of its vertices has a non-zero initial velocity (reductions).
struct BodyFacts {
  std::vector<double> lo, hi;  // 3 per body; +inf / -inf for a body without vertices
  std::vector<int> moving;     // per body, 0 or 1
};

PetscErrorCode GatherBodyFacts(MPI_Comm comm, const Scene &scene, const MeshShare &share,
                               BodyFacts *facts) {
  PetscFunctionBeginUser;
  const size_t n = scene.bodies.size();
  facts->lo.assign(3 * n, std::numeric_limits<double>::infinity());
  facts->hi.assign(3 * n, -std::numeric_limits<double>::infinity());
  facts->moving.assign(n, 0);
  for (PetscInt i = 0; i < share.slab_size(); ++i) {
    const int32_t b = BodyOfNatural(scene, share.first_vertex + i);
    for (int c = 0; c < 3; ++c) {
      facts->lo[3 * b + c] = std::min(facts->lo[3 * b + c], share.rest(i, c));
      facts->hi[3 * b + c] = std::max(facts->hi[3 * b + c], share.rest(i, c));
    }
    if (share.velocities.row(i).squaredNorm() != 0) facts->moving[b] = 1;
  }
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, facts->lo.data(), 3 * n, MPI_DOUBLE, MPI_MIN, comm));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, facts->hi.data(), 3 * n, MPI_DOUBLE, MPI_MAX, comm));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, facts->moving.data(), n, MPI_INT, MPI_MAX, comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Whether the boxes of bodies a and b meet.
bool BoxesMeet(const BodyFacts &facts, size_t a, size_t b) {
  for (int c = 0; c < 3; ++c)
    if (facts.lo[3 * a + c] > facts.hi[3 * b + c] || facts.lo[3 * b + c] > facts.hi[3 * a + c])
      return false;
  return true;
}

}  // namespace

PetscErrorCode MarkBodiesAtRest(MPI_Comm comm, const MotionSources &sources, Scene *scene,
                                MeshShare *share, int *marked) {
  PetscFunctionBeginUser;
  *marked = 0;
  if (sources.gravity || sources.ground || sources.constraints) PetscFunctionReturn(PETSC_SUCCESS);
  const size_t n = scene->bodies.size();
  for (size_t b = 0; b < n; ++b)
    if (!scene->bodies[b].fixed && b < sources.deformed.size() && sources.deformed[b])
      PetscFunctionReturn(PETSC_SUCCESS);
  BodyFacts facts;
  PetscCall(GatherBodyFacts(comm, *scene, *share, &facts));
  for (size_t b = 0; b < n; ++b)
    if (!scene->bodies[b].fixed && facts.moving[b]) PetscFunctionReturn(PETSC_SUCCESS);  // it moves
  // Everything is still: a free body at rest unless its box meets another's.
  std::vector<bool> alone(n, true);
  for (size_t a = 0; a < n; ++a)
    for (size_t b = a + 1; b < n; ++b) {
      if (scene->bodies[a].num_vertices() == 0 || scene->bodies[b].num_vertices() == 0) continue;
      if (BoxesMeet(facts, a, b)) alone[a] = alone[b] = false;
    }
  for (size_t b = 0; b < n; ++b) {
    Body &body = scene->bodies[b];
    if (body.fixed || !alone[b]) continue;
    body.fixed = body.at_rest = true;
    share->body_fixed[b] = 1;
    ++*marked;
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ProcessPartitionOptions(MPI_Comm comm, PartitionOptions *options) {
  PetscFunctionBeginUser;
  static const char *const kNames[] = {"auto", "metis", "ptscotch", "Partitioner", "", nullptr};
  PetscEnum chosen = static_cast<PetscEnum>(options->partitioner);
  PetscEnum order = static_cast<PetscEnum>(options->vertex_order);
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kChoice, "-partitioner", kNames},
                                     {OptionSyntax::kChoice, "-vertex_order", kVertexOrderNames}}));
  PetscOptionsBegin(comm, nullptr, "Partition of the free vertices over the ranks", nullptr);
  PetscCall(PetscOptionsEnum("-partitioner",
                             "auto (METIS on up to 2 ranks, else PT-Scotch), metis (the whole "
                             "graph on rank 0) or ptscotch (on the distributed graph)",
                             nullptr, kNames, chosen, &chosen, nullptr));
  PetscCall(PetscOptionsEnum("-vertex_order",
                             "order of each rank's vertices (and tets, sorted by their vertices) "
                             "for cache locality: hilbert or morton (a space-filling curve through "
                             "the rest positions) or natural (the mesh files' order); the output "
                             "is in the files' order either way",
                             nullptr, kVertexOrderNames, order, &order, nullptr));
  PetscOptionsEnd();
  options->partitioner = static_cast<Partitioner>(chosen);
  options->vertex_order = static_cast<VertexOrder>(order);
  PetscFunctionReturn(PETSC_SUCCESS);
}

const char *PartitionerName(Partitioner partitioner) {
  switch (partitioner) {
    case Partitioner::kMetis:
      return "metis";
    case Partitioner::kPtScotch:
      return "ptscotch";
    default:
      return "auto";
  }
}

namespace {

// The natural vertices of the share's free tets, four per tet.
std::vector<PetscInt> FreeTetVertices(const MeshShare &share) {
  std::vector<PetscInt> naturals;
  for (size_t t = 0; t < share.tets.size(); ++t)
    if (share.TetIsFree(t))
      naturals.insert(naturals.end(), share.tets[t].begin(), share.tets[t].end());
  return naturals;
}

// Collective. share->free_index: a vertex is free when a free tet names it (a
// reduction from the tets' vertices to their slabs, through tet_sf: CreateSlabSF
// of FreeTetVertices), numbered in natural order (an exclusive scan over the
// slabs). Returns the number of free vertices.
PetscErrorCode NumberFreeVertices(MPI_Comm comm, PetscSF tet_sf, MeshShare *share,
                                  PetscInt *num_free) {
  PetscFunctionBeginUser;
  PetscInt leaves;
  PetscCall(PetscSFGetGraph(tet_sf, nullptr, &leaves, nullptr, nullptr));
  const std::vector<PetscInt> named(leaves, 1);
  share->free_index.assign(share->slab_size(), 0);
  PetscCall(PetscSFReduceBegin(tet_sf, MPIU_INT, named.data(), share->free_index.data(), MPI_MAX));
  PetscCall(PetscSFReduceEnd(tet_sf, MPIU_INT, named.data(), share->free_index.data(), MPI_MAX));
  PetscInt count = std::accumulate(share->free_index.begin(), share->free_index.end(), PetscInt(0));
  PetscInt next = 0;
  PetscCallMPI(MPI_Exscan(&count, &next, 1, MPIU_INT, MPI_SUM, comm));
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (rank == 0) next = 0;  // MPI_Exscan leaves rank 0's result undefined
  for (PetscInt &index : share->free_index) index = index ? next++ : -1;
  PetscCallMPI(MPI_Allreduce(&count, num_free, 1, MPIU_INT, MPI_SUM, comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. The free indices of the vertices of the share's free tets (from the slabs).
PetscErrorCode FreeTets(PetscSF tet_sf, const MeshShare &share,
                        std::vector<std::array<PetscInt, 4>> *tets) {
  PetscFunctionBeginUser;
  PetscInt leaves;
  PetscCall(PetscSFGetGraph(tet_sf, nullptr, &leaves, nullptr, nullptr));
  tets->resize(leaves / 4);
  PetscCall(FetchFromSlabs(tet_sf, MPIU_INT, 1, share.free_index.data(), tets->data()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// PETSc numbers from the parts of this rank's graph rows: part by part, natural
// order inside a part (ISPartitioningToNumbering). Sets vertex_start; *numbers is
// the PETSc vertex of each of this rank's rows (free indices).
PetscErrorCode NumberByPart(MPI_Comm comm, const std::vector<PetscInt> &part, DofLayout *layout,
                            IS *numbers) {
  PetscFunctionBeginUser;
  IS parts;
  PetscCall(ISCreateGeneral(comm, static_cast<PetscInt>(part.size()), part.data(),
                            PETSC_USE_POINTER, &parts));
  PetscCall(ISPartitioningToNumbering(parts, numbers));
  std::vector<PetscInt> counts(layout->size);
  PetscCall(ISPartitioningCount(parts, layout->size, counts.data()));
  layout->vertex_start.assign(layout->size + 1, 0);
  for (PetscMPIInt q = 0; q < layout->size; ++q)
    layout->vertex_start[q + 1] = layout->vertex_start[q] + counts[q];
  PetscCall(ISDestroy(&parts));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. A star forest from the free vertices of the share's slab (leaves,
// at their slab positions) to `key` of each (roots: `roots_here` consecutive
// entries per rank).
PetscErrorCode CreateFreeVertexSF(MPI_Comm comm, const MeshShare &share,
                                  const std::vector<PetscInt> &key, PetscInt roots_here,
                                  PetscSF *sf) {
  PetscFunctionBeginUser;
  std::vector<PetscInt> slab_position, remote;
  for (PetscInt i = 0; i < share.slab_size(); ++i)
    if (share.free_index[i] >= 0) {
      slab_position.push_back(i);
      remote.push_back(key[i]);
    }
  PetscLayout roots;
  PetscCall(PetscLayoutCreate(comm, &roots));
  PetscCall(PetscLayoutSetLocalSize(roots, roots_here));
  PetscCall(PetscLayoutSetUp(roots));
  PetscCall(PetscSFCreate(comm, sf));
  PetscCall(PetscSFSetGraphLayout(*sf, roots, static_cast<PetscInt>(remote.size()),
                                  slab_position.data(), PETSC_COPY_VALUES, remote.data()));
  PetscCall(PetscLayoutDestroy(&roots));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. share->petsc_vertex from the numbering (distributed by free index,
// like the graph rows), and layout->natural_of_owned from the slabs.
PetscErrorCode SpreadNumbering(MPI_Comm comm, IS numbers, MeshShare *share, DofLayout *layout) {
  PetscFunctionBeginUser;
  PetscInt rows;
  const PetscInt *petsc_of_row;
  PetscCall(ISGetLocalSize(numbers, &rows));
  PetscCall(ISGetIndices(numbers, &petsc_of_row));
  PetscSF by_free, by_petsc;
  PetscCall(CreateFreeVertexSF(comm, *share, share->free_index, rows, &by_free));
  share->petsc_vertex.assign(share->slab_size(), -1);
  PetscCall(
      PetscSFBcastBegin(by_free, MPIU_INT, petsc_of_row, share->petsc_vertex.data(), MPI_REPLACE));
  PetscCall(
      PetscSFBcastEnd(by_free, MPIU_INT, petsc_of_row, share->petsc_vertex.data(), MPI_REPLACE));
  PetscCall(ISRestoreIndices(numbers, &petsc_of_row));
  PetscCall(PetscSFDestroy(&by_free));
  std::vector<PetscInt> natural(share->slab_size());
  std::iota(natural.begin(), natural.end(), share->first_vertex);
  layout->natural_of_owned.assign(layout->local_count(), -1);
  PetscCall(
      CreateFreeVertexSF(comm, *share, share->petsc_vertex, layout->local_count(), &by_petsc));
  PetscCall(PetscSFReduceBegin(by_petsc, MPIU_INT, natural.data(), layout->natural_of_owned.data(),
                               MPI_REPLACE));
  PetscCall(PetscSFReduceEnd(by_petsc, MPIU_INT, natural.data(), layout->natural_of_owned.data(),
                             MPI_REPLACE));
  PetscCall(PetscSFDestroy(&by_petsc));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Renumbers the vertices this rank owns inside its block, along the
// curve of `order` through their rest positions (fetched from the slabs):
// layout->natural_of_owned is permuted and share->petsc_vertex follows.
PetscErrorCode OrderOwnedVertices(MPI_Comm comm, VertexOrder order, MeshShare *share,
                                  DofLayout *layout) {
  PetscFunctionBeginUser;
  layout->vertex_order = order;
  if (order == VertexOrder::kNatural) PetscFunctionReturn(PETSC_SUCCESS);
  const PetscInt owned = layout->local_count(), begin = layout->local_begin();
  PetscSF by_petsc;  // roots: the owned vertices; leaves: the slabs' free vertices
  PetscCall(CreateFreeVertexSF(comm, *share, share->petsc_vertex, owned, &by_petsc));
  std::vector<std::array<double, 3>> rest(owned);
  MPI_Datatype point;
  PetscCallMPI(MPI_Type_contiguous(3, MPI_DOUBLE, &point));
  PetscCallMPI(MPI_Type_commit(&point));
  PetscCall(PetscSFReduceBegin(by_petsc, point, share->rest.data(), rest.data(), MPI_REPLACE));
  PetscCall(PetscSFReduceEnd(by_petsc, point, share->rest.data(), rest.data(), MPI_REPLACE));
  PetscCallMPI(MPI_Type_free(&point));
  const std::vector<PetscInt> old_of_new = CurveOrder(rest, order);
  std::vector<PetscInt> new_petsc(owned), natural(owned);
  for (PetscInt k = 0; k < owned; ++k) {
    new_petsc[old_of_new[k]] = begin + k;
    natural[k] = layout->natural_of_owned[old_of_new[k]];
  }
  layout->natural_of_owned = std::move(natural);
  PetscCall(PetscSFBcastBegin(by_petsc, MPIU_INT, new_petsc.data(), share->petsc_vertex.data(),
                              MPI_REPLACE));
  PetscCall(PetscSFBcastEnd(by_petsc, MPIU_INT, new_petsc.data(), share->petsc_vertex.data(),
                            MPI_REPLACE));
  PetscCall(PetscSFDestroy(&by_petsc));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode BuildDofLayout(MPI_Comm comm, const PartitionOptions &options, MeshShare *share,
                              DofLayout *layout) {
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &layout->rank));
  PetscCallMPI(MPI_Comm_size(comm, &layout->size));
  PetscSF tet_sf;
  PetscCall(CreateSlabSF(comm, *share, FreeTetVertices(*share), &tet_sf));
  PetscInt num_free;
  PetscCall(NumberFreeVertices(comm, tet_sf, share, &num_free));
  VertexGraphRows graph;
  {
    std::vector<std::array<PetscInt, 4>> free_tets;
    PetscCall(FreeTets(tet_sf, *share, &free_tets));
    PetscCall(BuildVertexGraphRows(comm, free_tets, num_free, &graph));
  }
  PetscCall(PetscSFDestroy(&tet_sf));
  std::vector<PetscInt> part;
  PetscCall(PartitionVertexGraph(comm, &graph, options.partitioner, &part, &layout->partitioner));
  graph = VertexGraphRows();
  IS numbers;
  PetscCall(NumberByPart(comm, part, layout, &numbers));
  PetscCall(SpreadNumbering(comm, numbers, share, layout));
  PetscCall(ISDestroy(&numbers));
  PetscCall(OrderOwnedVertices(comm, options.vertex_order, share, layout));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ReplicateNumbering(MPI_Comm comm, const MeshShare &share, DofLayout *layout) {
  PetscFunctionBeginUser;
  // The slabs are consecutive ranges of natural vertices in rank order.
  std::vector<PetscInt> slab(share.slab_size());
  for (PetscInt i = 0; i < share.slab_size(); ++i)
    slab[i] = share.free_index[i] >= 0 ? share.petsc_vertex[i] : -1;
  PetscCall(AllGatherRecords(comm, slab, &layout->petsc_of_natural));
  PetscCheck(static_cast<PetscInt>(layout->petsc_of_natural.size()) == share.num_vertices, comm,
             PETSC_ERR_PLIB, "the slabs do not cover the natural vertices");
  PetscFunctionReturn(PETSC_SUCCESS);
}

int32_t BodyOfNatural(const Scene &scene, PetscInt natural) {
  const auto after = std::upper_bound(
      scene.bodies.begin(), scene.bodies.end(), natural,
      [](PetscInt v, const Body &body) { return v < static_cast<PetscInt>(body.first_vertex); });
  return static_cast<int32_t>(after - scene.bodies.begin()) - 1;
}

std::vector<int32_t> OwnedVertexBodies(const Scene &scene, const DofLayout &layout) {
  std::vector<int32_t> owned(layout.local_count());
  for (PetscInt i = 0; i < layout.local_count(); ++i)
    owned[i] = BodyOfNatural(scene, layout.natural_of_owned[i]);
  return owned;
}

}  // namespace softbody
