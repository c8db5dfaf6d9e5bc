// Distributed assembly of the lumped mass and the elastic matrices.
//
// Every rank computes the elements it owns (the owner of an element is the owner
// of its lowest-numbered PETSc vertex) and hands PETSc coordinate (COO) triplets:
// the pattern once (MatSetPreallocationCOO), the values at every refill
// (MatSetValuesCOO: repeated entries are summed, off-process entries are sent to
// their owner). Matrices are MATAIJ with block size 3 over the DofLayout.
#pragma once

#include <petscmat.h>

#include <array>
#include <vector>

#include "element.hpp"
#include "partition.hpp"
#include "scene.hpp"

namespace softbody {

// Elements owned by this rank and their rest-state data.
struct LocalElements {
  std::vector<std::array<PetscInt, 4>> vertices;  // PETSc vertex indices
  std::vector<ShapeGradients> gradients;          // rest shape-function gradients (1/m)
  std::vector<double> volumes;                    // rest volumes |V| (m^3)
  std::vector<Lame> lame;                         // Pa
  std::vector<double> densities;                  // kg/m^3

  size_t size() const { return vertices.size(); }
};

// Not collective.
LocalElements CollectLocalElements(const Scene &scene, const DofLayout &layout);

// Collective. A MATAIJ matrix (block size 3) with the COO pattern of the local
// elements' 12 x 12 blocks, plus, when with_diagonal, every local diagonal entry
// (for the mass term of A).
PetscErrorCode CreateElasticMatrix(MPI_Comm comm, const DofLayout &layout,
                                   const LocalElements &elements, PetscBool with_diagonal, Mat *matrix);

// Collective. matrix = stiffness_scale K + mass_scale diag(lumped_mass), where K
// is the linear elastic stiffness with the given shear scale; lumped_mass may be
// nullptr only when the matrix was created without its diagonal part.
PetscErrorCode FillElasticMatrix(const LocalElements &elements, double shear_scale,
                                 double stiffness_scale, Vec lumped_mass, double mass_scale,
                                 Mat matrix);

// Collective. Lumped mass per DOF (kg), density x volume / 4 to each vertex of
// each tet, repeated for the three coordinates. Created from the layout.
PetscErrorCode AssembleLumpedMass(MPI_Comm comm, const DofLayout &layout,
                                  const LocalElements &elements, Vec *lumped_mass);

}  // namespace softbody

namespace softbody {

// The distributed state, PETSc order, block size 3 (x y z per vertex).
struct State {
  Vec rest_positions = nullptr;  // X (m)
  Vec positions = nullptr;       // x (m)
  Vec velocities = nullptr;      // v (m/s)
  Vec lumped_mass = nullptr;     // M per DOF (kg)

  State() = default;
  State(const State &) = delete;
  State &operator=(const State &) = delete;
  ~State();
};

// Collective. Rest and initial positions, initial velocities, lumped mass.
PetscErrorCode CreateState(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                           const LocalElements &elements, State *state);

}  // namespace softbody
