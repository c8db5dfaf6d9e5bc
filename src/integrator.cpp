#include "integrator.hpp"

#include <cmath>

#include "log_stages.hpp"
#include "options.hpp"
#include "text_reader.hpp"
#include "solver.hpp"
#include "warp_preconditioner.hpp"

namespace softbody {

const char *const kElasticityModes[] = {"linear", "corotational", "ElasticityMode", "MODE_", nullptr};

PetscErrorCode ProcessIntegratorOptions(MPI_Comm comm, IntegratorOptions *o) {
  PetscFunctionBeginUser;
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kChoice, "-mode", kElasticityModes},
                                     {OptionSyntax::kReal, "-dt"},
                                     {OptionSyntax::kRealList, "-gravity"},
                                     {OptionSyntax::kInteger, "-steps"},
                                     {OptionSyntax::kReal, "-alpha"},
                                     {OptionSyntax::kReal, "-beta"},
                                     {OptionSyntax::kReal, "-shear_scale"}}));
  char schedule[PETSC_MAX_PATH_LEN] = "";
  PetscReal gravity[3] = {o->gravity[0], o->gravity[1], o->gravity[2]};
  PetscInt gravity_count = 3;
  PetscBool gravity_set = PETSC_FALSE;
  PetscOptionsBegin(comm, nullptr, "Time integration (backward Euler)", nullptr);
  PetscCall(PetscOptionsEnum("-mode",
                             "Elasticity: linear (K factorised once) or corotational (per-tet "
                             "rotations, K rebuilt and solved every step)",
                             nullptr, kElasticityModes, (PetscEnum)o->mode, (PetscEnum *)&o->mode,
                             nullptr));
  PetscCall(PetscOptionsReal("-dt", "Time step (s)", nullptr, o->dt, &o->dt, nullptr));
  PetscCall(PetscOptionsString("-dt_schedule",
                               "Change the time step during the run: t1:dt1,t2:dt2 (s) means dt1 from "
                               "time t1 on, then dt2 from t2 on; A is refactorised once per change",
                               nullptr, schedule, schedule, sizeof(schedule), nullptr));
  PetscCall(PetscOptionsRealArray("-gravity", "Gravitational acceleration gx,gy,gz (m/s^2)", nullptr,
                                  gravity, &gravity_count, &gravity_set));
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
  if (gravity_set) {
    PetscCheck(gravity_count == 3, comm, PETSC_ERR_USER_INPUT, "option -gravity: expected gx,gy,gz");
    o->gravity = Eigen::Vector3d(gravity[0], gravity[1], gravity[2]);
  }
  o->dt_schedule.clear();
  for (std::string_view rest = schedule; !rest.empty();) {
    const size_t comma = rest.find(',');
    const std::string_view item = rest.substr(0, comma);
    const size_t colon = item.find(':');
    std::pair<PetscReal, PetscReal> entry;
    PetscCheck(colon != std::string_view::npos && ParseNumber(item.substr(0, colon), &entry.first) &&
                   ParseNumber(item.substr(colon + 1), &entry.second) && std::isfinite(entry.first) &&
                   std::isfinite(entry.second) && entry.first >= 0 && entry.second > 0,
               comm, PETSC_ERR_USER_INPUT,
               "option -dt_schedule: '%s' is not time:dt with time >= 0 and dt > 0 (s)",
               std::string(item).c_str());
    PetscCheck(o->dt_schedule.empty() || entry.first > o->dt_schedule.back().first, comm,
               PETSC_ERR_USER_INPUT, "option -dt_schedule: times must increase");
    o->dt_schedule.push_back(entry);
    if (comma == std::string_view::npos) break;
    rest.remove_prefix(comma + 1);
  }
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

PetscReal TimeStepAt(const IntegratorOptions &options, PetscReal time) {
  PetscReal dt = options.dt;
  // An entry applies from its time on, up to round-off in the accumulated time.
  for (const auto &[from, step] : options.dt_schedule)
    if (time >= from - 1e-9 * step) dt = step;
  return dt;
}

ImplicitEuler::~ImplicitEuler() {
  VecDestroy(&gravity_force_);
  VecDestroy(&x_start_);
  KSPDestroy(&ksp_);
  MatDestroy(&A_);
  MatDestroy(&K_);
  MatDestroy(&A_linear_);
  VecDestroy(&elastic_force_);
  VecDestroy(&rhs_);
  VecDestroy(&displacement_);
  VecScatterDestroy(&touched_scatter_);
  VecDestroy(&x_touched_);
  VecDestroy(&X_touched_);
}

