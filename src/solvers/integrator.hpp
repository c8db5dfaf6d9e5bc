// Time integration of the finite-element equations of motion
//
//     M x'' + D x' + f_el(x) = f_ext,    D = a M + b K  (Rayleigh damping),
//
// by one of the schemes of -integrator (time_scheme.hpp: backward Euler, the
// default; BDF2; implicit Newmark; generalized-alpha). Each scheme's step is one
// solve for a velocity-like unknown u, in backward Euler's velocity form:
//
//     A u = M u_b - h_f f_el(x_b) + h_f f_ext,    x = x_b + h_x u,
//     A = (1 + a h_f) M + (b h_f + h_f h_x) K,
//
// with the scheme's base point x_b, u_b and step sizes h_x, h_f (s); the new
// positions and velocities are combinations of x, u and the old state (and, per
// scheme, its history: previous positions and velocities, or accelerations).
// Backward Euler: h_x = h_f = dt, x_b = x0, u_b = v0, x1 = x, v1 = u:
//
//     (M + dt D + dt^2 K) v1 = M v0 - dt f_el(x0) + dt f_ext,    x1 = x0 + dt v1.
//
// Below, "dt" in a formula of the step stands for h_f (forces, damping) or h_x
// (positions), "x0, v0" for x_b, u_b and "v" for u.
//
// M is the lumped mass (kg, kept as a Vec), X the rest positions (m), x positions
// (m), v velocities (m/s), dt in s, a in 1/s, b in s. D is never formed:
// A = (1 + a dt) M + (b dt + dt^2) K.
//
// Linear mode: K is the rest stiffness, f_el = K (x - X); A is assembled and
//   factorised once per time step size; a step costs one K x product and one solve.
// Corotational mode (Mueller & Gross 2004, "Interactive Virtual Materials"): each
//   step extracts every tet's rotation R from F = Ds Dm^-1 (see element.hpp),
//   K = K(R) = sum_e R K_e R^T and f_el = sum_e R K_e (R^T x_e - X_e); A's values
//   are refilled into the same pattern (no symbolic work) and solved again,
//   by default with CG preconditioned by the linear system's factor rotated per
//   vertex (warp_preconditioner.hpp), warm-started from the previous velocity; A
//   is filled straight into its CSR rows (row_assembly.hpp).
//   The step is the root of
//       g(v) = M (v - v0) + a dt M v + dt f_el(x) + b h(x) - dt f_ext,  x = x0 + dt v,
//   h = sum_e R K_e (y_e - y_e0), y_e = R^T x_e - X_e: the stiffness damping acts on
//   the rotation-free deformation increment of the step, (y_e - y_e0) / dt, so a
//   rigid rotation is not damped (b K(R) v would damp a chord's centripetal part
//   and, for stiff bodies, pump energy into strain). g is the gradient of
//       P(v) = |v - v0|_M^2 / 2 + a dt |v|_M^2 / 2 + E(x) + (b / dt) Psi(x) - dt f_ext . v,
//   Psi = sum_e |y_e - y_e0|_K_e^2 / 2 (up to rotation derivatives of the damping
//   term), and is solved from v_0 = 0 by
//       A_k d = -g(v_k),  A_k = (1 + a dt) M + (b dt + dt^2) K(R_k)  (the rotation's
//       own derivative left out: A_k is SPD, d descends),  v_k+1 = v_k + s d,
//   s halved until P falls (Armijo; near the root, until |g| falls). The first
//   iterate is Mueller & Gross's single linearised step with D = a M + b K(R0);
//   it stands unless it gains energy (|v1|_M^2 / 2 + E(x1) - dt f_ext . v1 >
//   |v0|_M^2 / 2 + E(x0)); such steps iterate until |g| <= -newton_rtol
//   (|M v0| + dt |f_el(x0)| + dt |f_ext|) (-newton_always: every step does), or
//   until the iteration stalls at an iterate that gains no energy (reported).
//   The energy test is backward Euler's (its step never gains energy); the
//   other schemes iterate every step until |g| <= -newton_rtol (scale) or the
//   iteration stalls (reported as stopped short).
//   With contact, the step is the single linearised solve (projected_solve.hpp).
// Energies: kinetic v^T M v / 2; elastic (x - X)^T K (x - X) / 2 in linear mode
// (summed element by element, each term non-negative),
// sum_e y_e^T K_e y_e / 2 with y_e = R^T x_e - X_e in corotational mode (J).
// External force: gravity, f_ext = M g.
#pragma once

