// Time integration of the linear finite-element equations of motion
//
//     M x'' + D x' + K (x - X) = f_ext,    D = a M + b K  (Rayleigh damping),
//
// with backward (implicit) Euler in velocity form, one linear solve per step:
//
//     (M + dt D + dt^2 K) v1 = M v0 - dt K (x0 - X) + dt f_ext,    x1 = x0 + dt v1.
//
// M is the lumped mass (kg, kept as a Vec), K the stiffness (N/m), X the rest
// positions (m), x positions (m), v velocities (m/s), dt in s, a in 1/s, b in s.
// D is never formed: A = (1 + a dt) M + (b dt + dt^2) K. A is assembled and
// factorised once per time step size; each step then costs one K x product and
// one solve. Energies: kinetic v^T M v / 2, elastic (x - X)^T K (x - X) / 2 (J).
#pragma once

#include <petscksp.h>

#include "assembly.hpp"

namespace softbody {

struct IntegratorOptions {
  PetscReal dt = 0.02;     // s
  PetscInt steps = 100;
  PetscReal alpha = 0.1;   // mass damping a, 1/s
  PetscReal beta = 0.1;    // stiffness damping b, s
  PetscReal shear_scale = 1.0;
};

// Collective. Reads -dt -steps -alpha -beta -shear_scale; rejects impossible values.
PetscErrorCode ProcessIntegratorOptions(MPI_Comm comm, IntegratorOptions *options);

struct SolverStatistics {
  PetscInt solves = 0;
  PetscInt total_iterations = 0;
  PetscInt last_iterations = 0;
  PetscInt max_iterations = 0;
  PetscLogDouble factor_seconds = 0;  // wall time of the last (re)factorisation
};

class LinearImplicitEuler {
 public:
  LinearImplicitEuler() = default;
  LinearImplicitEuler(const LinearImplicitEuler &) = delete;
  LinearImplicitEuler &operator=(const LinearImplicitEuler &) = delete;
  ~LinearImplicitEuler();

  // Collective. Assembles K and A for options.dt and sets up (factorises) the
  // solver. rest_positions and lumped_mass are referenced, not copied.
  PetscErrorCode Setup(MPI_Comm comm, const DofLayout &layout, const LocalElements &elements,
                       Vec rest_positions, Vec lumped_mass, const IntegratorOptions &options);
  // Collective. Refills A and refactorises for a new time step size (s).
  PetscErrorCode SetTimeStep(PetscReal dt);
  // Collective. Advances positions x and velocities v by one step (f_ext = 0).
  PetscErrorCode Step(Vec x, Vec v);
  // Collective. Kinetic and elastic energy (J) of the state (x, v).
  PetscErrorCode Energies(Vec x, Vec v, PetscReal *kinetic, PetscReal *elastic);

  Mat stiffness() const { return K_; }
  KSP solver() const { return ksp_; }
  PetscReal time_step() const { return dt_; }
  const SolverStatistics &statistics() const { return stats_; }

 private:
  // K (x - X) into stiffness_product_, unless already computed for these
  // positions (x changes only in Step).
  PetscErrorCode UpdateStiffnessProduct(Vec x);

  const LocalElements *elements_ = nullptr;
  IntegratorOptions options_;
  PetscReal dt_ = 0;
  Vec rest_ = nullptr, mass_ = nullptr;      // not owned
  Mat K_ = nullptr, A_ = nullptr;
  KSP ksp_ = nullptr;
  Vec displacement_ = nullptr, stiffness_product_ = nullptr, rhs_ = nullptr;
  bool product_current_ = false;             // K u is that of the positions of the last Step
  SolverStatistics stats_;
};

}  // namespace softbody
