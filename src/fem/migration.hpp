// The tets a rank assembles, moved to it from the ranks whose share holds them.
//
// Owner computes (row_assembly.hpp): a rank needs every free tet with at least
// one vertex it owns. Each rank sends each tet of its MeshShare to the owners of
// its vertices (one to four ranks), with the tet's PETSc vertices and rest
// positions fetched from the vertex slabs (mesh_share.hpp); no rank reads the
// scene's meshes. The received tets are sorted, so every sum over them is formed
// in one order whatever the way the tets came: by their sorted PETSc vertices
// (lexicographic, ties by tet index), so that element loops walk the vertices in
// their (space-filling, vertex_order.hpp) order; with -vertex_order natural, by
// their index among all tets (bodies in scene order, tets in file order), which
// is also independent of the number of ranks.
#pragma once

#include <petscsys.h>

#include <array>
#include <cstdint>
#include <vector>

#include "fem/element.hpp"
#include "fem/mesh_share.hpp"
#include "fem/partition.hpp"

namespace softbody {

struct LocalTets {
  std::vector<int64_t> index;                     // among all tets
  std::vector<int32_t> body;                      // scene body
  std::vector<std::array<PetscInt, 4>> vertices;  // PETSc vertices
  std::vector<TetPositions> rest;                 // rest positions (m), row a: vertex a

  size_t size() const { return index.size(); }
};

// Collective. The tets with a vertex this rank owns, from every rank's share
// (after BuildDofLayout has numbered the share's slab), in the order above
// (layout.vertex_order).
PetscErrorCode MigrateTets(MPI_Comm comm, const MeshShare &share, const DofLayout &layout,
                           LocalTets *tets);

}  // namespace softbody
