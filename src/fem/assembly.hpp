// The local elements, the distributed state and its lumped mass, the elements'
// linear strain energy, and the assembly of the rest stiffness K by COO triplets.
//
// Every rank holds the elements it owns (the owner of an element is the owner
// of its lowest-numbered PETSc vertex). The COO assembly hands PETSc coordinate
// triplets: the pattern once (MatSetPreallocationCOO), the values then
// (MatSetValuesCOO: repeated entries are summed, off-process entries are sent
// to their owner). It builds K for -export_matrices (output.hpp), and it is the
// independent reference the unit tests compare RowAssembler against
// (tests/unit/coo_reference.hpp); the time step's matrices come from
// RowAssembler (row_assembly.hpp). Matrices are MATAIJ with block size 3 over
// the DofLayout.
#pragma once

#include <petscmat.h>

#include <array>
#include <vector>

#include "fem/element.hpp"
#include "fem/migration.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"

namespace softbody {

// Elements owned by this rank and their rest-state data.
struct LocalElements {
  std::vector<std::array<PetscInt, 4>> vertices;  // PETSc vertex indices
  // The vertices the local elements touch (owned or not), increasing PETSc
  // index, and each element's vertices as positions in that list.
  std::vector<PetscInt> touched_vertices;
  std::vector<std::array<PetscInt, 4>> touched_index;
  std::vector<ShapeGradients> gradients;  // rest shape-function gradients (1/m)
  std::vector<double> volumes;            // rest volumes |V| (m^3)
  std::vector<Lame> lame;                 // Pa
  std::vector<double> densities;          // kg/m^3

  size_t size() const { return vertices.size(); }
};

// Not collective. The tets among `tets` whose lowest PETSc vertex this rank owns,
// with their bodies' materials.
LocalElements CollectLocalElements(const Scene &scene, const DofLayout &layout,
                                   const LocalTets &tets);

// Collective. A MATAIJ matrix (block size 3) with the COO pattern of the local
// elements' 12 x 12 blocks.
PetscErrorCode CreateElasticMatrix(MPI_Comm comm, const DofLayout &layout,
                                   const LocalElements &elements, Mat *matrix);

// Collective. The rest stiffness K (N/m): CreateElasticMatrix filled with the
// linear element stiffness.
PetscErrorCode CreateStiffnessMatrix(MPI_Comm comm, const DofLayout &layout,
                                     const LocalElements &elements, double shear_scale, Mat *K);

// COO values of a matrix made by CreateElasticMatrix: 144 per element (its
// 12 x 12 block, row-major).
using CooValues = std::vector<PetscScalar>;

// Not collective. values = stiffness_scale K_e (linear stiffness) per element.
void LinearStiffnessValues(const LocalElements &elements, double shear_scale,
                           double stiffness_scale, CooValues *values);

// Not collective. Positions of element e's vertices (rows, m) from an array of
// 3 values per touched vertex (LocalElements::touched_vertices order).
TetPositions ElementPositions(const LocalElements &elements, size_t e, const PetscScalar *touched);

// Not collective. Linear strain energy sum_e V strain . C strain / 2 (J) of the
// local elements at positions x_touched (rest X_touched), element by element:
// every term is non-negative, unlike u^T K u / 2 summed in floating point.
double LinearStrainEnergy(const LocalElements &elements, double shear_scale,
                          const PetscScalar *x_touched, const PetscScalar *X_touched);

// Collective. Sets the matrix's values (made by CreateElasticMatrix) from values.
PetscErrorCode SetElasticMatrixValues(const CooValues &values, Mat matrix);

// Collective. Lumped mass per DOF (kg), density x volume / 4 to each vertex of
// each tet, repeated for the three coordinates. Created from the layout.
PetscErrorCode AssembleLumpedMass(MPI_Comm comm, const DofLayout &layout,
                                  const LocalElements &elements, Vec *lumped_mass);

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

// Energies of a state (J).
struct EnergySample {
  PetscReal kinetic = 0;        // v^T M v / 2
  PetscReal elastic = 0;        // strain energy
  PetscReal gravitational = 0;  // -sum_i m_i g . x_i
  PetscReal total() const { return kinetic + elastic + gravitational; }
};

// Collective. Rest and initial positions, initial velocities (from the share's
// slabs), lumped mass.
PetscErrorCode CreateState(MPI_Comm comm, const MeshShare &share, const DofLayout &layout,
                           const LocalElements &elements, State *state);

}  // namespace softbody
