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

#include "fem/element.hpp"
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

// Not collective.
LocalElements CollectLocalElements(const Scene &scene, const DofLayout &layout);

// Collective. A MATAIJ matrix (block size 3) with the COO pattern of the local
// elements' 12 x 12 blocks, plus, when with_diagonal, every local diagonal entry
// (for the mass term of A).
PetscErrorCode CreateElasticMatrix(MPI_Comm comm, const DofLayout &layout,
                                   const LocalElements &elements, PetscBool with_diagonal,
                                   Mat *matrix);

// Collective. The rest stiffness K (N/m): CreateElasticMatrix without diagonal
// part, filled with the linear element stiffness.
PetscErrorCode CreateStiffnessMatrix(MPI_Comm comm, const DofLayout &layout,
                                     const LocalElements &elements, double shear_scale, Mat *K);

// COO values of a matrix made by CreateElasticMatrix: 144 per element (its 12 x 12
// block, row-major), then, with a diagonal part, one per local DOF.
using CooValues = std::vector<PetscScalar>;

// Not collective. Element part of values = stiffness_scale K_e (linear stiffness).
void LinearStiffnessValues(const LocalElements &elements, double shear_scale,
                           double stiffness_scale, CooValues *values);

// Not collective. The corotational pass (Mueller & Gross 2004) over the local
// elements at positions x_touched (3 per touched vertex, m), rest positions
// X_touched: element part of values = stiffness_scale R K_e R^T; force_touched
// (zeroed here, 3 per touched vertex) += R K_e (R^T x_e - X_e); returns the local
// strain energy sum_e y^T K_e y / 2 (J). With damping: also records every y_e
// (12 per element) and, when damping->start holds y_e at the start of the step,
// adds R K_e (y_e - y_e,start) to damping->force_touched (zeroed here) and
// sum_e |y_e - y_e,start|_K_e^2 / 2 to damping->energy: the rotation-free
// deformation increment behind the corotated stiffness damping (integrator.hpp).
struct CorotatedDamping {
  std::vector<double> *current = nullptr;  // out: y_e
  const double *start = nullptr;           // in: y_e at the start of the step, or null
  PetscScalar *force_touched = nullptr;    // out (when start)
  double energy = 0;                       // out (when start), J
};
double CorotatedStiffnessValues(const LocalElements &elements, double shear_scale,
                                const PetscScalar *x_touched, const PetscScalar *X_touched,
                                double stiffness_scale, CooValues *values,
                                PetscScalar *force_touched, CorotatedDamping *damping = nullptr);

// Not collective. Linear strain energy sum_e V strain . C strain / 2 (J) of the
// local elements at positions x_touched (rest X_touched), element by element:
// every term is non-negative, unlike u^T K u / 2 summed in floating point.
double LinearStrainEnergy(const LocalElements &elements, double shear_scale,
                          const PetscScalar *x_touched, const PetscScalar *X_touched);

// Collective. Writes mass_scale x lumped_mass into the diagonal part of values
// (when lumped_mass is given) and sets the matrix's values from them.
PetscErrorCode SetElasticMatrixValues(Vec lumped_mass, double mass_scale, CooValues *values,
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

// Energies of a state (J).
struct EnergySample {
  PetscReal kinetic = 0;        // v^T M v / 2
  PetscReal elastic = 0;        // strain energy
  PetscReal gravitational = 0;  // -sum_i m_i g . x_i
  PetscReal total() const { return kinetic + elastic + gravitational; }
};

// Collective. Rest and initial positions, initial velocities, lumped mass.
PetscErrorCode CreateState(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                           const LocalElements &elements, State *state);

}  // namespace softbody
