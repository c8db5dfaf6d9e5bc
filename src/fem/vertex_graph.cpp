#include "fem/vertex_graph.hpp"

#include <metis.h>
#include <petscmat.h>

#include <algorithm>
#include <climits>
#include <cstdint>
#include <cstdlib>

#include "common/exchange.hpp"

namespace softbody {

namespace {

// METIS's random seed, fixed so that a scene is partitioned the same way at
// every run (results reproducible bit for bit); any fixed value would do.
constexpr idx_t kMetisSeed = 1;

// An edge (row, neighbour) of the graph packed in 64 bits, row in the high half, so
// that sorting the packed edges sorts them by row, then by neighbour.
uint64_t PackEdge(PetscInt row, PetscInt neighbour) {
  return (static_cast<uint64_t>(row) << 32) | static_cast<uint32_t>(neighbour);
}
PetscInt EdgeRow(uint64_t edge) {
  return static_cast<PetscInt>(edge >> 32);
}
PetscInt EdgeNeighbour(uint64_t edge) {
  return static_cast<PetscInt>(edge & 0xffffffffu);
}

void SortUnique(std::vector<uint64_t> *edges) {
  std::sort(edges->begin(), edges->end());
  edges->erase(std::unique(edges->begin(), edges->end()), edges->end());
}

// The edges of `tets` (free indices), each in both directions, without repeats.
std::vector<uint64_t> EdgesOfTets(const std::vector<std::array<PetscInt, 4>> &tets) {
  std::vector<uint64_t> edges;
  edges.reserve(12 * tets.size());
  for (const std::array<PetscInt, 4> &v : tets)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        if (a != b) edges.push_back(PackEdge(v[a], v[b]));
  SortUnique(&edges);
  return edges;
}

// Sends every edge to the rank holding its row; returns the edges of this rank's rows.
// `edges` is sorted by row, so the edges for each rank are one contiguous run.
PetscErrorCode SendEdgesToRows(MPI_Comm comm, PetscInt n, PetscMPIInt size,
                               const std::vector<uint64_t> &edges, std::vector<uint64_t> *mine) {
  PetscFunctionBeginUser;
  std::vector<int> send_counts(size, 0);
  size_t e = 0;
  for (PetscMPIInt q = 0; q < size; ++q) {
    const size_t run_begin = e;
    while (e < edges.size() && EdgeRow(edges[e]) < EvenShareBegin(n, size, q + 1)) ++e;
    PetscCheck(e - run_begin <= INT_MAX, PETSC_COMM_SELF, PETSC_ERR_SUP,
               "the vertex graph has more edges for one rank than MPI can send at once: "
               "run on more ranks");
    send_counts[q] = static_cast<int>(e - run_begin);
  }
  PetscCall(ExchangeRecords(comm, edges, send_counts, mine));
  SortUnique(mine);
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode BuildVertexGraphRows(MPI_Comm comm, const std::vector<std::array<PetscInt, 4>> &tets,
                                    PetscInt num_free, VertexGraphRows *graph) {
  PetscFunctionBeginUser;
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  const PetscInt n = num_free;
  graph->num_vertices = n;
  graph->row_begin = EvenShareBegin(n, size, rank);
  const PetscInt rows = EvenShareBegin(n, size, rank + 1) - graph->row_begin;
  std::vector<uint64_t> edges;
  PetscCall(SendEdgesToRows(comm, n, size, EdgesOfTets(tets), &edges));
  graph->offsets.assign(rows + 1, 0);
  graph->neighbours.resize(edges.size());
  for (size_t e = 0; e < edges.size(); ++e) {
    ++graph->offsets[EdgeRow(edges[e]) - graph->row_begin + 1];
    graph->neighbours[e] = EdgeNeighbour(edges[e]);
  }
  for (PetscInt i = 0; i < rows; ++i) graph->offsets[i + 1] += graph->offsets[i];
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// Rank 0: METIS k-way on the whole graph (CSR).
PetscErrorCode MetisKway(std::vector<idx_t> &offsets, std::vector<idx_t> &neighbours, idx_t parts,
                         std::vector<idx_t> *part) {
  PetscFunctionBeginUser;
  idx_t n = static_cast<idx_t>(offsets.size()) - 1, constraints = 1, cut = 0;
  idx_t options[METIS_NOPTIONS];
  METIS_SetDefaultOptions(options);
  options[METIS_OPTION_SEED] = kMetisSeed;
  part->assign(n, 0);
  const int status =
      METIS_PartGraphKway(&n, &constraints, offsets.data(), neighbours.data(), nullptr, nullptr,
                          nullptr, &parts, nullptr, nullptr, options, &cut, part->data());
  PetscCheck(status == METIS_OK, PETSC_COMM_SELF, PETSC_ERR_LIB, "METIS_PartGraphKway failed (%d)",
             status);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The rows gathered on rank 0 (as METIS's 32-bit CSR), partitioned there, and each
// rank's parts sent back.
PetscErrorCode PartitionWithMetis(MPI_Comm comm, const VertexGraphRows &graph, PetscMPIInt size,
                                  std::vector<PetscInt> *part) {
  PetscFunctionBeginUser;
  static_assert(sizeof(idx_t) == sizeof(int32_t), "METIS built with 32-bit indices expected");
  static_assert(sizeof(PetscInt) == sizeof(int32_t), "PETSc built with 32-bit indices expected");
  int64_t local = graph.neighbours.size(), total = 0;
  PetscCallMPI(MPI_Allreduce(&local, &total, 1, MPI_INT64_T, MPI_SUM, comm));
  PetscCheck(total < INT32_MAX, comm, PETSC_ERR_SUP,
             "option -partitioner metis: the vertex graph (%lld edges) is too large for METIS's "
             "32-bit indices; use -partitioner ptscotch",
             (long long)total);
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  std::vector<int> rows(size), edges(size), row_offsets(size + 1, 0), edge_offsets(size + 1, 0);
  const int my_rows = static_cast<int>(graph.num_rows()), my_edges = static_cast<int>(local);
  PetscCallMPI(MPI_Gather(&my_rows, 1, MPI_INT, rows.data(), 1, MPI_INT, 0, comm));
  PetscCallMPI(MPI_Gather(&my_edges, 1, MPI_INT, edges.data(), 1, MPI_INT, 0, comm));
  for (PetscMPIInt q = 0; q < size; ++q) {
    row_offsets[q + 1] = row_offsets[q] + rows[q];
    edge_offsets[q + 1] = edge_offsets[q] + edges[q];
  }
  // Row lengths travel (offsets are relative to each rank's first row).
  std::vector<idx_t> lengths(graph.num_rows()), all_lengths(rank == 0 ? graph.num_vertices : 0);
  for (PetscInt i = 0; i < graph.num_rows(); ++i)
    lengths[i] = graph.offsets[i + 1] - graph.offsets[i];
  std::vector<idx_t> neighbours(rank == 0 ? total : 0), all_part;
  PetscCallMPI(MPI_Gatherv(lengths.data(), my_rows, MPI_INT32_T, all_lengths.data(), rows.data(),
                           row_offsets.data(), MPI_INT32_T, 0, comm));
  PetscCallMPI(MPI_Gatherv(graph.neighbours.data(), my_edges, MPI_INT32_T, neighbours.data(),
                           edges.data(), edge_offsets.data(), MPI_INT32_T, 0, comm));
  PetscErrorCode status = PETSC_SUCCESS;
  if (rank == 0) {
    std::vector<idx_t> offsets(graph.num_vertices + 1, 0);
    for (PetscInt v = 0; v < graph.num_vertices; ++v) offsets[v + 1] = offsets[v] + all_lengths[v];
    status = MetisKway(offsets, neighbours, size, &all_part);
  }
  PetscCallMPI(MPI_Bcast(&status, 1, MPI_INT, 0, comm));
  PetscCheck(status == PETSC_SUCCESS, comm, PETSC_ERR_LIB, "METIS failed on rank 0");
  part->resize(graph.num_rows());
  PetscCallMPI(MPI_Scatterv(all_part.data(), rows.data(), row_offsets.data(), MPI_INT32_T,
                            part->data(), my_rows, MPI_INT32_T, 0, comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// PT-Scotch through PETSc's MatPartitioning on the distributed adjacency (MPIAdj).
// The tuning options -mat_partitioning_ptscotch_* apply. Debian builds Scotch
// without SCOTCH_DETERMINISTIC: on many ranks the partition can change from run to
// run (results then agree to round-off, not bit for bit; -partitioner metis is
// reproducible).
PetscErrorCode PartitionWithPtScotch(MPI_Comm comm, const VertexGraphRows &graph,
                                     std::vector<PetscInt> *part) {
  PetscFunctionBeginUser;
  PetscInt *offsets, *neighbours;  // owned by the MPIAdj matrix once created
  PetscCall(PetscMalloc1(graph.offsets.size(), &offsets));
  PetscCall(PetscMalloc1(std::max<size_t>(graph.neighbours.size(), 1), &neighbours));
  std::copy(graph.offsets.begin(), graph.offsets.end(), offsets);
  std::copy(graph.neighbours.begin(), graph.neighbours.end(), neighbours);
  Mat adjacency;
  PetscCall(MatCreateMPIAdj(comm, graph.num_rows(), graph.num_vertices, offsets, neighbours,
                            nullptr, &adjacency));
  MatPartitioning partitioning;
  PetscCall(MatPartitioningCreate(comm, &partitioning));
  PetscCall(MatPartitioningSetAdjacency(partitioning, adjacency));
  PetscCall(MatPartitioningSetType(partitioning, MATPARTITIONINGPTSCOTCH));
  PetscCall(MatPartitioningSetFromOptions(partitioning));
  // Scotch 7's threads call MPI concurrently, which needs MPI_THREAD_MULTIPLE (PETSc
  // initialises MPI without it, and Scotch's threaded bipartitions then hang):
  // one thread per rank.
  setenv("SCOTCH_PTHREAD_NUMBER", "1", 1);
  IS parts;
  PetscCall(MatPartitioningApply(partitioning, &parts));
  const PetscInt *values;
  PetscCall(ISGetIndices(parts, &values));
  part->assign(values, values + graph.num_rows());
  PetscCall(ISRestoreIndices(parts, &values));
  PetscCall(ISDestroy(&parts));
  PetscCall(MatPartitioningDestroy(&partitioning));
  PetscCall(MatDestroy(&adjacency));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode PartitionVertexGraph(MPI_Comm comm, VertexGraphRows *graph, Partitioner requested,
                                    std::vector<PetscInt> *part, Partitioner *used) {
  PetscFunctionBeginUser;
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  *used = Partitioner::kAuto;
  if (size == 1 || graph->num_vertices == 0) {
    part->assign(graph->num_rows(), 0);
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  *used = requested != Partitioner::kAuto  ? requested
          : size <= kMetisLargestRankCount ? Partitioner::kMetis
                                           : Partitioner::kPtScotch;
  if (*used == Partitioner::kMetis)
    PetscCall(PartitionWithMetis(comm, *graph, size, part));
  else
    PetscCall(PartitionWithPtScotch(comm, *graph, part));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