PetscErrorCode ImplicitEuler::Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                                    const LocalElements &elements, Vec rest_positions,
                                    Vec lumped_mass, const IntegratorOptions &options) {
  PetscFunctionBeginUser;
  elements_ = &elements;
  options_ = options;
  rest_ = rest_positions;
  mass_ = lumped_mass;
  PetscCall(VecDuplicate(rest_, &elastic_force_));
  PetscCall(VecDuplicate(rest_, &rhs_));
  if (options.gravity.squaredNorm() > 0) {  // f_ext = M g, coordinate by coordinate
    PetscCall(VecDuplicate(rest_, &gravity_force_));
    PetscCall(VecCopy(mass_, gravity_force_));
    PetscScalar *f;
    PetscInt n;
    PetscCall(VecGetLocalSize(gravity_force_, &n));
    PetscCall(VecGetArray(gravity_force_, &f));
    for (PetscInt i = 0; i < n; ++i) f[i] *= options.gravity[i % 3];
    PetscCall(VecRestoreArray(gravity_force_, &f));
  }
  PetscCall(assembler_.Setup(comm, scene, layout, options.shear_scale, rest_));
  // A: the plain product for CG's many products with it; K (one product per
  // linear step) keeps PETSc's default, as the stability matrix was set against it.
  PetscCall(assembler_.CreateMatrix(&A_, options.mode == MODE_COROTATIONAL));
  if (options.mode == MODE_LINEAR) {
    StageScope stage(Stages().assembly);
    PetscCall(assembler_.CreateMatrix(&K_));
    PetscCall(assembler_.Fill(K_, false, nullptr, 1.0, nullptr, 0.0, nullptr, nullptr));
    PetscCall(VecDuplicate(rest_, &displacement_));
  }
  {
    // Gather plan: owned and ghost positions of every vertex the local elements
    // touch (corotational steps; energies in both modes).
    const PetscInt touched = static_cast<PetscInt>(elements.touched_vertices.size());
    IS from;
    PetscCall(ISCreateBlock(PETSC_COMM_SELF, 3, touched, elements.touched_vertices.data(),
                            PETSC_COPY_VALUES, &from));
    PetscCall(VecCreateSeq(PETSC_COMM_SELF, 3 * touched, &x_touched_));
    PetscCall(VecDuplicate(x_touched_, &X_touched_));
    PetscCall(VecScatterCreate(rest_, from, x_touched_, nullptr, &touched_scatter_));
    PetscCall(ISDestroy(&from));
    PetscCall(VecScatterBegin(touched_scatter_, rest_, X_touched_, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecScatterEnd(touched_scatter_, rest_, X_touched_, INSERT_VALUES, SCATTER_FORWARD));
  }

  PetscCall(ApplyPresetDefaults(options.mode == MODE_LINEAR ? kDirectPreset : kCorotationalPreset));
  PetscCall(CreateSolver(A_, rest_positions, &ksp_));
  PC pc;
  PetscCall(KSPGetPC(ksp_, &pc));
  PetscBool gamg;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCGAMG, &gamg));
  gamg_ = gamg;
  PetscBool warp;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCWarp, &warp));
  if (warp && options.mode == MODE_COROTATIONAL) {
    // The warp preconditioner: A0 = the linear system, factorised per time step size.
    PetscCall(MatDuplicate(A_, MAT_DO_NOT_COPY_VALUES, &A_linear_));
    PetscCall(PCWarpSetLinearOperator(pc, A_linear_));
    assembler_.ComputeVertexRotations(true);
  } else if (warp) {  // linear mode: A itself, no rotations (a direct solve in one iteration)
    PetscCall(PCWarpSetLinearOperator(pc, A_));
    std::vector<double> identity(9 * layout.local_count(), 0.0);
    for (PetscInt v = 0; v < layout.local_count(); ++v) identity[9 * v] = identity[9 * v + 4] = identity[9 * v + 8] = 1.0;
    PetscCall(PCWarpSetRotations(pc, layout.local_count(), identity.data()));
  }
  PetscCall(SetTimeStep(options.dt));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::SetTimeStep(PetscReal dt) {
  PetscFunctionBeginUser;
  if (dt_ > 0) ++stats_.time_step_changes;
  dt_ = dt;
  if (options_.mode == MODE_COROTATIONAL) {
    elastic_state_current_ = false;  // A depends on dt: refilled at the next step
    if (A_linear_) {
      StageScope stage(Stages().assembly);
      PetscCall(assembler_.Fill(A_linear_, false, nullptr, options_.beta * dt + dt * dt, mass_,
                                1.0 + options_.alpha * dt, nullptr, nullptr));
    }
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  const PetscReal a = options_.alpha, b = options_.beta;
  PetscLogDouble start, end;
  {
    StageScope stage(Stages().assembly);
    PetscCall(PetscTime(&start));
    PetscCall(assembler_.Fill(A_, false, nullptr, b * dt + dt * dt, mass_, 1.0 + a * dt, nullptr, nullptr));
    PetscCall(PetscTime(&end));
    stats_.assemble_seconds = end - start;
    ++stats_.assemblies;
  }
  StageScope stage(Stages().factorisation);
  PetscCall(PetscTime(&start));
  PetscCall(KSPSetOperators(ksp_, A_, A_));
  PetscCall(KSPSetUp(ksp_));
  PetscCall(PetscTime(&end));
  stats_.factor_seconds = end - start;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::UpdateNearNullSpace(Vec x) {
  PetscFunctionBeginUser;
  MatNullSpace rigid_body_modes;
  PetscCall(MatNullSpaceCreateRigidBody(x, &rigid_body_modes));
  PetscCall(MatSetNearNullSpace(A_, rigid_body_modes));
  PetscCall(MatNullSpaceDestroy(&rigid_body_modes));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::UpdateElasticState(Vec x) {
  PetscFunctionBeginUser;
  if (elastic_state_current_) PetscFunctionReturn(PETSC_SUCCESS);
  if (options_.mode == MODE_LINEAR) {
    // f_el = K (x - X); its energy only when asked for (Energies).
    PetscCall(VecWAXPY(displacement_, -1.0, rest_, x));
    PetscCall(MatMult(K_, displacement_, elastic_force_));
  } else {
    // A = (1 + a dt) M + (b dt + dt^2) sum_e R K_e R^T, f_el and the energy in one pass.
    StageScope stage(Stages().assembly);
    const PetscReal a = options_.alpha, b = options_.beta;
    PetscLogDouble start, end;
    PetscCall(PetscTime(&start));
    PetscCall(assembler_.Fill(A_, true, x, b * dt_ + dt_ * dt_, mass_, 1.0 + a * dt_, elastic_force_,
                              &elastic_energy_));
    PetscCall(PetscTime(&end));
    stats_.assemble_seconds = end - start;
    ++stats_.assemblies;
    if (gamg_) PetscCall(UpdateNearNullSpace(x));
    if (A_linear_) {
      PC pc;
      PetscCall(KSPGetPC(ksp_, &pc));
      const std::vector<double> &rotations = assembler_.vertex_rotations();
      PetscCall(PCWarpSetRotations(pc, static_cast<PetscInt>(rotations.size() / 9), rotations.data()));
    }
  }
  elastic_state_current_ = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::Solve(Vec v, const ContactSolver *contact) {
  PetscFunctionBeginUser;
  KSPConvergedReason reason = KSP_CONVERGED_ITS;
  PetscInt iterations = 0;
  if (options_.mode == MODE_COROTATIONAL) {
    // The preconditioner's set-up for the refilled A, timed on its own stage.
    StageScope stage(Stages().factorisation);
    PC pc;
    PetscLogDouble start, end;
    PetscCall(PetscTime(&start));
    PetscCall(KSPGetPC(ksp_, &pc));
    PetscCall(PCSetUp(pc));
    PetscCall(PetscTime(&end));
    stats_.last_setup_seconds = end - start;
  }
  if (!contact || contact->global_constraint_count() == 0) {
    PetscCall(KSPSolve(ksp_, rhs_, v));
    PetscCall(KSPGetConvergedReason(ksp_, &reason));
    PetscCall(KSPGetIterationNumber(ksp_, &iterations));
    reactions_.clear();
  } else {
    StageScope stage(Stages().contact);
    PetscCall(projected_.Solve(ksp_, rhs_, contact->velocity_constraints(), v, &reactions_, &iterations));
    ++stats_.contact_solves;
    stats_.contact_iterations += iterations;
  }
  PetscCheck(reason >= 0, PetscObjectComm((PetscObject)ksp_), PETSC_ERR_NOT_CONVERGED,
             "step %" PetscInt_FMT ": the linear solve did not converge (%s after %" PetscInt_FMT
             " iterations); try a smaller -dt or another -ksp_type/-pc_type",
             stats_.solves + 1, KSPConvergedReasons[reason], iterations);
  ++stats_.solves;
  stats_.last_iterations = iterations;
  stats_.total_iterations += iterations;
  stats_.min_iterations = PetscMin(stats_.min_iterations, iterations);
  stats_.max_iterations = PetscMax(stats_.max_iterations, iterations);
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::Step(Vec x, Vec v, ContactSolver *contact) {
  PetscFunctionBeginUser;
  // rhs = M v0 - dt f_el(x0) + dt f_ext
  PetscCall(UpdateElasticState(x));
  PetscCall(VecPointwiseMult(rhs_, mass_, v));
  PetscCall(VecAXPY(rhs_, -dt_, elastic_force_));
  if (gravity_force_) PetscCall(VecAXPY(rhs_, dt_, gravity_force_));
  if (!contact || !contact->active()) {
    // A v1 = rhs; v holds v0, the initial guess of iterative solvers.
    PetscCall(Solve(v, nullptr));
    PetscCall(VecAXPY(x, dt_, v));  // x1 = x0 + dt v1
    elastic_state_current_ = false;
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  // With contact: the obstacles move with v0 meanwhile; constrain and solve again
  // until the step takes no further vertex inside an obstacle.
  if (!x_start_) PetscCall(VecDuplicate(x, &x_start_));
  PetscCall(VecCopy(x, x_start_));
  {
    StageScope stage(Stages().contact);
    PetscCall(contact->BeginStep(x_start_, v, dt_));
  }
  constexpr int kMaxRounds = 20;
  bool added = true;
  for (int round = 0; added && round < kMaxRounds; ++round) {
    PetscCall(Solve(v, contact));
    StageScope stage(Stages().contact);
    PetscCall(contact->AddPenetrations(x_start_, v, dt_, &added));
  }
  if (added) PetscCall(Solve(v, contact));
  PetscCall(VecWAXPY(x, dt_, v, x_start_));  // x1 = x0 + dt v1
  bool changed;
  {
    StageScope stage(Stages().contact);
    PetscCall(contact->EndStep(x, v, reactions_, &changed));
  }
  elastic_state_current_ = false;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::TimeAssembly(Vec x, PetscInt repeats, std::vector<double> *seconds) {
  PetscFunctionBeginUser;
  StageScope stage(Stages().assembly);
  const PetscReal a = options_.alpha, b = options_.beta;
  const bool rotated = options_.mode == MODE_COROTATIONAL;
  seconds->clear();
  for (PetscInt repeat = 0; repeat < repeats; ++repeat) {
    PetscLogDouble start, end;
    PetscCallMPI(MPI_Barrier(PetscObjectComm((PetscObject)x)));
    PetscCall(PetscTime(&start));
    PetscCall(assembler_.Fill(A_, rotated, x, b * dt_ + dt_ * dt_, mass_, 1.0 + a * dt_,
                              rotated ? elastic_force_ : nullptr, rotated ? &elastic_energy_ : nullptr));
    PetscCall(PetscTime(&end));
    seconds->push_back(end - start);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::Energies(Vec x, Vec v, EnergySample *energy) {
  PetscFunctionBeginUser;
  PetscCall(UpdateElasticState(x));
  energy->elastic = elastic_energy_;
  if (options_.mode == MODE_LINEAR) {  // element by element: see LinearStrainEnergy
    PetscCall(VecScatterBegin(touched_scatter_, x, x_touched_, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecScatterEnd(touched_scatter_, x, x_touched_, INSERT_VALUES, SCATTER_FORWARD));
    const PetscScalar *x_touched, *X_touched;
    PetscCall(VecGetArrayRead(x_touched_, &x_touched));
    PetscCall(VecGetArrayRead(X_touched_, &X_touched));
    const double local_energy = LinearStrainEnergy(*elements_, options_.shear_scale, x_touched, X_touched);
    PetscCall(VecRestoreArrayRead(x_touched_, &x_touched));
    PetscCall(VecRestoreArrayRead(X_touched_, &X_touched));
    PetscCall(MPIU_Allreduce(&local_energy, &energy->elastic, 1, MPIU_REAL, MPIU_SUM,
                             PetscObjectComm((PetscObject)x)));
  }
  energy->gravitational = 0;
  if (gravity_force_) {
    PetscCall(VecDot(gravity_force_, x, &energy->gravitational));
    energy->gravitational *= -1;
  }
  PetscCall(VecPointwiseMult(rhs_, mass_, v));
  PetscCall(VecDot(rhs_, v, &energy->kinetic));
  energy->kinetic *= 0.5;
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