#include <petscksp.h>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "contact/contact.hpp"
#include "fem/assembly.hpp"
#include "fem/row_assembly.hpp"
#include "solvers/projected_solve.hpp"
#include "solvers/time_scheme.hpp"

namespace softbody {

typedef enum { MODE_LINEAR, MODE_COROTATIONAL } ElasticityMode;
extern const char *const kElasticityModes[];

struct IntegratorOptions {
  ElasticityMode mode = MODE_LINEAR;
  TimeScheme scheme = SCHEME_BE;  // -integrator
  // -alpha_rho_inf: generalized-alpha's spectral radius at dt*omega -> infinity.
  // 0.9 damps an unresolved mode by 10 % per step while a mode resolved by 20
  // steps per period loses only 0.05 % of its amplitude per period
  // (docs/integrators.md); 1 is Newmark without dissipation, 0 the most.
  PetscReal rho_inf = 0.9;
  // -dt_adapt: each step of -dt (the interval between steps the time loop sees,
  // frames and -dt_schedule) is taken in substeps whose size follows a local
  // error estimate; -tol is about the relative error of x - X at the run's end
  // in linear mode, the relative error per substep in corotational mode (see Step).
  PetscBool adaptive = PETSC_FALSE;
  PetscReal tolerance = 1e-4;
  // -dt_adapt_horizon (s): the time over which -tol bounds the error (linear
  // mode); 0: the run's length, -steps x -dt.
  PetscReal horizon = 0;
  // -dt_adapt_factors: linear mode keeps the systems (A and its factor) of this
  // many substep sizes, the least recently used replaced first. 4: bdf2 moving
  // between two sizes uses four systems (each size's own and the two of the
  // step after a change); each holds a factor (20 MB at the default scene).
  PetscInt factor_cache = 4;
  PetscReal dt = 0.02;  // s
  // -dt_schedule: from time .first (s) on, the step is .second (s); sorted by time.
  std::vector<std::pair<PetscReal, PetscReal>> dt_schedule;
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();  // m/s^2
  PetscInt steps = 100;
  PetscReal alpha = 0.1;        // mass damping a, 1/s
  PetscReal beta = 0.1;         // stiffness damping b, s
  PetscReal shear_scale = 1.0;  // s on the shear block of the elasticity tensor (element.hpp)
  // Corotational mode: the step's nonlinear equation is solved by Newton-type
  // iterations until |g| <= newton_rtol (|M v0| + dt |f_el(x0)| + dt |f_ext|), at
  // most newton_max_it linearised solves, every step when newton_always (else
  // only steps whose first iterate gains energy; see the top of this file).
  PetscReal newton_rtol = 1e-4;
  PetscInt newton_max_it = 50;
  PetscBool newton_always = PETSC_FALSE;
  // A solve that breaks down (a factor or preconditioner that is not positive
  // definite, NaN) is repeated by a distributed direct factorisation
  // (SuperLU_dist LU, column order by ParMETIS; integrator.cpp).
  PetscBool fallback_direct = PETSC_TRUE;
  // Linear mode with a factorisation: the contact solves' preconditioner with
  // the constraint correction (solvers/constraint_correction.hpp).
  PetscBool constraint_correction = PETSC_TRUE;
  // How contact solves treat two-sided rows (free bodies against each other):
  // chosen by their count and the solver (projected_solve.hpp), or forced.
  TwoSidedPath two_sided_path = TwoSidedPath::kAuto;
};

// The time step at time t (s): -dt until the first -dt_schedule entry applies.
PetscReal TimeStepAt(const IntegratorOptions &options, PetscReal time);

// Collective. Reads the options of IntegratorOptions (their list with units and
// defaults: softbody -help, section "Time integration"); rejects impossible
// values (non-positive -dt, negative damping, ...).
PetscErrorCode ProcessIntegratorOptions(MPI_Comm comm, IntegratorOptions *options);

struct SolverStatistics {
  PetscInt solves = 0;
  PetscInt total_iterations = 0;
  PetscInt last_iterations = 0;
  PetscInt min_iterations = PETSC_MAX_INT;
  PetscInt max_iterations = 0;
  PetscLogDouble factor_seconds = 0;      // wall time of the last (re)factorisation/set-up
  PetscLogDouble assemble_seconds = 0;    // wall time of the last fill of A (linear: with K)
  PetscLogDouble last_setup_seconds = 0;  // preconditioner set-up inside the last step
  PetscInt assemblies = 0;                // fills of A
  PetscInt time_step_changes = 0;         // SetTimeStep calls after the first
  PetscInt contact_solves = 0;            // solves with contact constraints
  PetscInt contact_iterations = 0;        // their CG iterations
  PetscInt newton_iterations = 0;         // corotational: linearised solves, all steps
  PetscInt max_newton_iterations = 0;     // corotational: most in one step
  PetscInt backtracks = 0;                // corotational: line-search step halvings
  // corotational: dissipative steps that stalled above -newton_rtol
  PetscInt newton_stopped_short = 0;
  PetscInt fallback_solves = 0;  // solves repeated by the direct fallback after a breakdown
  // -dt_adapt: accepted and rejected substeps, the accepted substeps' sizes (s).
  PetscInt accepted_steps = 0, rejected_steps = 0;
  PetscReal min_step = PETSC_MAX_REAL, max_step = 0;
  std::string choice;  // the default solver's choice and its reason (empty: none checked)
};

// The integrator of every scheme (the class keeps backward Euler's name).
class ImplicitEuler {
 public:
  ImplicitEuler() = default;
  ImplicitEuler(const ImplicitEuler &) = delete;
  ImplicitEuler &operator=(const ImplicitEuler &) = delete;
  ~ImplicitEuler();

