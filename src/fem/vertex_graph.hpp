// The free-vertex graph, distributed by rows, and its partition into one part per rank.
//
// Vertices are free indices 0 .. n-1 (partition.hpp); two are adjacent when they
// share a tet. Rank r holds the rows of the free vertices of its even share
// [EvenShareBegin(n, P, r), EvenShareBegin(n, P, r + 1)): each row the sorted free
// indices of its neighbours, without the vertex itself. The rows are built from each
// rank's even share of the free bodies' tets, so no rank ever holds the whole graph
// (a rank's memory is O(its tets + its rows)); the edges travel to their rows' ranks
// in one all-to-all exchange.
#pragma once

#include <petscsys.h>

#include <array>
#include <vector>

#include "common/even_share.hpp"

namespace softbody {

struct VertexGraphRows {
  PetscInt num_vertices = 0;         // n, over all ranks
  PetscInt row_begin = 0;            // this rank's rows: [row_begin, row_begin + num_rows())
  std::vector<PetscInt> offsets;     // CSR: row i's neighbours are
  std::vector<PetscInt> neighbours;  //   neighbours[offsets[i] .. offsets[i + 1])

  PetscInt num_rows() const { return static_cast<PetscInt>(offsets.size()) - 1; }
};

// Collective. The rows of this rank's even share of the n = `num_free` free vertices,
// from `tets` (free indices of their vertices): this rank's share of the free tets;
// together the ranks' tets are every free tet.
PetscErrorCode BuildVertexGraphRows(MPI_Comm comm, const std::vector<std::array<PetscInt, 4>> &tets,
                                    PetscInt num_free, VertexGraphRows *graph);

// Which partitioner splits the graph.
enum class Partitioner {
  kAuto,      // METIS on up to kMetisLargestRankCount ranks, else PT-Scotch
  kMetis,     // the whole graph gathered to rank 0, METIS k-way there
  kPtScotch,  // PT-Scotch on the distributed graph (PETSc's MatPartitioning)
};

// METIS partitions better than PT-Scotch on the meshes measured (docs/design/
// fem-solvers.md) and keeps results identical to earlier versions; it needs the whole
// graph on rank 0, affordable while two ranks share the work.
constexpr PetscMPIInt kMetisLargestRankCount = 2;

// Collective. *part: the part (rank) of each of this rank's rows; `used` says which
// partitioner ran (kMetis or kPtScotch; kAuto resolved). One rank: every part 0, no
// partitioner (used = kAuto).
PetscErrorCode PartitionVertexGraph(MPI_Comm comm, VertexGraphRows *graph, Partitioner requested,
                                    std::vector<PetscInt> *part, Partitioner *used);

}  // namespace softbody
