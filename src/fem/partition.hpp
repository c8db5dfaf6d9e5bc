// Degrees of freedom and their distribution.
//
// Free vertices are the vertices of bodies that are not fixed and that belong to
// at least one tet (a stray vertex has no mass and no stiffness: it stays put).
// Their natural order ("free index") follows the scene's natural vertex order.
// The free-vertex graph (vertices adjacent when they share a tet; vertex_graph.hpp)
// is split into one part per rank by METIS or PT-Scotch (-partitioner); the
// vertices are renumbered part by part, so rank r owns the contiguous block
// [vertex_start[r], vertex_start[r+1]) of "PETSc vertex" indices, and inside its
// block in the order of -vertex_order (vertex_order.hpp): along a space-filling
// curve through the rest positions, or the natural order. DOF 3 p + c is
// coordinate c of PETSc vertex p (block size 3).
#pragma once

#include <petscsys.h>

#include <vector>

#include "fem/mesh_share.hpp"
#include "fem/vertex_graph.hpp"
#include "fem/vertex_order.hpp"
#include "io/scene.hpp"

namespace softbody {

struct PartitionOptions {
  Partitioner partitioner = Partitioner::kAuto;  // -partitioner auto|metis|ptscotch
  // -vertex_order natural|hilbert|morton: the order inside each rank's block
  // (Hilbert: the fastest measured, docs/performance.md "Locality").
  VertexOrder vertex_order = VertexOrder::kHilbert;
};

// Collective. Reads -partitioner and -vertex_order.
PetscErrorCode ProcessPartitionOptions(MPI_Comm comm, PartitionOptions *options);

// The partitioner's name as -partitioner spells it ("auto" for none: one rank).
const char *PartitionerName(Partitioner partitioner);

struct DofLayout {
  std::vector<PetscInt> vertex_start;  // size ranks + 1: ownership of PETSc vertices
  // This rank's share (O(local), what scalable code uses): the natural vertex of
  // each owned PETSc vertex, in PETSc order.
  std::vector<PetscInt> natural_of_owned;
  // Replicated (O(N) on every rank, 4 B per vertex; empty unless
  // ReplicateNumbering ran): for contact and -export_matrices, which still read
  // it (docs/design/scale-out.md); new code uses natural_of_owned or a
  // MeshShare lookup (mesh_share.hpp).
  std::vector<PetscInt> petsc_of_natural;  // natural vertex -> PETSc vertex, or -1
  PetscMPIInt rank = 0, size = 1;
  Partitioner partitioner = Partitioner::kAuto;      // the one that ran (kAuto: one rank, none)
  VertexOrder vertex_order = VertexOrder::kNatural;  // the order inside each rank's block

  PetscInt num_free() const { return vertex_start.back(); }
  PetscInt local_begin() const { return vertex_start[rank]; }
  PetscInt local_count() const { return vertex_start[rank + 1] - vertex_start[rank]; }
  bool OwnsPetscVertex(PetscInt petsc) const {
    return petsc >= local_begin() && petsc < vertex_start[rank + 1];
  }
  // Natural vertex -> PETSc vertex; -1 for a vertex without unknowns (fixed, at
  // rest or stray). Needs ReplicateNumbering.
  PetscInt PetscVertexOfNatural(PetscInt natural) const { return petsc_of_natural[natural]; }
  // Natural vertex -> index among this rank's vertices (0 .. local_count() - 1),
  // or -1 when the vertex has no unknowns (fixed, at rest or stray) or another
  // rank owns it. Needs ReplicateNumbering.
  PetscInt LocalOfNatural(PetscInt natural) const {
    const PetscInt petsc = petsc_of_natural[natural];
    return petsc >= 0 && OwnsPetscVertex(petsc) ? petsc - local_begin() : -1;
  }
};

// Collective. Numbers the free vertices (the vertices of the share's tets) in
// natural order, partitions their graph (vertex_graph.hpp) from the share's tets,
// numbers them part by part (PETSc's ISPartitioningToNumbering) and then, inside
// each rank's block, in options.vertex_order of their rest positions (O(local):
// each rank orders the vertices it owns). Fills share->free_index and
// share->petsc_vertex for the slab, and the layout.
PetscErrorCode BuildDofLayout(MPI_Comm comm, const PartitionOptions &options, MeshShare *share,
                              DofLayout *layout);

// Collective, after BuildDofLayout. The replicated petsc_of_natural (O(N) on
// every rank), gathered from the slabs: only for what still reads it, contact
// and -export_matrices.
PetscErrorCode ReplicateNumbering(MPI_Comm comm, const MeshShare &share, DofLayout *layout);

// Not collective. The body of a natural vertex (the last body starting at or before it).
int32_t BodyOfNatural(const Scene &scene, PetscInt natural);

// Not collective. The body of each vertex this rank owns, in PETSc order.
std::vector<int32_t> OwnedVertexBodies(const Scene &scene, const DofLayout &layout);

// What could set a body in motion besides its initial velocities.
struct MotionSources {
  bool gravity = false;        // g != 0
  bool ground = false;         // a ground plane (a body inside it is pushed out)
  bool constraints = false;    // distance constraints or edge bounds
  std::vector<bool> deformed;  // per body: named by a -deform
};

// Collective. Bodies that nothing can set in motion become immobile like fixed
// ones (body.fixed = body.at_rest = true, and in share->body_fixed), so they add
// no unknowns: a body that is not fixed, all of whose initial velocities are
// zero, that no -deform names, in a scene without gravity, ground or constraints
// in which every other free body is just as still (a moving body could hit it),
// and whose bounding box meets no other body's (contact would push overlapping
// bodies apart). Boxes and velocities come from the slabs (reductions). Sets
// *marked to how many bodies were marked.
PetscErrorCode MarkBodiesAtRest(MPI_Comm comm, const MotionSources &sources, Scene *scene,
                                MeshShare *share, int *marked);

}  // namespace softbody