  // Collective. Creates the matrices (from `tets`, MigrateTets, consumed: freed
  // before the solver's set-up) and the solver for options.dt (linear mode:
  // assembles and factorises A). elements, rest_positions and lumped_mass are
  // referenced.
  PetscErrorCode Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout, LocalTets &&tets,
                       const LocalElements &elements, Vec rest_positions, Vec lumped_mass,
                       const IntegratorOptions &options);
  // Collective. Linear mode: owned_body[i] is the body of owned vertex i; each
  // step then takes every body's rigid-body velocity (translation and
  // infinitesimal rotation about its rest centre of mass) from its momentum:
  // K annihilates these modes exactly, so (1 + a dt) Z^T M Z y = Z^T (M v0 + dt f_ext)
  // holds for them, and the factorisation, which cannot resolve them when the
  // mass part of A is below K's round-off (stiff slivers), is not asked to.
  PetscErrorCode SetBodies(std::vector<int32_t> owned_body, int num_bodies);
  // Collective. New time step size (s); linear mode refills A and refactorises.
  PetscErrorCode SetTimeStep(PetscReal dt);
  // Collective. Advances positions x and velocities v by one step; with
  // -dt_adapt, by substeps of the step: each is repeated with a smaller size
  // while its local error estimate exceeds -tol (linear mode: filtered by the
  // damping over the run and, with history, taken per unit time times the
  // run's length: SetDampingFilter, ScaleToRun; relative to |x - X| + Dt |v|, Dt
  // the step and |v| the larger of the substep's start and end speeds:
  // backward Euler h |v1 - v0| / 2, the second-order schemes
  // h |v1 - v0 - (h / h_prev)(v0 - v_prev)| / 6, the velocity's second difference),
  // and the next substeps' size follows the estimate (sizes Dt / 2^k, grown
  // only beyond a factor, so that A is refactorised seldom); with contact, a
  // rejected substep also restores the contact's carried state, and after a
  // substep in which the contact acted the scheme's history restarts. The external
  // force is gravity, f_ext = M g (none when g = 0). With contact (may be null):
  // solve, constrain the vertices the step would take inside obstacles, solve
  // again with the constraints until no new one appears (contact.hpp), then the
  // contact's velocity response and distance constraints.
  PetscErrorCode Step(Vec x, Vec v, ContactSolver *contact);
  // Collective. For a restart: sets the solver up once for the original run's
  // first step (positions x_first, time step dt_first), so that a solver that
  // keeps state from its first set-up holds what it held in the uninterrupted
  // run (GAMG copies the near-null space at its first set-up and reuses the copy
  // at every later one, until PCReset). Nothing to do in linear mode.
  PetscErrorCode PrimeSolver(Vec x_first, PetscReal dt_first);
  // Not collective. To be called after positions were changed outside Step
  // (-deform): the schemes' history restarts (bdf2 takes a backward Euler step,
  // alpha takes the acceleration from the equation of motion).
  void PositionsChanged() {
    elastic_state_current_ = false;
    previous_dt_ = 0;
    acceleration_valid_ = false;
  }
  // Collective. The scheme's history for a checkpoint (vectors created on first
  // use; after SetHistory they hold what a checkpoint stored).
  PetscErrorCode GetHistory(SchemeHistory *history);
  // Collective. After a restart: found tells whether the checkpoint held this
  // scheme's history (its vectors, from GetHistory, now filled, and scalars);
  // without it the history starts afresh as after PositionsChanged.
  PetscErrorCode SetHistory(const std::vector<double> &scalars, bool found);
  // Collective. Kinetic, elastic and gravitational energy (J) of the state (x, v);
  // the gravitational energy is -sum_i m_i g . x_i (zero at the origin).
  PetscErrorCode Energies(Vec x, Vec v, EnergySample *energy);

