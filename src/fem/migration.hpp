// The tets a rank assembles, moved to it from the ranks whose share holds them.
//
// Owner computes (row_assembly.hpp): a rank needs every free tet with at least
// one vertex it owns. Each rank sends each tet of its MeshShare to the owners of
// its vertices (one to four ranks), with the tet's PETSc vertices and rest
// positions fetched from the vertex slabs (mesh_share.hpp); no rank reads the
// scene's meshes. The received tets are sorted by their index among all tets
// (bodies in scene order, tets in file order), so every sum over them
// is formed in one order, whatever the number of ranks or the way the tets came.
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
  std::vector<int64_t> index;                     // among all tets, increasing
  std::vector<int32_t> body;                      // scene body
  std::vector<std::array<PetscInt, 4>> vertices;  // PETSc vertices
  std::vector<TetPositions> rest;                 // rest positions (m), row a: vertex a

  size_t size() const { return index.size(); }
};

// Collective. The tets with a vertex this rank owns, from every rank's share
// (after BuildDofLayout has numbered the share's slab).
PetscErrorCode MigrateTets(MPI_Comm comm, const MeshShare &share, const DofLayout &layout,
                           LocalTets *tets);

}  // namespace softbody
