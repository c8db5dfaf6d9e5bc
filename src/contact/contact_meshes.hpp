// What contact's set-up reads of the bodies' meshes, built from the ranks'
// shares (mesh_share.hpp), so that no rank holds a body's mesh whole.
//
// - The boundary triangles of every body (fixed ones too), as BoundaryTriangles
//   (mesh.hpp) gives them from the whole mesh: body-local vertex indices, the
//   same rows in the same order. Found from the shares (share_boundary.hpp) and
//   gathered on every rank: O(scene surface) per rank, 12 B per triangle, for
//   the set-up only (the guard, the obstacles' free triangles and overlap
//   separation keep their own copies, as they did).
// - Per body, its longest rest tet edge (m): a maximum over the tet shares;
//   per fixed body, its box: a reduction over the vertex slabs.
// - The fixed tets of this rank's tet share with their corners' rest
//   positions (TakeFixedShare), which fixed_tets.hpp keeps for the run.
// - Rest positions (m) of the vertices asked for (FetchRest), fetched from
//   the vertex slabs (read from the mesh where the scene holds it whole,
//   -scene_replicate).
// - The free bodies' tets listed under the key vertices asked for
//   (FetchFreeTets; key: a tet's first corner with unknowns, free_items.hpp):
//   each free tet travels once to the rank whose vertex slab holds its key, and
//   a rank asks those ranks for the tets of its keys. A tet without a key (no
//   corner with unknowns) goes to every rank.
// Memory: O(surface + local + what was asked for) per rank; messages likewise.
// Rest positions are copied bit for bit, and lengths computed with the same
// Eigen expressions as from the whole meshes, so everything contact builds from
// them is what it built from the whole meshes.
#pragma once

#include <petscsys.h>

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "contact/fixed_tets.hpp"
#include "contact/free_items.hpp"
#include "contact/geometry.hpp"
#include "fem/mesh_share.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"

namespace softbody {

class ContactMeshes {
 public:
  // #B x 3 body-local vertex indices, outward (BoundaryTriangles' rows).
  using Triangles = Eigen::Matrix<int32_t, Eigen::Dynamic, 3, Eigen::RowMajor>;
  using Positions = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

  // Collective, after the layout's replicated numbering (ReplicateNumbering).
  // The boundaries, the longest edges, and the free tets sent to the slab
  // owners of their keys. scene, layout and share must outlive this object;
  // the scene holds the fixed bodies' meshes (or all of them).
  PetscErrorCode Build(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                       const MeshShare &share);
  // Collective. Adds the rest positions of `naturals` (any order, repeats
  // allowed; each rank its own list).
  PetscErrorCode FetchRest(const std::vector<int32_t> &naturals);
  // Collective, once. free_tets(): the free tets listed under `keys` (natural
  // vertices, any order, repeats allowed; each rank its own list) and those
  // without a key. The tets held for other ranks' requests are freed.
  PetscErrorCode FetchFreeTets(const std::vector<int32_t> &keys);
  // Not collective. Frees free_tets() once nothing reads them.
  void ReleaseFreeTets() { std::vector<IndexedItem<FreeTet>>().swap(free_tets_); }

  const Triangles &boundary(size_t body) const { return boundary_[body]; }
  double longest_edge(size_t body) const { return longest_edge_[body]; }
  // The rest position of a fixed body's vertex or of one fetched (FetchRest),
  // as a row of a #V x 3 matrix like TetMesh::vertices; NaN for any other.
  Positions::ConstRowXpr rest_row(int32_t natural) const;
  Point rest(int32_t natural) const { return rest_row(natural).transpose(); }
  // The free tets of FetchFreeTets, with their keys (-1: none) and their index
  // in the scene's list of free tets (bodies in order, tets in mesh order); in
  // no particular order.
  const std::vector<IndexedItem<FreeTet>> &free_tets() const { return free_tets_; }
  // The scene's free tets (all ranks).
  int64_t num_free_tets() const { return num_free_tets_; }
  // This rank's share of the fixed tets with their corners (fixed_tets.hpp),
  // handed over once; the scene's fixed tets (all ranks).
  FixedTetShare TakeFixedShare() { return std::move(fixed_share_); }
  int64_t num_fixed_tets() const { return num_fixed_tets_; }
  // A fixed body's box (its vertices at rest); empty for a free body.
  const Box &fixed_box(size_t body) const { return fixed_box_[body]; }

 private:
  PetscErrorCode GatherBoundaries();
  PetscErrorCode FindLongestEdges();
  void KeepFixedShare(const Positions &corners);
  PetscErrorCode FindFixedBoxes();
  PetscErrorCode SendTetsToKeyOwners();
  int32_t KeyOf(const FreeTet &tet) const;

  MPI_Comm comm_ = MPI_COMM_NULL;
  PetscMPIInt size_ = 1;
  const Scene *scene_ = nullptr;
  const DofLayout *layout_ = nullptr;
  const MeshShare *share_ = nullptr;
  std::vector<Triangles> boundary_;           // per body
  std::vector<double> longest_edge_;          // per body (m)
  std::vector<int32_t> rest_natural_;         // sorted
  Positions rest_;                            // row k: rest_natural_[k]'s; last row NaN
  std::vector<IndexedItem<FreeTet>> keyed_;   // tets whose key is in this rank's slab, sorted
  std::vector<IndexedItem<FreeTet>> static_;  // tets without a key (every rank)
  std::vector<IndexedItem<FreeTet>> free_tets_;
  int64_t num_free_tets_ = 0;
  FixedTetShare fixed_share_;
  int64_t num_fixed_tets_ = 0;
  std::vector<Box> fixed_box_;  // per body
};

}  // namespace softbody