  // Collective. Fills A `repeats` more times as a step would (linear: the rest
  // stiffness; corotational: at positions x, with forces and energy) and
  // returns each fill's wall time (s); A's values stay the same. For -bench.
  PetscErrorCode TimeAssembly(Vec x, PetscInt repeats, std::vector<double> *seconds);

  KSP solver() const { return ksp_; }
  ElasticityMode mode() const { return options_.mode; }
  // The system matrix A and (linear mode) the rest stiffness K (null in corotational mode).
  Mat system_matrix() const { return A_; }
  Mat stiffness_matrix() const { return K_; }
  // Elements this rank's assembly computes (its own and those shared with a neighbour).
  size_t assembled_elements() const { return assembler_.num_elements(); }
  PetscReal time_step() const { return interval_; }
  TimeScheme scheme() const { return options_.scheme; }
  const SolverStatistics &statistics() const { return stats_; }
  // After Step: contact acted in it (a solve under contact constraints, or the
  // end-of-step response or guard changed x or v; any substep with -dt_adapt).
  bool last_step_had_contact() const { return step_had_contact_; }

 private:
  // Setup's steps: f_ext = M g; the assembler, A (and K in linear mode); the
  // gather plan of the local elements' vertices; the KSP (and the warp PC's A0).
  PetscErrorCode CreateGravityForce();
  PetscErrorCode CreateMatrices(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                                LocalTets &&tets);
  PetscErrorCode CreateTouchedScatter(const LocalElements &elements);
  PetscErrorCode CreateLinearSolver(const DofLayout &layout);
  // f_el(x) into elastic_force_ and the elastic energy; corotational mode also
  // refills A for x. Skipped when already done for these positions (x changes
  // only in Step).
  PetscErrorCode UpdateElasticState(Vec x);
  PetscErrorCode UpdateNearNullSpace(Vec x);
  // v = A^-1 rhs_ (v: initial guess), with the contact's velocity constraints
  // when any rank has one.
  PetscErrorCode Solve(Vec v, const ContactSolver *contact);
  // Collective. A v = rhs again by the direct fallback (-fallback_direct) after
  // the solver broke down with `failed`; its reason in *reason.
  PetscErrorCode SolveDirectly(Vec v, KSPConvergedReason failed, KSPConvergedReason *reason);
  // The scheme's step: its coefficients for the next step (A refilled, linear
  // mode: refactorised, when its step sizes changed); x, v from x_n, v_n to
  // x_b, u_b (the state kept); after the solve, x, v to x1, v1 and the history.
  PetscErrorCode PrepareStep();
  // One step of size dt_ (Step without -dt_adapt).
  PetscErrorCode TakeStep(Vec x, Vec v, ContactSolver *contact);
  // -dt_adapt: the substeps of one step; saving and restoring the state of a
  // substep; its relative local error estimate (*estimated false: no history).
  // With contact (null: none), its carried state (the resting contacts) is
  // saved and restored with the substep's.
  PetscErrorCode AdaptiveStep(Vec x, Vec v, ContactSolver *contact);
  // The substep sizes are the step's halvings dt / 2^level: a few sizes recur,
  // so A changes (linear mode: is refactorised) only when the size moves on
  // this ladder, and the substeps end on the step's end exactly. The level of
  // the next substep: the largest size not above the target that `elapsed`
  // (in units of the smallest size) is a multiple of.
  int LadderLevel(uint64_t elapsed) const;
  PetscErrorCode SaveSubstepState(Vec x, Vec v, const ContactSolver *contact);
  PetscErrorCode RestoreSubstepState(Vec x, Vec v, ContactSolver *contact);
  PetscErrorCode SubstepError(Vec x, Vec v, PetscReal *error, bool *estimated);
  // Linear mode with stiffness damping: factorises the damping filter B of the
  // estimate (integrator.cpp) for the run's length (once).
  PetscErrorCode SetDampingFilter();
  // -dt_adapt, linear mode: makes A_ and ksp_ the cached system of the step sizes
  // (h_f, h_x); *cached when it holds them already factorised (else the caller
  // fills and factorises it: a new entry, or the least recently used one).
  PetscErrorCode SelectCachedSystem(PetscReal hf, PetscReal hx, bool *cached);
  // The estimate against -tol (scaled per unit time to the run's length, or
  // not) and the exponent of tol / error in the next target size.
  void ScaleToRun(PetscReal *error, PetscReal *exponent) const;
  // -dt_adapt_horizon, by default the run's length -steps x -dt (s); at least
  // the step of the time loop.
  PetscReal RunLength() const {
    return PetscMax(interval_,
                    options_.horizon > 0 ? options_.horizon : options_.steps * options_.dt);
  }
  PetscErrorCode FillSystem(PetscReal force_step, PetscReal position_step);
  PetscErrorCode BeginSchemeStep(Vec x, Vec v);
  PetscErrorCode FinishSchemeStep(Vec x, Vec v);
  PetscErrorCode Combine(const Combination &c, Vec x, Vec v, Vec result);
  // alpha without history: a = M^-1 (f_ext - D v - f_el(x)) at the state (x, v).
  PetscErrorCode InitialAcceleration(Vec x, Vec v);
  PetscErrorCode CreateHistoryVectors();
  // Linear mode: per body, the momentum and angular momentum about the rest
  // centre of mass of m_i w_i (+ dt f_ext,i when with_force).
  PetscErrorCode BodyMomenta(Vec w, bool with_force, std::vector<Eigen::Vector3d> *momenta);
  // Step without contact, linear mode: one solve, then each body's rigid-body
  // velocity from its momentum (v += dp / m + (I^-1 dL) x r per vertex, dp and
  // dL the momenta target / (1 + a dt) - solved).
  PetscErrorCode LinearStep(Vec x, Vec v);
  PetscErrorCode CorrectRigidBodyVelocities(const std::vector<Eigen::Vector3d> &target,
                                            const std::vector<Eigen::Vector3d> &solved, Vec v);
  // Fixed steps, after a step in which the contact acted (x, v: x1, v1): a
  // contact's velocity jump is no smooth history (bdf2 would extrapolate it
  // into a rebound, alpha's a1 holds it), so the history restarts from a
  // constant velocity, keeping the step sizes and A (-dt_adapt instead restarts
  // as after PositionsChanged, its substep sizes change anyway).
  PetscErrorCode RestartHistoryAfterContact(Vec x, Vec v);
  // Step with contact: solve, constrain, solve again (Step).
  PetscErrorCode ContactStep(Vec x, Vec v, ContactSolver *contact);
  // The step's motion for the contact (contact.hpp's StepMotion), with x = x_b:
  // from x_n to x1 = x_e + h_e u (time_scheme.hpp's end map).
  PetscErrorCode ContactMotion(Vec x, StepMotion *motion);
  // x = x1, solved again (at most kMaxGuardSolves times) while the collision
  // guard would move vertices, with their zone velocities prescribed.
  PetscErrorCode SolveWithGuardedVertices(const StepMotion &motion, Vec x, Vec v,
                                          ContactSolver *contact);
  // rhs = M u_b - h_f f_el(x_b) + h_f f_ext for the state x = x_b, v = u_b.
  PetscErrorCode LinearisedRightHandSide(Vec x, Vec v);
  // Corotational mode with contact but no constraint yet, schemes other than
  // backward Euler: the corotational iteration; *constrain when it took a
  // vertex into an obstacle (x, v and rhs are then back at x_b, u_b).
  PetscErrorCode IterateBeforeContact(const StepMotion &motion, Vec x, Vec v,
                                      ContactSolver *contact, bool *constrain);
  // Corotational step without contact: the Newton-type iteration above, in its
  // steps: x0, v0 and the damping's start; g's scale and the start energy; the
  // direction A_k d = -g(v_k) and the slope g.d; the line search on the step
  // length s; the energy of the iterate (and its work term dt f_ext.v_k, J);
  // the statistics, the convergence check and v = v_k.
  PetscErrorCode CorotationalStep(Vec x, Vec v);
  PetscErrorCode BeginCorotationalStep(Vec x, Vec v);
  PetscErrorCode StepScales(Vec v, PetscReal *scale, PetscReal *start_energy);
  PetscErrorCode NewtonDirection(PetscInt k, PetscReal *slope);
  PetscErrorCode LineSearch(Vec x, PetscReal slope, PetscReal scale, PetscReal *merit,
                            PetscReal *residual, PetscReal *step_length);
  PetscErrorCode IterateEnergy(PetscReal *energy, PetscReal *work);
  PetscErrorCode FinishCorotationalStep(PetscInt iterations, PetscReal residual,
                                        PetscReal tolerance, bool dissipative, Vec v);
  // g(v) and the merit P(v) for the state at x0 + dt v (element pass done).
  PetscErrorCode Residual(Vec v, Vec g, PetscReal *merit);

