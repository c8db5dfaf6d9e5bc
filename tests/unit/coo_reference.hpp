// The independent reference test_row_assembly.cpp compares RowAssembler
// (row_assembly.hpp) against: the corotated matrix, force, energy and increment
// damping computed element by element with the Eigen kernels of element.hpp
// (CorotatedElement, ElasticForceAndEnergy) and handed to PETSc as COO triplets
// (assembly.hpp's COO path), the mass term added on the diagonal afterwards.
// Nothing here shares code with RowAssembler's element pass.
#pragma once

#include <petscmat.h>

#include <vector>

#include "fem/assembly.hpp"
#include "fem/element.hpp"

namespace softbody::coo_reference {

// Increment damping of the corotated pass: records every y_e (12 per element,
// rows R^T x_a - X_a) and, when `start` holds y_e at the start of the step, adds
// R K_e (y_e - y_e,start) to force_touched (zeroed here) and
// sum_e |y_e - y_e,start|_K_e^2 / 2 to energy (J).
struct CorotatedDamping {
  std::vector<double> *current = nullptr;  // out: y_e
  const double *start = nullptr;           // in: y_e at the start of the step, or null
  PetscScalar *force_touched = nullptr;    // out (when start)
  double energy = 0;                       // out (when start), J
};

// Not collective. The corotational pass (Mueller & Gross 2004) over the local
// elements at positions x_touched (3 per touched vertex, m), rest positions
// X_touched: values = stiffness_scale R K_e R^T per element (COO order of
// CreateElasticMatrix); force_touched (zeroed here, 3 per touched vertex) +=
// R K_e (R^T x_e - X_e); returns the local strain energy sum_e y^T K_e y / 2 (J).
inline double CorotatedStiffnessValues(const LocalElements &elements, double shear_scale,
                                       const PetscScalar *x_touched, const PetscScalar *X_touched,
                                       double stiffness_scale, CooValues *values,
                                       PetscScalar *force_touched,
                                       CorotatedDamping *damping = nullptr) {
  const size_t touched = 3 * elements.touched_vertices.size();
  std::fill(force_touched, force_touched + touched, 0.0);
  if (damping) {
    damping->current->resize(12 * elements.size());
    damping->energy = 0;
    if (damping->start) std::fill(damping->force_touched, damping->force_touched + touched, 0.0);
  }
  values->resize(144 * elements.size());
  PetscScalar *out = values->data();
  double energy = 0;
  for (size_t e = 0; e < elements.size(); ++e) {
    const TetPositions x = ElementPositions(elements, e, x_touched),
                       X = ElementPositions(elements, e, X_touched);
    TetPositions force;
    Mat12 K;
    double element_energy;
    const Mat3 R = CorotatedElement(elements.gradients[e], elements.volumes[e], elements.lame[e],
                                    shear_scale, x, X, &force, &element_energy, &K);
    energy += element_energy;
    for (int a = 0; a < 4; ++a)
      for (int c = 0; c < 3; ++c)
        force_touched[3 * elements.touched_index[e][a] + c] += force(a, c);
    if (damping) {
      Eigen::Map<Eigen::Matrix<double, 4, 3, Eigen::RowMajor>> y(damping->current->data() + 12 * e);
      y = x * R - X;  // rows R^T x_a - X_a
      if (damping->start) {
        const Eigen::Map<const Eigen::Matrix<double, 4, 3, Eigen::RowMajor>> y_start(
            damping->start + 12 * e);
        TetPositions increment_force;
        double increment_energy;
        ElasticForceAndEnergy(elements.gradients[e], elements.volumes[e], elements.lame[e],
                              shear_scale, y - y_start, &increment_force, &increment_energy);
        damping->energy += increment_energy;
        increment_force = increment_force * R.transpose();
        for (int a = 0; a < 4; ++a)
          for (int c = 0; c < 3; ++c)
            damping->force_touched[3 * elements.touched_index[e][a] + c] += increment_force(a, c);
      }
    }
    for (int i = 0; i < 12; ++i)
      for (int j = 0; j < 12; ++j) *out++ = stiffness_scale * K(i, j);
  }
  return energy;
}

// Collective. The reference A: the elements' COO values (stiffness part) plus
// mass_scale diag(lumped_mass).
inline PetscErrorCode ReferenceMatrix(MPI_Comm comm, const DofLayout &layout,
                                      const LocalElements &elements, const CooValues &values,
                                      Vec lumped_mass, double mass_scale, Mat *A) {
  PetscFunctionBeginUser;
  PetscCall(CreateElasticMatrix(comm, layout, elements, A));
  PetscCall(SetElasticMatrixValues(values, *A));
  Vec diagonal;
  PetscCall(VecDuplicate(lumped_mass, &diagonal));
  PetscCall(VecCopy(lumped_mass, diagonal));
  PetscCall(VecScale(diagonal, mass_scale));
  PetscCall(MatDiagonalSet(*A, diagonal, ADD_VALUES));
  PetscCall(VecDestroy(&diagonal));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody::coo_reference
