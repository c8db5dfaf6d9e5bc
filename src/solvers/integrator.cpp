#include "solvers/integrator.hpp"

#include <cmath>
#include <utility>

#include "app/log_stages.hpp"
#include "common/options.hpp"
#include "common/text_reader.hpp"
#include "fem/block_matrix.hpp"
#include "fem/block_product.hpp"
#include "fem/matrix_pages.hpp"
#include "solvers/solver.hpp"
#include "solvers/warp/warp_preconditioner.hpp"

namespace softbody {

namespace {

// -dt_schedule: an entry applies from its time t on, with t taken as reached
// within this fraction of its step (the accumulated time carries round-off).
constexpr PetscReal kScheduleTimeTolerance = 1e-9;
// With contact: most rounds of "solve, add penetrating vertices or release
// slipping contacts"; a last solve follows when the rounds run out. Twenty
// rounds is well above what settling contacts take.
constexpr int kMaxContactRounds = 20;
// Solves with the collision guard's zone velocities prescribed (each round
// holds the vertices the guard would still move); the guard after the step
// resolves what is left.
constexpr int kMaxGuardSolves = 10;

// Corotational iteration (CorotationalStep):
// Sufficient decrease of the line search (Armijo's c1, the customary 1e-4): P
// must fall by this fraction of s g.d, or, near the root, |g| by this fraction of s.
constexpr PetscReal kSufficientDecrease = 1e-4;
// "Near the root": the last |g| is below this fraction of g's scale; there |g|
// decides, as round-off in P hides its decrease.
constexpr PetscReal kNearRootFraction = 1e-2;
// The line search halves s at most this often (s = 2^-40: the iterate stands).
constexpr int kMaxHalvings = 40;
// Relative round-off of the energy balance: an iterate "gains energy" only
// beyond this fraction of the energies involved.
constexpr PetscReal kEnergyRoundOff = 1e-12;
// The iteration stalls when |g| keeps more than this fraction of its last value.
constexpr PetscReal kStallRatio = 0.9;

// -dt_adapt (AdaptiveStep). A new target substep size is the old one times
// kSafety (tol / error)^(1 / (order + 1)), the customary safety factor 0.9 so
// that the next substep passes; a rejection shrinks it by at most kMaxShrink;
// an accepted substep grows it only when the estimate allows kGrowthThreshold
// (A is refactorised for every new size: sizes that would grow by less stay),
// and by at most kMaxGrowth per substep (one rung of the ladder of halvings).
constexpr PetscReal kSafety = 0.9;
constexpr PetscReal kMaxShrink = 0.2;
constexpr PetscReal kGrowthThreshold = 1.5;
constexpr PetscReal kMaxGrowth = 2.0;
// Error constants of the estimates: backward Euler's local position error
// h^2 x'' / 2; the second-order schemes' h^3 x^(3) / 6 (Newmark's constant is
// 1/12, BDF2's 2/9).
constexpr PetscReal kFirstOrderErrorConstant = 0.5;
constexpr PetscReal kSecondOrderErrorConstant = 1.0 / 6.0;
// A substep rejected this often in a row stops the run (the error estimate
// does not fall with the size: not a smooth motion).
constexpr int kMaxRejections = 30;
// Substep sizes are the step's halvings dt / 2^k, k <= kLadderLevels (a
// substep of dt / 2^60 is far below any the error control asks for: the
// rejections stop the run first); elapsed time is counted exactly in units of
// the smallest.
constexpr int kLadderLevels = 60;
constexpr uint64_t kLadderUnits = uint64_t(1) << kLadderLevels;

}  // namespace

const char *const kElasticityModes[] = {"linear", "corotational", "ElasticityMode", "MODE_",
                                        nullptr};

namespace {

// "t1:dt1,t2:dt2,..." (s) into schedule: times >= 0 and increasing, steps > 0.
PetscErrorCode ParseTimeStepSchedule(MPI_Comm comm, std::string_view text,
                                     std::vector<std::pair<PetscReal, PetscReal>> *schedule) {
  PetscFunctionBeginUser;
  schedule->clear();
  for (std::string_view rest = text; !rest.empty();) {
    const size_t comma = rest.find(',');
    const std::string_view item = rest.substr(0, comma);
    const size_t colon = item.find(':');
    std::pair<PetscReal, PetscReal> entry;
    PetscCheck(
        colon != std::string_view::npos && ParseNumber(item.substr(0, colon), &entry.first) &&
            ParseNumber(item.substr(colon + 1), &entry.second) && std::isfinite(entry.first) &&
            std::isfinite(entry.second) && entry.first >= 0 && entry.second > 0,
        comm, PETSC_ERR_USER_INPUT,
        "option -dt_schedule: '%s' is not time:dt with time >= 0 and dt > 0 (s)",
        std::string(item).c_str());
    PetscCheck(schedule->empty() || entry.first > schedule->back().first, comm,
               PETSC_ERR_USER_INPUT, "option -dt_schedule: times must increase");
    schedule->push_back(entry);
    if (comma == std::string_view::npos) break;
    rest.remove_prefix(comma + 1);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CheckIntegratorOptions(MPI_Comm comm, const IntegratorOptions &o) {
  PetscFunctionBeginUser;
  PetscCheck(o.dt > 0, comm, PETSC_ERR_USER_INPUT, "option -dt: must be > 0 (got %g)",
             (double)o.dt);
  PetscCheck(o.steps >= 0, comm, PETSC_ERR_USER_INPUT,
             "option -steps: must be >= 0 (got %" PetscInt_FMT ")", o.steps);
  PetscCheck(o.alpha >= 0, comm, PETSC_ERR_USER_INPUT, "option -alpha: must be >= 0 (got %g)",
             (double)o.alpha);
  PetscCheck(o.beta >= 0, comm, PETSC_ERR_USER_INPUT, "option -beta: must be >= 0 (got %g)",
             (double)o.beta);
  PetscCheck(o.newton_rtol > 0, comm, PETSC_ERR_USER_INPUT,
             "option -newton_rtol: must be > 0 (got %g)", (double)o.newton_rtol);
  PetscCheck(o.newton_max_it >= 1, comm, PETSC_ERR_USER_INPUT,
             "option -newton_max_it: must be >= 1 (got %" PetscInt_FMT ")", o.newton_max_it);
  PetscCheck(o.factor_cache >= 1, comm, PETSC_ERR_USER_INPUT,
             "option -dt_adapt_factors: must be >= 1 (got %" PetscInt_FMT ")", o.factor_cache);
  PetscCheck(o.horizon >= 0, comm, PETSC_ERR_USER_INPUT,
             "option -dt_adapt_horizon: must be >= 0 (got %g)", (double)o.horizon);
  PetscCheck(o.tolerance > 0 && o.tolerance < 1, comm, PETSC_ERR_USER_INPUT,
             "option -tol: must be in (0, 1) (got %g)", (double)o.tolerance);
  PetscCheck(o.rho_inf >= 0 && o.rho_inf <= 1, comm, PETSC_ERR_USER_INPUT,
             "option -alpha_rho_inf: must be in [0, 1] (got %g)", (double)o.rho_inf);
  PetscCheck(o.shear_scale > 0, comm, PETSC_ERR_USER_INPUT,
             "option -shear_scale: must be > 0 (got %g)", (double)o.shear_scale);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Inside ProcessIntegratorOptions' PetscOptionsBegin/End: the corotational
// iteration and the direct fallback.
PetscErrorCode ReadSolveOptions(PetscOptionItems *PetscOptionsObject, IntegratorOptions *o) {
  PetscFunctionBeginUser;
  PetscCall(PetscOptionsReal("-newton_rtol",
                             "Corotational mode: a step is done when its residual |g| is below "
                             "this times |M v0| + dt |f_el(x0)| + dt |f_ext| (integrator.hpp)",
                             nullptr, o->newton_rtol, &o->newton_rtol, nullptr));
  PetscCall(PetscOptionsBool("-newton_always",
                             "Corotational mode: iterate every step to -newton_rtol (default: only "
                             "steps whose single linearised solve would gain energy)",
                             nullptr, o->newton_always, &o->newton_always, nullptr));
  PetscCall(PetscOptionsInt("-newton_max_it",
                            "Corotational mode: most linearised solves per step (1: the single "
                            "linearised step, no check)",
                            nullptr, o->newton_max_it, &o->newton_max_it, nullptr));
  PetscCall(
      PetscOptionsBool("-fallback_direct",
                       "Repeat a solve that breaks down (factor or preconditioner not positive "
                       "definite, NaN) by a distributed direct factorisation, SuperLU_dist LU "
                       "(its options take the prefix -fallback_)",
                       nullptr, o->fallback_direct, &o->fallback_direct, nullptr));
  PetscCall(PetscOptionsBool(
      "-constraint_correction",
      "Linear mode with a factorisation: contact solves keep columns of A^-1 (3 back-solves per "
      "newly constrained vertex): the projected CG's preconditioner gets the constraints' Schur "
      "complement (one CG iteration), the two-sided solve needs no back-solve per row",
      nullptr, o->constraint_correction, &o->constraint_correction, nullptr));
  PetscCall(PetscOptionsEnum(
      "-contact_solve",
      "How contact solves treat free bodies' two-sided rows: auto (by their count and the "
      "solver), delassus (the dense m x m problem), projected, augmented (augmented Lagrangian: "
      "a few projected solves; docs/contact.md)",
      nullptr, kTwoSidedPaths, (PetscEnum)o->two_sided_path, (PetscEnum *)&o->two_sided_path,
      nullptr));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode ProcessIntegratorOptions(MPI_Comm comm, IntegratorOptions *o) {
  PetscFunctionBeginUser;
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kChoice, "-mode", kElasticityModes},
                                     {OptionSyntax::kChoice, "-integrator", kTimeSchemes},
                                     {OptionSyntax::kReal, "-alpha_rho_inf"},
                                     {OptionSyntax::kBool, "-dt_adapt"},
                                     {OptionSyntax::kReal, "-tol"},
                                     {OptionSyntax::kReal, "-dt"},
                                     {OptionSyntax::kRealList, "-gravity"},
                                     {OptionSyntax::kInteger, "-steps"},
                                     {OptionSyntax::kReal, "-alpha"},
                                     {OptionSyntax::kReal, "-beta"},
                                     {OptionSyntax::kReal, "-shear_scale"},
                                     {OptionSyntax::kReal, "-newton_rtol"},
                                     {OptionSyntax::kInteger, "-newton_max_it"},
                                     {OptionSyntax::kBool, "-newton_always"},
                                     {OptionSyntax::kBool, "-fallback_direct"},
                                     {OptionSyntax::kBool, "-constraint_correction"},
                                     {OptionSyntax::kChoice, "-contact_solve", kTwoSidedPaths}}));
  char schedule[PETSC_MAX_PATH_LEN] = "";
  PetscReal gravity[3] = {o->gravity[0], o->gravity[1], o->gravity[2]};
  PetscInt gravity_count = 3;
  PetscBool gravity_set = PETSC_FALSE;
  PetscOptionsBegin(comm, nullptr, "Time integration", nullptr);
  PetscCall(PetscOptionsEnum("-mode",
                             "Elasticity: linear (K factorised once) or corotational (per-tet "
                             "rotations, K rebuilt and solved every step)",
                             nullptr, kElasticityModes, (PetscEnum)o->mode, (PetscEnum *)&o->mode,
                             nullptr));
  PetscCall(PetscOptionsEnum("-integrator",
                             "Time integration scheme: be (backward Euler, first order), bdf2, "
                             "newmark (beta 1/4, gamma 1/2: energy-conserving), alpha "
                             "(generalized-alpha); all but be are second order "
                             "(docs/integrators.md)",
                             nullptr, kTimeSchemes, (PetscEnum)o->scheme, (PetscEnum *)&o->scheme,
                             nullptr));
  PetscCall(
      PetscOptionsReal("-alpha_rho_inf",
                       "-integrator alpha: spectral radius at dt*omega -> infinity, in [0, 1] "
                       "(1: no numerical dissipation, 0: the most)",
                       nullptr, o->rho_inf, &o->rho_inf, nullptr));
  PetscCall(PetscOptionsReal("-dt", "Time step (s)", nullptr, o->dt, &o->dt, nullptr));
  PetscCall(PetscOptionsBool("-dt_adapt",
                             "Take each time step in substeps sized by a local error estimate "
                             "(-tol); frames stay at the steps' times (docs/integrators.md)",
                             nullptr, o->adaptive, &o->adaptive, nullptr));
  PetscCall(
      PetscOptionsReal("-tol",
                       "-dt_adapt: about the relative error of x - X at the run's end "
                       "(linear mode, bdf2, newmark, alpha: each substep's estimate, filtered "
                       "by the damping, per unit time times the run's length -steps x -dt); "
                       "be and corotational mode: the relative error per substep, over "
                       "|x - X| + dt max(|v0|, |v1|) (docs/integrators.md)",
                       nullptr, o->tolerance, &o->tolerance, nullptr));
  PetscCall(
      PetscOptionsInt("-dt_adapt_factors",
                      "-dt_adapt, linear mode: factorisations of A kept for the substep "
                      "sizes used last, so that a size used again costs no refactorisation "
                      "(each holds a factor of A: mind the memory on big meshes; 1: none kept)",
                      nullptr, o->factor_cache, &o->factor_cache, nullptr));
  PetscCall(PetscOptionsReal("-dt_adapt_horizon",
                             "-dt_adapt, linear mode: the time (s) at whose end -tol bounds the "
                             "error; the damping filter of the estimate looks as far (0: the run's "
                             "length -steps x -dt; give it to continue a run with more -steps bit "
                             "for bit)",
                             nullptr, o->horizon, &o->horizon, nullptr));
  PetscCall(
      PetscOptionsString("-dt_schedule",
                         "Change the time step during the run: t1:dt1,t2:dt2 (s) means dt1 from "
                         "time t1 on, then dt2 from t2 on; A is refactorised once per change",
                         nullptr, schedule, schedule, sizeof(schedule), nullptr));
  PetscCall(PetscOptionsRealArray("-gravity", "Gravitational acceleration gx,gy,gz (m/s^2)",
                                  nullptr, gravity, &gravity_count, &gravity_set));
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
  PetscCall(ReadSolveOptions(PetscOptionsObject, o));
  PetscOptionsEnd();
  if (gravity_set) {
    PetscCheck(gravity_count == 3, comm, PETSC_ERR_USER_INPUT,
               "option -gravity: expected gx,gy,gz");
    o->gravity = Eigen::Vector3d(gravity[0], gravity[1], gravity[2]);
  }
  PetscCall(ParseTimeStepSchedule(comm, schedule, &o->dt_schedule));
  PetscCall(CheckIntegratorOptions(comm, *o));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscReal TimeStepAt(const IntegratorOptions &options, PetscReal time) {
  PetscReal dt = options.dt;
  // An entry applies from its time on, up to round-off in the accumulated time.
  for (const auto &[from, step] : options.dt_schedule)
    if (time >= from - kScheduleTimeTolerance * step) dt = step;
  return dt;
}

ImplicitEuler::~ImplicitEuler() {
  VecDestroy(&saved_x_);
  VecDestroy(&saved_v_);
  VecDestroy(&saved_previous_x_);
  VecDestroy(&saved_previous_v_);
  VecDestroy(&saved_acceleration_);
  VecDestroy(&step_x_);
  VecDestroy(&step_v_);
  VecDestroy(&previous_x_);
  VecDestroy(&previous_v_);
  VecDestroy(&acceleration_);
  VecDestroy(&end_acceleration_);
  VecDestroy(&combined_position_);
  VecDestroy(&combined_velocity_);
  VecDestroy(&gravity_force_);
  VecDestroy(&x_start_);
  VecDestroy(&motion_start_);
  VecDestroy(&end_base_);
  VecDestroy(&v_start_);
  VecDestroy(&iterate_);
  VecDestroy(&direction_);
  VecDestroy(&work_);
  VecDestroy(&v_trial_base_);
  VecDestroy(&damping_force_);
  if (!systems_.empty()) A_ = nullptr, ksp_ = nullptr;  // owned by the cache's entries
  for (CachedSystem &entry : systems_) {
    KSPDestroy(&entry.solver);
    MatDestroy(&entry.matrix);
  }
  KSPDestroy(&ksp_);
  KSPDestroy(&fallback_ksp_);
  KSPDestroy(&filter_ksp_);
  MatDestroy(&filter_matrix_);
  VecDestroy(&filter_work_);
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

PetscErrorCode ImplicitEuler::CreateGravityForce() {
  PetscFunctionBeginUser;
  PetscCall(VecDuplicate(rest_, &gravity_force_));
  PetscCall(VecCopy(mass_, gravity_force_));
  PetscScalar *f;
  PetscInt n;
  PetscCall(VecGetLocalSize(gravity_force_, &n));
  PetscCall(VecGetArray(gravity_force_, &f));
  for (PetscInt i = 0; i < n; ++i) f[i] *= options_.gravity[i % 3];
  PetscCall(VecRestoreArray(gravity_force_, &f));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::CreateMatrices(MPI_Comm comm, const Scene &scene,
                                             const DofLayout &layout, LocalTets &&tets) {
  PetscFunctionBeginUser;
  PetscCall(assembler_.Setup(comm, scene, layout, std::move(tets), options_.shear_scale, rest_));
  // A: the plain product for CG's many products with it. K (linear mode) is
  // used only in products (one per step), so it is stored as 3 x 3 blocks
  // (MATBAIJ: one column index per block, 0.7 of AIJ's bytes; 1.2 ms against
  // 2.2 ms per product on the 103 355-tet TetGen rung, AMD EPYC). Its sums
  // run in another order than AIJ's, so results moved at round-off (4e-16 m).
  // Copied by CopyToBlockMatrix, not MatConvert (block_matrix.hpp: why), and
  // moved onto huge pages (matrix_pages.hpp): 0.95-1.08 -> 0.86-0.90 ms per
  // product there. (A's CG products in corotational mode did not gain.)
  PetscCall(assembler_.CreateMatrix(&A_, options_.mode == MODE_COROTATIONAL
                                             ? RowAssembler::Products::kPlainCsr
                                             : RowAssembler::Products::kInode));
  if (options_.mode == MODE_LINEAR) {
    StageScope stage(Stages().assembly);
    PetscCall(assembler_.CreateMatrix(&K_));
    PetscCall(assembler_.Fill(K_, RowAssembler::FillTerms().Stiffness(1.0)));
    Mat blocks;
    PetscCall(CopyToBlockMatrix(K_, &blocks));
    PetscCall(MatDestroy(&K_));
    K_ = blocks;
    PetscCall(UseBlockProducts(K_));
    PetscCall(MoveMatrixToHugePages(K_));
    PetscCall(VecDuplicate(rest_, &displacement_));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::CreateTouchedScatter(const LocalElements &elements) {
  PetscFunctionBeginUser;
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
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::CreateLinearSolver(const DofLayout &layout) {
  PetscFunctionBeginUser;
  PetscCall(
      ApplyPresetDefaults(options_.mode == MODE_LINEAR ? kDirectPreset : kCorotationalPreset));
  SolverChoice choice;
  PetscCall(CreateSolver(A_, rest_, &ksp_, &choice));
  stats_.choice = choice.reason;
  PC pc;
  PetscCall(KSPGetPC(ksp_, &pc));
  PetscBool gamg;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCGAMG, &gamg));
  gamg_ = gamg;
  PetscBool warp;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCWarp, &warp));
  warp_ = warp;
  if (warp && options_.mode == MODE_COROTATIONAL) {
    // The warp preconditioner: A0 = the linear system, factorised per time step size.
    PetscCall(MatDuplicate(A_, MAT_DO_NOT_COPY_VALUES, &A_linear_));
    MatNullSpace rigid_body_modes;  // for an inner GAMG
    PetscCall(MatGetNearNullSpace(A_, &rigid_body_modes));
    PetscCall(MatSetNearNullSpace(A_linear_, rigid_body_modes));
    PetscCall(MatSetOption(A_linear_, MAT_SPD, PETSC_TRUE));
    PetscCall(MatSetOption(A_linear_, MAT_SPD_ETERNAL, PETSC_TRUE));
    PetscCall(PCWarpSetLinearOperator(pc, A_linear_));
    assembler_.ComputeVertexRotations(true);
  } else if (warp) {  // linear mode: A itself, no rotations (a direct solve in one iteration)
    PetscCall(PCWarpSetLinearOperator(pc, A_));
    std::vector<double> identity(9 * layout.local_count(), 0.0);
    for (PetscInt v = 0; v < layout.local_count(); ++v)
      identity[9 * v] = identity[9 * v + 4] = identity[9 * v + 8] = 1.0;
    PetscCall(PCWarpSetRotations(pc, layout.local_count(), identity.data()));
  }
  // Linear mode with a factorisation of A (KSPPREONLY): the constrained solves'
  // preconditioner gets the constraint correction, whose columns of A^-1 then
  // serve the whole run (A changes only with the time step).
  KSPType type;
  PetscCall(KSPGetType(ksp_, &type));
  PetscBool preonly;
  PetscCall(PetscStrcmp(type, KSPPREONLY, &preonly));
  projected_.set_constraint_correction(options_.mode == MODE_LINEAR && preonly &&
                                       options_.constraint_correction);
  projected_.set_two_sided_path(options_.two_sided_path);
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                                    LocalTets &&tets, const LocalElements &elements,
                                    Vec rest_positions, Vec lumped_mass,
                                    const IntegratorOptions &options) {
  PetscFunctionBeginUser;
  elements_ = &elements;
  options_ = options;
  rest_ = rest_positions;
  mass_ = lumped_mass;
  PetscCall(VecDuplicate(rest_, &elastic_force_));
  PetscCall(VecDuplicate(rest_, &rhs_));
  if (options.gravity.squaredNorm() > 0) PetscCall(CreateGravityForce());  // f_ext = M g
  PetscCall(CreateMatrices(comm, scene, layout, std::move(tets)));
  // Owned and ghost positions of every vertex the local elements touch
  // (element-wise energies in linear mode).
  PetscCall(CreateTouchedScatter(elements));
  PetscCall(CreateLinearSolver(layout));
  PetscCall(SetTimeStep(options.dt));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::SetBodies(std::vector<int32_t> owned_body, int num_bodies) {
  PetscFunctionBeginUser;
  if (options_.mode != MODE_LINEAR) PetscFunctionReturn(PETSC_SUCCESS);
  owned_body_ = std::move(owned_body);
  const MPI_Comm comm = PetscObjectComm((PetscObject)rest_);
  const PetscScalar *X, *m;
  PetscCall(VecGetArrayRead(rest_, &X));
  PetscCall(VecGetArrayRead(mass_, &m));
  // Mass and first moments, then second moments about the centres.
  std::vector<double> sums(4 * num_bodies, 0.0), second(9 * num_bodies, 0.0);
  for (size_t i = 0; i < owned_body_.size(); ++i) {
    double *sum = &sums[4 * owned_body_[i]];
    sum[0] += m[3 * i];
    for (int c = 0; c < 3; ++c) sum[1 + c] += m[3 * i] * X[3 * i + c];
  }
  PetscCall(MPIU_Allreduce(MPI_IN_PLACE, sums.data(), 4 * num_bodies, MPI_DOUBLE, MPI_SUM, comm));
  rigid_.assign(num_bodies, RigidBody());
  for (int b = 0; b < num_bodies; ++b) {
    rigid_[b].mass = sums[4 * b];
    if (rigid_[b].mass > 0) rigid_[b].centre = Eigen::Vector3d(&sums[4 * b + 1]) / rigid_[b].mass;
  }
  for (size_t i = 0; i < owned_body_.size(); ++i) {
    const int b = owned_body_[i];
    const Eigen::Vector3d r = Eigen::Vector3d(&X[3 * i]) - rigid_[b].centre;
    Eigen::Map<Eigen::Matrix3d> inertia(&second[9 * b]);
    inertia += m[3 * i] * (r.squaredNorm() * Eigen::Matrix3d::Identity() - r * r.transpose());
  }
  PetscCall(VecRestoreArrayRead(rest_, &X));
  PetscCall(VecRestoreArrayRead(mass_, &m));
  PetscCall(MPIU_Allreduce(MPI_IN_PLACE, second.data(), 9 * num_bodies, MPI_DOUBLE, MPI_SUM, comm));
  for (int b = 0; b < num_bodies; ++b)
    if (rigid_[b].mass > 0)
      rigid_[b].inverse_inertia = Eigen::Map<Eigen::Matrix3d>(&second[9 * b]).inverse();
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::BodyMomenta(Vec w, bool with_force,
                                          std::vector<Eigen::Vector3d> *momenta) {
  PetscFunctionBeginUser;
  const PetscScalar *X, *m, *v, *f = nullptr;
  PetscCall(VecGetArrayRead(rest_, &X));
  PetscCall(VecGetArrayRead(mass_, &m));
  PetscCall(VecGetArrayRead(w, &v));
  if (with_force && gravity_force_) PetscCall(VecGetArrayRead(gravity_force_, &f));
  momenta->assign(2 * rigid_.size(), Eigen::Vector3d::Zero());  // per body: p, L
  // Summed in registers over each run of vertices of one body (usually all of
  // them), in vertex order as into the body's entries: the same sums, without
  // a dependency through memory from one vertex to the next.
  for (size_t i = 0; i < owned_body_.size();) {
    const int b = owned_body_[i];
    const Eigen::Vector3d centre = rigid_[b].centre;
    Eigen::Vector3d linear = (*momenta)[2 * b], angular = (*momenta)[2 * b + 1];
    for (; i < owned_body_.size() && owned_body_[i] == b; ++i) {
      Eigen::Vector3d p = Eigen::Vector3d(m[3 * i] * v[3 * i], m[3 * i + 1] * v[3 * i + 1],
                                          m[3 * i + 2] * v[3 * i + 2]);
      if (f) p += step_.force_step * Eigen::Vector3d(&f[3 * i]);
      linear += p;
      angular += (Eigen::Vector3d(&X[3 * i]) - centre).cross(p);
    }
    (*momenta)[2 * b] = linear;
    (*momenta)[2 * b + 1] = angular;
  }
  PetscCall(VecRestoreArrayRead(rest_, &X));
  PetscCall(VecRestoreArrayRead(mass_, &m));
  PetscCall(VecRestoreArrayRead(w, &v));
  if (f) PetscCall(VecRestoreArrayRead(gravity_force_, &f));
  PetscCall(MPIU_Allreduce(MPI_IN_PLACE, momenta->data(), 6 * static_cast<int>(rigid_.size()),
                           MPI_DOUBLE, MPI_SUM, PetscObjectComm((PetscObject)w)));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::SetTimeStep(PetscReal dt) {
  PetscFunctionBeginUser;
  if (interval_ > 0) ++stats_.time_step_changes;
  interval_ = dt;
  if (options_.adaptive && (target_step_ <= 0 || target_step_ > dt)) target_step_ = dt;
  dt_ = options_.adaptive ? target_step_ : dt;
  PetscCall(PrepareStep());
  if (options_.adaptive) PetscCall(SetDampingFilter());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Linear mode, b > 0: B = (1 + a T) M + b T K, T the run's length: B^-1 M
// keeps a mode of frequency w by 1 / (1 + a T + b T w^2), about what its
// damping leaves of it at the run's end (exactly so for T w^2 b << 1), so an
// error in a mode that damps out before the end does not count (the strike of
// the default scene: its stiff modes' errors vanish by T, resolving them cost
// substeps down to 1e-5 s). Undamped modes pass unfiltered.
PetscErrorCode ImplicitEuler::SetDampingFilter() {
  PetscFunctionBeginUser;
  const PetscReal a = options_.alpha, b = options_.beta, horizon = RunLength();
  if (options_.mode != MODE_LINEAR || b <= 0 || horizon == filter_horizon_)
    PetscFunctionReturn(PETSC_SUCCESS);
  filter_horizon_ = horizon;
  if (!filter_matrix_) {
    PetscCall(assembler_.CreateMatrix(&filter_matrix_));
    PetscCall(VecDuplicate(rest_, &filter_work_));
  }
  {
    StageScope stage(Stages().assembly);
    PetscCall(assembler_.Fill(
        filter_matrix_,
        RowAssembler::FillTerms().Stiffness(b * horizon).Mass(mass_, 1.0 + a * horizon)));
  }
  StageScope stage(Stages().factorisation);
  if (!filter_ksp_) {
    SolverChoice choice;
    PetscCall(CreateSolver(filter_matrix_, rest_, &filter_ksp_, &choice));
  }
  PetscCall(KSPSetOperators(filter_ksp_, filter_matrix_, filter_matrix_));
  PetscCall(KSPSetUp(filter_ksp_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::PrepareStep() {
  PetscFunctionBeginUser;
  step_ = SchemeStep(options_.scheme, dt_, previous_dt_, options_.rho_inf,
                     options_.mode == MODE_LINEAR);
  if (step_.force_step != system_force_step_ || step_.position_step != system_position_step_)
    PetscCall(FillSystem(step_.force_step, step_.position_step));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// A = (1 + a h_f) M + (b h_f + h_f h_x) K: linear mode fills and factorises it;
// corotational mode refills it at the next element pass (and the warp
// preconditioner's linear system now).
PetscErrorCode ImplicitEuler::FillSystem(PetscReal hf, PetscReal hx) {
  PetscFunctionBeginUser;
  system_force_step_ = hf;
  system_position_step_ = hx;
  const PetscReal a = options_.alpha, b = options_.beta;
  if (options_.mode == MODE_COROTATIONAL) {
    elastic_state_current_ = false;  // A depends on dt: refilled at the next step
    if (A_linear_) {
      StageScope stage(Stages().assembly);
      PetscCall(assembler_.Fill(
          A_linear_,
          RowAssembler::FillTerms().Stiffness(b * hf + hf * hx).Mass(mass_, 1.0 + a * hf)));
    }
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  bool cached = false;
  PetscCall(SelectCachedSystem(hf, hx, &cached));
  if (cached) PetscFunctionReturn(PETSC_SUCCESS);
  PetscLogDouble start, end;
  {
    StageScope stage(Stages().assembly);
    PetscCall(PetscTime(&start));
    PetscCall(assembler_.Fill(
        A_, RowAssembler::FillTerms().Stiffness(b * hf + hf * hx).Mass(mass_, 1.0 + a * hf)));
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

PetscErrorCode ImplicitEuler::SelectCachedSystem(PetscReal hf, PetscReal hx, bool *cached) {
  PetscFunctionBeginUser;
  *cached = false;
  if (!options_.adaptive || options_.factor_cache <= 0 || options_.mode != MODE_LINEAR || warp_)
    PetscFunctionReturn(PETSC_SUCCESS);
  ++cache_clock_;
  if (systems_.empty()) {  // the set-up's A and solver become the first entry (owned by it)
    systems_.push_back({hf, hx, A_, ksp_, cache_clock_});
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  CachedSystem *chosen = nullptr;
  for (CachedSystem &entry : systems_)
    if (entry.force_step == hf && entry.position_step == hx) chosen = &entry;
  if (chosen) {
    *cached = true;
  } else if (static_cast<PetscInt>(systems_.size()) < options_.factor_cache) {
    CachedSystem entry{hf, hx, nullptr, nullptr, 0};
    PetscCall(MatDuplicate(A_, MAT_DO_NOT_COPY_VALUES, &entry.matrix));
    SolverChoice choice;
    PetscCall(CreateSolver(entry.matrix, rest_, &entry.solver, &choice));
    systems_.push_back(entry);
    chosen = &systems_.back();
  } else {  // the least recently used entry is refilled
    chosen = &systems_.front();
    for (CachedSystem &entry : systems_)
      if (entry.last_use < chosen->last_use) chosen = &entry;
    chosen->force_step = hf;
    chosen->position_step = hx;
  }
  chosen->last_use = cache_clock_;
  A_ = chosen->matrix;
  ksp_ = chosen->solver;
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// c is the single vector `which` with coefficient 1.
bool IsUnit(const Combination &c, StepVector which) {
  for (int i = 0; i < kStepVectors; ++i)
    if (c[i] != (i == which ? 1.0 : 0.0)) return false;
  return true;
}

}  // namespace

PetscErrorCode ImplicitEuler::CreateHistoryVectors() {
  PetscFunctionBeginUser;
  if (step_x_) PetscFunctionReturn(PETSC_SUCCESS);
  for (Vec *vector : {&step_x_, &step_v_, &previous_x_, &previous_v_, &acceleration_,
                      &end_acceleration_, &combined_position_, &combined_velocity_}) {
    PetscCall(VecDuplicate(rest_, vector));
    PetscCall(VecZeroEntries(*vector));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::Combine(const Combination &c, Vec x, Vec v, Vec result) {
  PetscFunctionBeginUser;
  const Vec vectors[kStepVectors] = {step_x_,       previous_x_, step_v_, previous_v_,
                                     acceleration_, v,           x};
  PetscCall(VecZeroEntries(result));
  for (int i = 0; i < kStepVectors; ++i)
    if (c[i] != 0) PetscCall(VecAXPY(result, c[i], vectors[i]));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::InitialAcceleration(Vec x, Vec v) {
  PetscFunctionBeginUser;
  // a = (f_ext - f_el(x) - b K v) / M - a v
  const PetscReal b = options_.beta;
  Vec stiffness_damping = combined_velocity_;  // b K v
  if (options_.mode == MODE_LINEAR) {
    PetscCall(VecWAXPY(displacement_, -1.0, rest_, x));
    PetscCall(VecAXPY(displacement_, b, v));
    PetscCall(MatMult(K_, displacement_, acceleration_));  // f_el + b K v
    PetscCall(VecZeroEntries(stiffness_damping));
  } else {
    PetscCall(UpdateElasticState(x));  // f_el(x) and A = (1 + a h_f) M + (b h_f + h_f h_x) K(R)
    PetscCall(VecCopy(elastic_force_, acceleration_));
    const PetscReal hf = system_force_step_, hx = system_position_step_;
    // K(R) v from A v - (1 + a h_f) M v.
    PetscCall(VecZeroEntries(stiffness_damping));
    if (b > 0) {
      PetscCall(MatMult(A_, v, stiffness_damping));
      PetscCall(VecPointwiseMult(combined_position_, mass_, v));
      PetscCall(VecAXPY(stiffness_damping, -(1.0 + options_.alpha * hf), combined_position_));
      PetscCall(VecScale(stiffness_damping, b / (b * hf + hf * hx)));
    }
  }
  PetscCall(VecAXPY(acceleration_, 1.0, stiffness_damping));
  PetscCall(VecScale(acceleration_, -1.0));
  if (gravity_force_) PetscCall(VecAXPY(acceleration_, 1.0, gravity_force_));
  PetscCall(VecPointwiseDivide(acceleration_, acceleration_, mass_));
  PetscCall(VecAXPY(acceleration_, -options_.alpha, v));
  acceleration_valid_ = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::BeginSchemeStep(Vec x, Vec v) {
  PetscFunctionBeginUser;
  if (options_.scheme == SCHEME_BE) PetscFunctionReturn(PETSC_SUCCESS);
  PetscCall(CreateHistoryVectors());
  PetscCall(VecCopy(x, step_x_));
  PetscCall(VecCopy(v, step_v_));
  if (step_.uses_acceleration && !acceleration_valid_) PetscCall(InitialAcceleration(x, v));
  if (!IsUnit(step_.base_position, kXn)) {
    PetscCall(Combine(step_.base_position, x, v, combined_position_));
    PetscCall(VecCopy(combined_position_, x));
    elastic_state_current_ = false;
  }
  if (!IsUnit(step_.base_velocity, kVn)) {
    PetscCall(Combine(step_.base_velocity, x, v, combined_velocity_));
    PetscCall(VecCopy(combined_velocity_, v));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::FinishSchemeStep(Vec x, Vec v) {
  PetscFunctionBeginUser;
  if (options_.scheme == SCHEME_BE) PetscFunctionReturn(PETSC_SUCCESS);
  // a1, x1 and v1, all from the solved x, u and the state at the step's start.
  if (step_.gives_acceleration) PetscCall(Combine(step_.end_acceleration, x, v, end_acceleration_));
  const bool new_position = !IsUnit(step_.end_position, kXsolved);
  if (new_position) PetscCall(Combine(step_.end_position, x, v, combined_position_));
  if (!IsUnit(step_.end_velocity, kU)) {
    PetscCall(Combine(step_.end_velocity, x, v, combined_velocity_));
    PetscCall(VecCopy(combined_velocity_, v));
  }
  if (new_position) {
    PetscCall(VecCopy(combined_position_, x));
    elastic_state_current_ = false;
  }
  // The history of the next step: x_{n-1}, v_{n-1} = this step's x_n, v_n; a_n = a1.
  std::swap(previous_x_, step_x_);
  std::swap(previous_v_, step_v_);
  if (step_.gives_acceleration) std::swap(acceleration_, end_acceleration_);
  acceleration_valid_ = step_.gives_acceleration;
  previous_dt_ = dt_;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::GetHistory(SchemeHistory *history) {
  PetscFunctionBeginUser;
  history->scheme = kTimeSchemes[options_.scheme];
  history->vectors.clear();
  history->scalars = {previous_dt_, acceleration_valid_ ? 1.0 : 0.0, target_step_};
  if (options_.scheme == SCHEME_BE) PetscFunctionReturn(PETSC_SUCCESS);
  PetscCall(CreateHistoryVectors());
  // -dt_adapt's estimate needs the previous velocities with every scheme but be.
  if (options_.scheme == SCHEME_BDF2)
    history->vectors = {{"previous_positions", previous_x_}, {"previous_velocities", previous_v_}};
  else if (options_.adaptive)
    history->vectors = {{"previous_velocities", previous_v_}};
  if (options_.scheme == SCHEME_ALPHA) history->vectors.push_back({"accelerations", acceleration_});
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::SetHistory(const std::vector<double> &scalars, bool found) {
  PetscFunctionBeginUser;
  const bool usable = found && scalars.size() >= 2;
  first_substep_ = false;  // a checkpoint follows at least one step
  previous_dt_ = usable ? scalars[0] : 0;
  acceleration_valid_ = usable && scalars[1] != 0;
  if (options_.adaptive && usable && scalars.size() >= 3 && scalars[2] > 0) {
    target_step_ = scalars[2];
    dt_ = PetscMin(target_step_, interval_);
  }
  PetscCall(PrepareStep());
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
    const PetscReal hf = system_force_step_, hx = system_position_step_;
    PetscLogDouble start, end;
    PetscCall(PetscTime(&start));
    // Stiffness damping (b > 0): the corotated displacement gradients, and within
    // a step the force and energy of their increments since its start.
    if (b > 0 && !damping_force_) PetscCall(VecDuplicate(elastic_force_, &damping_force_));
    RowAssembler::IncrementDamping damping{&corotated_, step_started_ ? &corotated_start_ : nullptr,
                                           damping_force_};
    PetscCall(assembler_.Fill(A_, RowAssembler::FillTerms()
                                      .Stiffness(b * hf + hf * hx)
                                      .Mass(mass_, 1.0 + a * hf)
                                      .CorotatedAt(x)
                                      .ElasticForce(elastic_force_)
                                      .StrainEnergy(&elastic_energy_)
                                      .Damping(b > 0 ? &damping : nullptr)));
    if (step_started_) damping_energy_ = damping.energy;
    PetscCall(PetscTime(&end));
    stats_.assemble_seconds = end - start;
    ++stats_.assemblies;
    if (gamg_) PetscCall(UpdateNearNullSpace(x));
    if (A_linear_) {
      PC pc;
      PetscCall(KSPGetPC(ksp_, &pc));
      const std::vector<double> &rotations = assembler_.vertex_rotations();
      PetscCall(
          PCWarpSetRotations(pc, static_cast<PetscInt>(rotations.size() / 9), rotations.data()));
    }
  }
  elastic_state_current_ = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::PrimeSolver(Vec x_first, PetscReal dt_first) {
  PetscFunctionBeginUser;
  if (options_.mode == MODE_LINEAR) PetscFunctionReturn(PETSC_SUCCESS);
  // A as the first step filled it (its scheme's coefficients without history),
  // then this run's step sizes again (A is refilled at the next element pass).
  const StepCoefficients first =
      SchemeStep(options_.scheme, dt_first, 0, options_.rho_inf, options_.mode == MODE_LINEAR);
  const PetscReal hf = system_force_step_, hx = system_position_step_;
  system_force_step_ = first.force_step;
  system_position_step_ = first.position_step;
  elastic_state_current_ = false;
  PetscCall(UpdateElasticState(x_first));
  PetscCall(KSPSetUp(ksp_));
  system_force_step_ = hf;
  system_position_step_ = hx;
  elastic_state_current_ = false;
  PetscFunctionReturn(PETSC_SUCCESS);
}

// A breakdown, as opposed to a solve that ran out of iterations: the factor or
// preconditioner is not positive definite, or NaN appeared (A numerically
// singular: a stiff, nearly incompressible sliver has a mass part below K's
// round-off).
// The fallback's SuperLU_dist settings, where -fallback_* sets none: the
// column order by ParMETIS (PT-Scotch's layer in this PETSc), and no
// equilibration: scaling rows and columns of a matrix whose mass part is below
// its stiffness's round-off lost the rigid-body modes (angular momentum kept
// to 4e-9 instead of 2e-15, tests/regression/test_fallback.py). Its
// parallel symbolic factorisation needs a PETSc built with ParMETIS itself.
static PetscErrorCode InsertFallbackDefaults() {
  PetscFunctionBeginUser;
  const char *const defaults[][2] = {{"-fallback_mat_superlu_dist_colperm", "PARMETIS"},
                                     {"-fallback_mat_superlu_dist_equil", "false"}};
  for (const auto &option : defaults) {
    PetscBool set;
    PetscCall(PetscOptionsHasName(nullptr, nullptr, option[0], &set));
    if (!set) PetscCall(PetscOptionsSetValue(nullptr, option[0], option[1]));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

static bool IsBreakdown(KSPConvergedReason reason) {
  return reason == KSP_DIVERGED_PC_FAILED || reason == KSP_DIVERGED_INDEFINITE_PC ||
         reason == KSP_DIVERGED_INDEFINITE_MAT || reason == KSP_DIVERGED_NANORINF ||
         reason == KSP_DIVERGED_BREAKDOWN || reason == KSP_DIVERGED_BREAKDOWN_BICG ||
         reason == KSP_DIVERGED_DTOL;
}

PetscErrorCode ImplicitEuler::SolveDirectly(Vec v, KSPConvergedReason failed,
                                            KSPConvergedReason *reason) {
  PetscFunctionBeginUser;
  if (!fallback_ksp_) {
    PetscCall(KSPCreate(PetscObjectComm((PetscObject)A_), &fallback_ksp_));
    PetscCall(KSPSetOptionsPrefix(fallback_ksp_, "fallback_"));
    PetscCall(KSPSetType(fallback_ksp_, KSPPREONLY));
    PC pc;
    PetscCall(KSPGetPC(fallback_ksp_, &pc));
    PetscCall(PCSetType(pc, PCLU));
    PetscCall(PCFactorSetMatSolverType(pc, MATSOLVERSUPERLU_DIST));
    PetscCall(InsertFallbackDefaults());
    PetscCall(KSPSetFromOptions(fallback_ksp_));
  }
  PetscCall(PetscInfo(ksp_,
                      "solve %" PetscInt_FMT " broke down (%s): repeated by the direct fallback\n",
                      stats_.solves + 1, KSPConvergedReasons[failed]));
  PetscCall(KSPSetOperators(fallback_ksp_, A_, A_));  // refactorises only when A changed
  PetscCall(KSPSolve(fallback_ksp_, rhs_, v));
  PetscCall(KSPGetConvergedReason(fallback_ksp_, reason));
  ++stats_.fallback_solves;
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
    PetscBool warp;
    PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCWarp, &warp));
    if (warp && stats_.choice.empty()) {
      SolverChoice inner;
      PetscCall(PCWarpGetInnerChoice(pc, &inner));
      if (inner.checked) stats_.choice = "warp around " + inner.reason;
    }
  }
  if (!contact || contact->global_constraint_count() == 0) {
    PetscCall(KSPSolve(ksp_, rhs_, v));
    PetscCall(KSPGetConvergedReason(ksp_, &reason));
    PetscCall(KSPGetIterationNumber(ksp_, &iterations));
    reactions_.clear();
    if (IsBreakdown(reason) && options_.fallback_direct)
      PetscCall(SolveDirectly(v, reason, &reason));
  } else {
    StageScope stage(Stages().contact);
    PetscCall(
        projected_.Solve(ksp_, rhs_, contact->velocity_constraints(), v, &reactions_, &iterations));
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

PetscErrorCode ImplicitEuler::CorrectRigidBodyVelocities(const std::vector<Eigen::Vector3d> &target,
                                                         const std::vector<Eigen::Vector3d> &solved,
                                                         Vec v) {
  PetscFunctionBeginUser;
  PetscScalar *w;
  const PetscScalar *X;
  PetscCall(VecGetArray(v, &w));
  PetscCall(VecGetArrayRead(rest_, &X));
  const double damping = 1.0 + options_.alpha * step_.force_step;
  // Per body: the translation dp / mass and the rotation I^-1 dL that correct it.
  std::vector<Eigen::Vector3d> translation(rigid_.size()), rotation(rigid_.size());
  for (size_t b = 0; b < rigid_.size(); ++b) {
    const Eigen::Vector3d dp = target[2 * b] / damping - solved[2 * b];
    const Eigen::Vector3d dL = target[2 * b + 1] / damping - solved[2 * b + 1];
    translation[b] =
        rigid_[b].mass > 0 ? Eigen::Vector3d(dp / rigid_[b].mass) : Eigen::Vector3d::Zero();
    rotation[b] = rigid_[b].inverse_inertia * dL;
  }
  for (size_t i = 0; i < owned_body_.size(); ++i) {
    const int b = owned_body_[i];
    const Eigen::Vector3d r = Eigen::Vector3d(&X[3 * i]) - rigid_[b].centre;
    Eigen::Map<Eigen::Vector3d>(&w[3 * i]) += translation[b] + rotation[b].cross(r);
  }
  PetscCall(VecRestoreArray(v, &w));
  PetscCall(VecRestoreArrayRead(rest_, &X));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::LinearStep(Vec x, Vec v) {
  PetscFunctionBeginUser;
  // A v1 = rhs; v holds v0, the initial guess of iterative solvers. Then each
  // body's rigid-body velocity from its momentum (SetBodies).
  std::vector<Eigen::Vector3d> target, solved;
  if (!rigid_.empty()) PetscCall(BodyMomenta(v, true, &target));
  PetscCall(Solve(v, nullptr));
  if (!rigid_.empty()) {
    PetscCall(BodyMomenta(v, false, &solved));
    PetscCall(CorrectRigidBodyVelocities(target, solved, v));
  }
  PetscCall(VecAXPY(x, step_.position_step, v));  // x1 = x0 + dt v1
  elastic_state_current_ = false;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::ContactStep(Vec x, Vec v, ContactSolver *contact) {
  PetscFunctionBeginUser;
  // The obstacles move with v0 meanwhile; constrain and solve again until the
  // step takes no further vertex inside an obstacle.
  StepMotion motion;
  PetscCall(ContactMotion(x, &motion));
  {
    StageScope stage(Stages().contact);
    PetscCall(contact->BeginStep(motion, v));
  }
  // Corotational mode, schemes other than backward Euler: while no constraint
  // holds, the step iterates as without contact (a single linearised solve
  // would make them first order).
  bool again = true;
  if (options_.mode == MODE_COROTATIONAL && !step_.identity &&
      contact->global_constraint_count() == 0)
    PetscCall(IterateBeforeContact(motion, x, v, contact, &again));
  // Sticking contacts that would need more than Coulomb's friction slip (their
  // friction impulse goes into rhs_) and the step is solved again.
  for (int round = 0; again && round < kMaxContactRounds; ++round) {
    PetscCall(Solve(v, contact));
    StageScope stage(Stages().contact);
    bool added, released = false;
    PetscCall(contact->AddPenetrations(motion, v, &added));
    if (!added) PetscCall(contact->ReleaseSlipping(reactions_, rhs_, &released));
    again = added || released;
  }
  if (again) PetscCall(Solve(v, contact));
  PetscCall(SolveWithGuardedVertices(motion, x, v, contact));
  PetscCall(FinishSchemeStep(x, v));  // the response acts on the scheme's x1, v1
  bool changed;
  {
    StageScope stage(Stages().contact);
    PetscCall(contact->EndStep(motion, x, v, reactions_, &changed));
  }
  contact_acted_ = changed || contact->global_constraint_count() > 0;
  elastic_state_current_ = false;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::ContactMotion(Vec x, StepMotion *motion) {
  PetscFunctionBeginUser;
  if (!x_start_) PetscCall(VecDuplicate(x, &x_start_));
  PetscCall(VecCopy(x, x_start_));
  if (step_.identity) {
    *motion = {x_start_, x_start_, step_.position_step, dt_, false};
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  if (!motion_start_) PetscCall(VecDuplicate(x, &motion_start_));
  if (!end_base_) PetscCall(VecDuplicate(x, &end_base_));
  PetscCall(VecCopy(step_x_, motion_start_));
  PetscCall(Combine(step_.end_base, x, x, end_base_));
  *motion = {motion_start_, end_base_, step_.end_step, dt_, true};
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::SolveWithGuardedVertices(const StepMotion &motion, Vec x, Vec v,
                                                       ContactSolver *contact) {
  PetscFunctionBeginUser;
  for (int round = 0;; ++round) {
    PetscCall(VecWAXPY(x, motion.h, v, motion.base));  // x1 = x_e + h_e u
    if (round == kMaxGuardSolves) break;
    bool held;
    {
      StageScope stage(Stages().contact);
      PetscCall(contact->HoldGuardedVertices(motion, x, reactions_, &held));
    }
    if (!held) break;
    PetscCall(Solve(v, contact));
    // A contact released above may let its vertex sink: constrained again.
    bool added;
    {
      StageScope stage(Stages().contact);
      PetscCall(contact->AddPenetrations(motion, v, &added));
    }
    if (added) PetscCall(Solve(v, contact));
    {
      StageScope stage(Stages().contact);
      PetscCall(contact->CancelHeldImpulse(reactions_, mass_, v));
    }
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::LinearisedRightHandSide(Vec x, Vec v) {
  PetscFunctionBeginUser;
  // rhs = M v0 - dt f_el(x0) + dt f_ext
  const PetscReal dt = step_.force_step;
  PetscCall(UpdateElasticState(x));
  PetscCall(VecPointwiseMult(rhs_, mass_, v));
  PetscCall(VecAXPY(rhs_, -dt, elastic_force_));
  if (gravity_force_) PetscCall(VecAXPY(rhs_, dt, gravity_force_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::IterateBeforeContact(const StepMotion &motion, Vec x, Vec v,
                                                   ContactSolver *contact, bool *constrain) {
  PetscFunctionBeginUser;
  // The corotational iteration; it stands unless it takes a vertex into an obstacle.
  PetscCall(CorotationalStep(x, v));
  {
    StageScope stage(Stages().contact);
    PetscCall(contact->AddPenetrations(motion, v, constrain));
  }
  reactions_.clear();
  if (!*constrain) PetscFunctionReturn(PETSC_SUCCESS);
  // Back to x_b, u_b for the single linearised solve with the constraints.
  PetscCall(VecCopy(x_start_, x));
  PetscCall(VecCopy(v_start_, v));
  elastic_state_current_ = false;
  PetscCall(LinearisedRightHandSide(x, v));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::Step(Vec x, Vec v, ContactSolver *contact) {
  PetscFunctionBeginUser;
  const PetscInt contact_solves_before = stats_.contact_solves;
  if (!options_.adaptive) {
    PetscCall(TakeStep(x, v, contact));
    if (contact_acted_) PetscCall(RestartHistoryAfterContact(x, v));
  } else {
    PetscCall(AdaptiveStep(x, v, contact && contact->active() ? contact : nullptr));
  }
  step_had_contact_ = contact_acted_ || stats_.contact_solves > contact_solves_before;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::RestartHistoryAfterContact(Vec x, Vec v) {
  PetscFunctionBeginUser;
  // bdf2: x_{n-1} = x1 - dt v1, v_{n-1} = v1, so the next step's base point is
  // x1 + dt/3 v1, u_b = v1 (the theta method's, without its acceleration), with
  // the same step sizes and so the same A. alpha: a_n = 0. The equation of
  // motion's acceleration leaves out the contact forces (a vertex resting on
  // the ground would be given gravity's acceleration into it).
  if (options_.scheme == SCHEME_BDF2) {
    PetscCall(VecWAXPY(previous_x_, -dt_, v, x));
    PetscCall(VecCopy(v, previous_v_));
  }
  if (options_.scheme == SCHEME_ALPHA) PetscCall(VecZeroEntries(acceleration_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::SaveSubstepState(Vec x, Vec v, const ContactSolver *contact) {
  PetscFunctionBeginUser;
  if (contact) saved_contact_ = contact->CarriedState();
  PetscCall(CreateHistoryVectors());
  if (!saved_x_)
    for (Vec *vector :
         {&saved_x_, &saved_v_, &saved_previous_x_, &saved_previous_v_, &saved_acceleration_})
      PetscCall(VecDuplicate(rest_, vector));
  PetscCall(VecCopy(x, saved_x_));
  PetscCall(VecCopy(v, saved_v_));
  PetscCall(VecCopy(previous_x_, saved_previous_x_));
  PetscCall(VecCopy(previous_v_, saved_previous_v_));
  PetscCall(VecCopy(acceleration_, saved_acceleration_));
  saved_previous_dt_ = previous_dt_;
  saved_acceleration_valid_ = acceleration_valid_;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::RestoreSubstepState(Vec x, Vec v, ContactSolver *contact) {
  PetscFunctionBeginUser;
  if (contact) contact->RestoreCarriedState(saved_contact_);
  PetscCall(VecCopy(saved_x_, x));
  PetscCall(VecCopy(saved_v_, v));
  PetscCall(VecCopy(saved_previous_x_, previous_x_));
  PetscCall(VecCopy(saved_previous_v_, previous_v_));
  PetscCall(VecCopy(saved_acceleration_, acceleration_));
  previous_dt_ = saved_previous_dt_;
  acceleration_valid_ = saved_acceleration_valid_;
  elastic_state_current_ = false;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::SubstepError(Vec x, Vec v, PetscReal *error, bool *estimated) {
  PetscFunctionBeginUser;
  // The velocity's first difference (backward Euler, schemes without history)
  // or second difference (v1 - v0) - (h / h_prev) (v0 - v_prev).
  const PetscReal h = dt_;
  const bool second = options_.scheme != SCHEME_BE && saved_previous_dt_ > 0;
  PetscCall(VecWAXPY(combined_velocity_, -1.0, saved_v_, v));
  if (second) {
    PetscCall(VecWAXPY(combined_position_, -1.0, saved_previous_v_, saved_v_));
    PetscCall(VecAXPY(combined_velocity_, -h / saved_previous_dt_, combined_position_));
  }
  PetscReal raw = 0;
  PetscCall(VecNorm(combined_velocity_, NORM_2, &raw));
  if (filter_ksp_) {
    StageScope stage(Stages().step);
    PetscCall(VecPointwiseMult(filter_work_, mass_, combined_velocity_));
    PetscCall(KSPSolve(filter_ksp_, filter_work_, combined_velocity_));
  }
  // The scale: the displacement plus the distance the faster of the substep's
  // start and end velocities covers in a step of the time loop (not of the
  // substep: a body starting from rest, an impact or a strike changes v by as
  // much as |v| itself, and only this scale lets a smaller substep meet -tol).
  PetscReal difference, displacement, speed, start_speed;
  PetscCall(VecNorm(combined_velocity_, NORM_2, &difference));
  PetscCall(VecWAXPY(combined_position_, -1.0, rest_, x));
  PetscCall(VecNorm(combined_position_, NORM_2, &displacement));
  PetscCall(VecNorm(v, NORM_2, &speed));
  PetscCall(VecNorm(saved_v_, NORM_2, &start_speed));
  const PetscReal scale = displacement + interval_ * PetscMax(speed, start_speed);
  *estimated = scale > 0;
  // bdf2's theta start keeps backward Euler's constant: with its own
  // (theta - 1/2 = 1/6) the bar of test_integrators.py (g) ends 2 to 4 times
  // further from the exact solution at -tol 1e-3 .. 1e-5 (its velocity error,
  // of the same order, is not in the estimate).
  const PetscReal constant = second ? kSecondOrderErrorConstant : kFirstOrderErrorConstant;
  *error = constant * h * difference / (scale > 0 ? scale : 1);
  PetscCall(PetscInfo(nullptr, "-dt_adapt: substep %.6g s estimate %.4g (unfiltered %.4g) %s\n",
                      (double)h, (double)*error,
                      (double)(*error * raw / (difference > 0 ? difference : 1)),
                      second ? "second" : "first"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Linear mode: the estimate of a second-order scheme's substep with history is
// a local error that accumulates over the run, so it is compared with -tol per
// unit time, scaled to the run's length (error x T / h: the sum of such errors
// over the run is then about -tol). The estimate of a start without history,
// or of a substep in which the contact acted (a velocity jump, however small
// the substep), is a one-off error and is compared with -tol as it is.
// Backward Euler keeps the per-substep tolerance: its first-difference
// estimate relative to |x - X| + Dt |v| is, per unit time, h-independent for a
// body starting from rest (v1 - v0 = g h, |v| = g h), so no substep met it.
// Exponents: estimate ~ h^(p+1), per unit time ~ h^p. Corotational mode keeps
// the per-substep tolerance (no filter there: the strike's stiff content would
// ask for tiny substeps per unit time).
void ImplicitEuler::ScaleToRun(PetscReal *error, PetscReal *exponent) const {
  const bool history = options_.scheme != SCHEME_BE && saved_previous_dt_ > 0;
  if (options_.mode == MODE_LINEAR && history && !contact_acted_) {
    *error *= RunLength() / dt_;
    *exponent = 0.5;
  } else {
    *exponent = history ? 1.0 / 3 : 0.5;
  }
}

int ImplicitEuler::LadderLevel(uint64_t elapsed) const {
  int level = 0;
  while (level < kLadderLevels &&
         (std::ldexp(interval_, -level) > target_step_ || elapsed % (kLadderUnits >> level) != 0))
    ++level;
  return level;
}

PetscErrorCode ImplicitEuler::AdaptiveStep(Vec x, Vec v, ContactSolver *contact) {
  PetscFunctionBeginUser;
  uint64_t elapsed = 0;  // in units of the smallest substep
  int rejections = 0;
  while (elapsed < kLadderUnits) {
    const int level = LadderLevel(elapsed);
    dt_ = std::ldexp(interval_, -level);
    PetscCall(SaveSubstepState(x, v, contact));
    PetscCall(PrepareStep());
    PetscCall(TakeStep(x, v, contact));
    PetscReal error;
    bool estimated;
    PetscCall(SubstepError(x, v, &error, &estimated));
    PetscReal exponent;
    ScaleToRun(&error, &exponent);
    const PetscReal factor = estimated && error > 0
                                 ? kSafety * std::pow(options_.tolerance / error, exponent)
                                 : kMaxGrowth;
    if (estimated && error > options_.tolerance) {
      PetscCall(RestoreSubstepState(x, v, contact));
      ++stats_.rejected_steps;
      PetscCheck(++rejections <= kMaxRejections, PetscObjectComm((PetscObject)x),
                 PETSC_ERR_NOT_CONVERGED,
                 "option -tol: %d substeps in a row missed the local error %g (last %g at "
                 "dt = %g s); the motion is not smooth enough for -dt_adapt",
                 rejections, (double)options_.tolerance, (double)error, (double)dt_);
      target_step_ = dt_ * PetscMax(kMaxShrink, PetscMin(factor, kSafety));
      continue;
    }
    rejections = 0;
    elapsed += kLadderUnits >> level;
    // A contact's velocity jump is no smooth history: the scheme restarts after
    // it (a multistep scheme would extrapolate the jump into a rebound) and the
    // next estimate is the first difference.
    if ((contact && contact_acted_) || (first_substep_ && options_.scheme != SCHEME_BE))
      PositionsChanged();
    first_substep_ = false;
    ++stats_.accepted_steps;
    PetscCall(PetscInfo(nullptr, "-dt_adapt: substep of %.17g s accepted\n", (double)dt_));
    stats_.min_step = PetscMin(stats_.min_step, dt_);
    stats_.max_step = PetscMax(stats_.max_step, dt_);
    if (factor >= kGrowthThreshold)
      target_step_ = PetscMin(interval_, dt_ * PetscMin(factor, kMaxGrowth));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::TakeStep(Vec x, Vec v, ContactSolver *contact) {
  PetscFunctionBeginUser;
  contact_acted_ = false;
  // x, v to the scheme's x_b, u_b (backward Euler: x0, v0 as they are).
  PetscCall(PrepareStep());
  PetscCall(BeginSchemeStep(x, v));
  PetscCall(LinearisedRightHandSide(x, v));
  if (contact && contact->active()) {
    PetscCall(ContactStep(x, v, contact));
  } else {
    if (options_.mode == MODE_COROTATIONAL)
      PetscCall(CorotationalStep(x, v));
    else
      PetscCall(LinearStep(x, v));
    PetscCall(FinishSchemeStep(x, v));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::Residual(Vec v, Vec g, PetscReal *merit) {
  PetscFunctionBeginUser;
  const PetscReal a = options_.alpha, dt = step_.force_step;
  // The elastic and damping terms of h_f f_el(x_b + h_x u): E and Psi, per h_x of
  // displacement, weigh h_f / h_x (1 for be, bdf2, newmark).
  const PetscReal ratio = step_.force_step / step_.position_step, b = ratio * options_.beta;
  // g = M (v - v0) + a dt M v + dt f_el + b h - dt f_ext
  PetscCall(VecWAXPY(work_, -1.0, v_start_, v));  // v - v0
  PetscCall(VecPointwiseMult(g, mass_, work_));
  PetscReal inertia, mass_damping = 0, external = 0;
  PetscCall(VecDot(g, work_, &inertia));  // |v - v0|_M^2
  if (a > 0) {
    PetscCall(VecPointwiseMult(work_, mass_, v));
    PetscCall(VecDot(work_, v, &mass_damping));  // |v|_M^2
    PetscCall(VecAXPY(g, a * dt, work_));
  }
  PetscCall(VecAXPY(g, dt, elastic_force_));
  if (b > 0) PetscCall(VecAXPY(g, b, damping_force_));
  if (gravity_force_) {
    PetscCall(VecAXPY(g, -dt, gravity_force_));
    PetscCall(VecDot(gravity_force_, v, &external));
  }
  // P = |v - v0|_M^2 / 2 + a dt |v|_M^2 / 2 + E + (b / dt) Psi - dt f_ext . v
  *merit = 0.5 * inertia + 0.5 * a * dt * mass_damping + ratio * elastic_energy_ +
           (b > 0 ? b / step_.position_step * damping_energy_ : 0) - dt * external;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::BeginCorotationalStep(Vec x, Vec v) {
  PetscFunctionBeginUser;
  if (!x_start_) PetscCall(VecDuplicate(x, &x_start_));
  if (!v_start_) {
    PetscCall(VecDuplicate(x, &v_start_));
    PetscCall(VecDuplicate(x, &iterate_));
    PetscCall(VecDuplicate(x, &direction_));
    PetscCall(VecDuplicate(x, &work_));
    PetscCall(VecDuplicate(x, &v_trial_base_));
  }
  PetscCall(VecCopy(x, x_start_));
  PetscCall(VecCopy(v, v_start_));
  if (options_.beta > 0) {  // the step's deformation increments count from here: h = 0, Psi = 0
    corotated_start_.swap(corotated_);
    PetscCall(VecZeroEntries(damping_force_));
    damping_energy_ = 0;
    step_started_ = true;
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::StepScales(Vec v, PetscReal *scale, PetscReal *start_energy) {
  PetscFunctionBeginUser;
  PetscReal momentum, force, external = 0, start_kinetic;
  PetscCall(VecPointwiseMult(work_, mass_, v));
  PetscCall(VecNorm(work_, NORM_2, &momentum));
  PetscCall(VecDot(work_, v, &start_kinetic));
  PetscCall(VecNorm(elastic_force_, NORM_2, &force));
  if (gravity_force_) PetscCall(VecNorm(gravity_force_, NORM_2, &external));
  *scale = momentum + step_.force_step * (force + external);
  *start_energy = 0.5 * start_kinetic + elastic_energy_;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::NewtonDirection(PetscInt k, PetscReal *slope) {
  PetscFunctionBeginUser;
  // A_k d = -g(v_k); the first direction is v1 itself, guessed as v0.
  PetscCall(VecScale(rhs_, -1.0));
  if (k == 0)
    PetscCall(VecCopy(v_start_, direction_));
  else
    PetscCall(VecZeroEntries(direction_));
  PetscCall(Solve(direction_, nullptr));
  PetscCall(VecDot(rhs_, direction_, slope));
  *slope = -*slope;  // g.d < 0
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::LineSearch(Vec x, PetscReal slope, PetscReal scale, PetscReal *merit,
                                         PetscReal *residual, PetscReal *step_length) {
  PetscFunctionBeginUser;
  // Armijo on P. Near the root |g| decides: round-off in P (stiff elements: y is
  // a small difference) hides the decrease, and the left-out rotation
  // derivatives of the damping term move P's minimum off g's root by a little.
  const PetscReal last_merit = *merit, last_residual = *residual;
  PetscCall(VecCopy(iterate_, v_trial_base_));
  PetscReal s = 1;
  for (int halvings = 0;; ++halvings) {
    PetscCall(VecWAXPY(iterate_, s, direction_, v_trial_base_));
    PetscCall(VecWAXPY(x, step_.position_step, iterate_, x_start_));
    elastic_state_current_ = false;
    PetscCall(UpdateElasticState(x));
    PetscCall(Residual(iterate_, rhs_, merit));
    PetscCall(VecNorm(rhs_, NORM_2, residual));
    const bool near_root = last_residual <= kNearRootFraction * scale;
    if (*merit <= last_merit + kSufficientDecrease * s * slope ||
        (near_root && *residual <= (1 - kSufficientDecrease * s) * last_residual) ||
        halvings == kMaxHalvings)
      break;
    s *= 0.5;
    ++stats_.backtracks;
  }
  *step_length = s;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::IterateEnergy(PetscReal *energy, PetscReal *work) {
  PetscFunctionBeginUser;
  // |v_k|_M^2 / 2 + E(x_k) - dt f_ext.v_k
  PetscReal kinetic;
  *work = 0;
  PetscCall(VecPointwiseMult(work_, mass_, iterate_));
  PetscCall(VecDot(work_, iterate_, &kinetic));
  if (gravity_force_) PetscCall(VecDot(gravity_force_, iterate_, work));
  *energy = 0.5 * kinetic + elastic_energy_ - step_.force_step * *work;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::FinishCorotationalStep(PetscInt iterations, PetscReal residual,
                                                     PetscReal tolerance, bool dissipative, Vec v) {
  PetscFunctionBeginUser;
  step_started_ = false;
  stats_.newton_iterations += iterations;
  stats_.max_newton_iterations = PetscMax(stats_.max_newton_iterations, iterations);
  if (iterations == options_.newton_max_it && residual > tolerance && options_.newton_max_it > 1) {
    PetscCheck(
        dissipative, PetscObjectComm((PetscObject)v), PETSC_ERR_NOT_CONVERGED,
        "step: the corotational iteration did not converge (|g| = %g > %g after %" PetscInt_FMT
        " iterations) and its last iterate gains energy; try a smaller -dt or a larger "
        "-newton_max_it",
        (double)residual, (double)tolerance, iterations);
    ++stats_.newton_stopped_short;
  }
  // x = x0 + dt v_k and the elastic state of x are current: the next step starts from them.
  PetscCall(VecCopy(iterate_, v));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::CorotationalStep(Vec x, Vec v) {
  PetscFunctionBeginUser;
  PetscCall(BeginCorotationalStep(x, v));
  // Scale of g: |M v0| + dt |f_el(x0)| + dt |f_ext|; total energy at the start,
  // |v0|_M^2 / 2 + E(x0) (gravity's reference: x0).
  PetscReal scale, start_energy;
  PetscCall(StepScales(v, &scale, &start_energy));
  const PetscReal tolerance = options_.newton_rtol * scale;
  PetscCall(VecZeroEntries(iterate_));  // v_0 = 0: x = x0
  PetscReal merit, residual = PETSC_MAX_REAL;
  PetscCall(Residual(iterate_, rhs_, &merit));
  PetscInt k = 0;
  bool dissipative = false;
  for (; k < options_.newton_max_it; ++k) {
    PetscReal slope, s, energy, work;
    PetscCall(NewtonDirection(k, &slope));
    const PetscReal last_residual = residual;
    PetscCall(LineSearch(x, slope, scale, &merit, &residual, &s));
    PetscCall(IterateEnergy(&energy, &work));
    const PetscReal gain = energy - start_energy;
    PetscCall(PetscInfo(ksp_,
                        "corotational iterate %" PetscInt_FMT
                        ": |g| = %g (%g of the scale), step length %g, "
                        "energy gain %g J of %g J\n",
                        k + 1, (double)residual, (double)(residual / scale), (double)s,
                        (double)gain, (double)start_energy));
    if (residual <= tolerance) break;
    // The linearised step stands unless it gains energy (round-off allowed).
    const PetscReal round_off = kEnergyRoundOff * (start_energy + PetscAbsReal(energy) +
                                                   step_.force_step * PetscAbsReal(work));
    // The energy test is backward Euler's (its steps never gain energy); the
    // other schemes' steps stand on |g| alone.
    const bool backward_euler = step_.identity;
    dissipative = !backward_euler || gain <= round_off;
    if (k == 0 && backward_euler && !options_.newton_always && dissipative) break;
    // A dissipative iterate also stands once the iteration stalls (|g| falls by
    // less than a tenth: a kink of R at an inverted element, or the left-out
    // rotation derivative with lambda >> mu); counted as stopped short.
    if (k > 0 && dissipative && residual > kStallRatio * last_residual) {
      ++stats_.newton_stopped_short;
      break;
    }
  }
  const PetscInt iterations = PetscMin(k + 1, options_.newton_max_it);
  PetscCall(FinishCorotationalStep(iterations, residual, tolerance, dissipative, v));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ImplicitEuler::TimeAssembly(Vec x, PetscInt repeats, std::vector<double> *seconds) {
  PetscFunctionBeginUser;
  StageScope stage(Stages().assembly);
  const PetscReal a = options_.alpha, b = options_.beta;
  const bool rotated = options_.mode == MODE_COROTATIONAL;
  // The refill of A alone (rotations, rotated element blocks, values, forces,
  // energy); the warp preconditioner's per-vertex rotations, which a step
  // computes in the same pass, are its own work and left out here.
  const bool vertex_rotations = assembler_.vertex_rotations_requested();
  assembler_.ComputeVertexRotations(false);
  seconds->clear();
  for (PetscInt repeat = 0; repeat < repeats; ++repeat) {
    PetscLogDouble start, end;
    PetscCallMPI(MPI_Barrier(PetscObjectComm((PetscObject)x)));
    PetscCall(PetscTime(&start));
    RowAssembler::FillTerms terms =
        RowAssembler::FillTerms()
            .Stiffness(b * system_force_step_ + system_force_step_ * system_position_step_)
            .Mass(mass_, 1.0 + a * system_force_step_);
    if (rotated) terms.CorotatedAt(x).ElasticForce(elastic_force_).StrainEnergy(&elastic_energy_);
    PetscCall(assembler_.Fill(A_, terms));
    PetscCall(PetscTime(&end));
    seconds->push_back(end - start);
  }
  assembler_.ComputeVertexRotations(vertex_rotations);
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
    const double local_energy =
        LinearStrainEnergy(*elements_, options_.shear_scale, x_touched, X_touched);
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