  const LocalElements *elements_ = nullptr;
  IntegratorOptions options_;
  PetscReal dt_ = 0;        // the size of the next (during Step: this) step or substep (s)
  PetscReal interval_ = 0;  // the step the time loop asked for (s); dt_ without -dt_adapt
  // -dt_adapt: the substep size the error estimate asks for (s); the state at the
  // start of a substep (x, v, history) to restore after a rejection.
  PetscReal target_step_ = 0, saved_previous_dt_ = 0;
  bool saved_acceleration_valid_ = false;
  RestingContacts saved_contact_;
  // -dt_adapt: no substep accepted yet in this run (the history restarts after it).
  bool first_substep_ = true;
  // The last step's contact constrained a vertex or changed x or v after the solve.
  bool contact_acted_ = false;
  bool step_had_contact_ = false;  // last_step_had_contact()
  Vec saved_x_ = nullptr, saved_v_ = nullptr, saved_previous_x_ = nullptr,
      saved_previous_v_ = nullptr, saved_acceleration_ = nullptr;
  // The next (during Step: this) step's coefficients; A's step sizes (h_f, h_x).
  StepCoefficients step_;
  PetscReal system_force_step_ = 0, system_position_step_ = 0;
  // History: the last step's size (0: none, e.g. before the first step); x_n and
  // v_n of the current step; bdf2's x_{n-1}, v_{n-1}; alpha's a_n and whether it
  // holds the acceleration of the current state.
  PetscReal previous_dt_ = 0;
  Vec step_x_ = nullptr, step_v_ = nullptr, previous_x_ = nullptr, previous_v_ = nullptr,
      acceleration_ = nullptr, end_acceleration_ = nullptr;
  Vec combined_position_ = nullptr, combined_velocity_ = nullptr;  // work vectors of Combine
  bool acceleration_valid_ = false;
  Vec rest_ = nullptr, mass_ = nullptr;  // not owned
  Mat A_ = nullptr;
  KSP ksp_ = nullptr;
  KSP fallback_ksp_ = nullptr;  // created at the first breakdown
  // -dt_adapt's damping filter B, its solver, a work vector and the length (s)
  // B was filled for (0: none).
  struct CachedSystem {
    PetscReal force_step, position_step;  // h_f, h_x (s) of its values
    Mat matrix;
    KSP solver;
    uint64_t last_use;
  };
  std::vector<CachedSystem> systems_;  // -dt_adapt_factors; empty: A_, ksp_ own themselves
  uint64_t cache_clock_ = 0;
  bool warp_ = false;  // the warp preconditioner holds A_: no cache
  Mat filter_matrix_ = nullptr;
  KSP filter_ksp_ = nullptr;
  Vec filter_work_ = nullptr;
  PetscReal filter_horizon_ = 0;
  Vec elastic_force_ = nullptr, rhs_ = nullptr;
  Vec gravity_force_ = nullptr;  // M g, only when g != 0
  Vec x_start_ = nullptr;        // x0 during a step with contact
  // Schemes other than be, with contact: x_n and the end map's base x_e.
  Vec motion_start_ = nullptr, end_base_ = nullptr;
  // Corotational iteration: v0, the iterate v_k (and v_k before its line search),
  // the direction d, a work vector.
  Vec v_start_ = nullptr, iterate_ = nullptr, v_trial_base_ = nullptr, direction_ = nullptr,
      work_ = nullptr;
  // Corotational stiffness damping (b > 0): the displacement gradients of y_e of
  // the last element pass and at the start of the step (9 doubles per element
  // each), h = sum_e R K_e (y_e - y_e,start) and Psi (during a step).
  std::vector<double> corotated_, corotated_start_;
  bool step_started_ = false;
  Vec damping_force_ = nullptr;
  PetscReal damping_energy_ = 0;
  ProjectedSolver projected_;
  std::vector<PetscReal> reactions_;
  PetscReal elastic_energy_ = 0;  // corotational mode (linear: in Energies)
  bool elastic_state_current_ = false;
  bool gamg_ = false;       // the PC uses the near-null space
  RowAssembler assembler_;  // fills A (and K) straight into their CSR values
  // Linear mode, rigid-body velocities (SetBodies): per body mass (kg), rest centre
  // of mass (m) and inverse rotational inertia about it (1/(kg m^2)).
  struct RigidBody {
    double mass = 0;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    Eigen::Matrix3d inverse_inertia = Eigen::Matrix3d::Zero();
  };
  std::vector<int32_t> owned_body_;
  std::vector<RigidBody> rigid_;
  // Linear mode: the rest stiffness and a work vector for x - X.
  Mat K_ = nullptr;
  // Corotational mode with the warp preconditioner: A0, the linear system.
  Mat A_linear_ = nullptr;
  Vec displacement_ = nullptr;
  // Positions of the vertices the local elements touch (corotational steps,
  // element-wise energies).
  VecScatter touched_scatter_ = nullptr;
  Vec x_touched_ = nullptr, X_touched_ = nullptr;
  SolverStatistics stats_;
};

}  // namespace softbody
