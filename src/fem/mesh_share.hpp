// A rank's share of the scene's meshes: the input of the distributed set-up.
//
// Two even shares (EvenShareBegin), independent of the partition:
// - a slab of the natural vertices (all bodies, natural order): their placed rest
//   positions and initial velocities, and, once the layout is built
//   (partition.hpp), their free index and PETSc vertex;
// - a share of the tets (all bodies, in scene order, tets in file order): their
//   natural vertices and body; the tets of the bodies that are not fixed are the
//   free tets, which carry the unknowns.
// The set-up reaches the vertices its tets or its owned vertices name through a
// PetscSF whose roots are the vertex slabs (CreateSlabSF), so no rank needs
// another's share whole. Memory: O(N / P + T / P) per rank.
#pragma once

#include <petscsf.h>

#include <array>
#include <cstdint>
#include <vector>

#include "io/scene.hpp"

namespace softbody {

struct MeshShare {
  PetscInt num_vertices = 0;  // natural vertices over all ranks
  PetscInt first_vertex = 0;  // this rank's slab: [first_vertex, first_vertex + slab_size())
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> rest;        // m
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> velocities;  // m/s
  std::vector<PetscInt> free_index;    // per slab vertex, -1 when not free (partition.hpp)
  std::vector<PetscInt> petsc_vertex;  // per slab vertex, -1 when not free (partition.hpp)

  int64_t num_all_tets = 0;  // over all ranks and bodies
  int64_t first_tet = 0;     // this rank's share: [first_tet, first_tet + num_tets())
  std::vector<std::array<PetscInt, 4>> tets;  // natural vertices
  std::vector<int32_t> tet_body;              // scene body of each tet
  std::vector<char> body_fixed;               // per scene body: fixed (or at rest)

  PetscInt slab_size() const { return static_cast<PetscInt>(rest.rows()); }
  PetscInt num_tets() const { return static_cast<PetscInt>(tets.size()); }
  bool TetIsFree(size_t t) const { return !body_fixed[tet_body[t]]; }
};

// Not collective. This rank's shares (of `size` ranks), taken from a scene every
// rank holds (bodies' fixed flags as they are now); free_index and petsc_vertex
// are left empty.
MeshShare ShareScene(const Scene &scene, PetscMPIInt rank, PetscMPIInt size);

// How the meshes are held once distributed.
enum class MeshHolding {
  kSlabs,  // no rank holds a mesh whole
  kWhole,  // every rank holds every mesh (-scene_replicate)
};

// Collective, after LoadScene (rank 0 holds the meshes, but not the deferred .h5
// ones). kWhole: rank 0 reads the deferred meshes (LoadDeferredMeshes), every
// rank receives the meshes and initial velocities (BroadcastMeshes) and takes
// its shares from them. Otherwise no rank keeps a mesh whole (scene->meshes_held
// false everywhere): every rank reads its slabs of each deferred mesh
// (ReadBodyShareFromFile), and the shares are gathered by one PetscSF per kind of
// row from rank 0's meshes and the ranks' file slabs (meshes_read_in_slabs
// counts the latter); rank 0 then drops its meshes. The shares are the same
// whichever way a mesh came (bit for bit).
PetscErrorCode DistributeScene(MPI_Comm comm, const MeshingOptions &meshing, MeshHolding holding,
                               Scene *scene, MeshShare *share);

// Collective. A star forest with one root per vertex of this rank's slab and one
// leaf per entry of `naturals` (natural vertices, each in [0, num_vertices), any
// order, repeats allowed), leaf i attached to the root of naturals[i]. Bcast
// sends slab values to the leaves; Reduce sends leaf values to the slab.
PetscErrorCode CreateSlabSF(MPI_Comm comm, const MeshShare &share,
                            const std::vector<PetscInt> &naturals, PetscSF *sf);

// Collective. values[i] = the slab's `per_vertex` entries (`width` of them per
// vertex, each of `type`) of naturals[i], through CreateSlabSF's forest.
PetscErrorCode FetchFromSlabs(PetscSF sf, MPI_Datatype type, int width, const void *per_vertex,
                              void *values);

}  // namespace softbody
