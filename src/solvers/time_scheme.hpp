// The time integration schemes of -integrator, each written as one
// backward-Euler-like solve per step (integrator.hpp), so that every scheme keeps
// softbody's fast paths: one factorisation of a constant A per step size in
// linear mode, the rigid-body momentum correction, the contact's projected solve
// and the corotational Newton iteration on an incremental potential.
//
// Equations of motion: M x'' + D x' + f_el(x) = f_ext, D = a M + b K.
// Every scheme's step solves for one velocity-like unknown u
//
//     M (u - u_b) + h_f (D u + f_el(x) - f_ext) = 0,    x = x_b + h_x u,          (S)
//
// (linear mode: A u = M u_b - h_f f_el(x_b) + h_f f_ext with
// A = (1 + a h_f) M + (b h_f + h_f h_x) K, constant for fixed dt), where the base
// point x_b, u_b and the step sizes h_x, h_f (s) come from the scheme and its
// history, and the new state (x1, v1, a1) is a linear combination of the solved
// x, u and the old state. Per scheme (state x_n, v_n, a_n at the start of the step):
//
//   be      backward Euler: h_x = h_f = dt, x_b = x_n, u_b = v_n; v1 = u, x1 = x.
//   bdf2    BDF2 with variable steps (w = dt / dt_prev):
//           y_{n+1} - (1+w)^2/(1+2w) y_n + w^2/(1+2w) y_{n-1} = (1+w)/(1+2w) dt y'_{n+1}
//           for y = x and y = v: h_x = h_f = (1+w)/(1+2w) dt (2/3 dt at a constant
//           step), x_b, u_b the combinations of x_n, x_{n-1} (v_n, v_{n-1}); v1 = u,
//           x1 = x. Without history (the first step, after -deform moved positions)
//           the step is, in linear mode, the theta method with theta = 2/3
//           (h_x = h_f = 2/3 dt: A as BDF2's, no factorisation of its own), with a_n
//           from the equation of motion; in corotational mode (A is refilled every
//           step anyway) backward Euler, which needs no a_n: after an impulsive
//           start a_n holds M^-1 b K v_n, far beyond the motion's scale, and the
//           corotational iteration stalls on the theta method's predictor.
//   newmark implicit Newmark with beta = 1/4, gamma = 1/2 (the trapezoidal rule) in
//           its implicit-midpoint form: u = (v_n + v1)/2, h_x = h_f = dt/2, x_b = x_n,
//           u_b = v_n; v1 = 2u - v_n, x1 = x_n + dt u. For linear elasticity this is
//           exactly the trapezoidal rule (same x1, v1); for corotational elasticity
//           the forces are taken at the midpoint (second order, symmetric, the
//           step's potential is an incremental potential).
//   alpha   generalized-alpha for second-order systems (Chung & Hulbert 1993, "A
//           time integration algorithm for structural dynamics with improved
//           numerical dissipation: the generalized-alpha method", J. Appl. Mech. 60):
//           M a_{1-am} + D v_{1-af} + f_el(x_{1-af}) = f, with Newmark's updates
//           x1 = x_n + dt v_n + dt^2 ((1/2 - beta) a_n + beta a1),
//           v1 = v_n + dt ((1 - gamma) a_n + gamma a1), and from rho_inf in [0, 1]
//           a_m = (2 rho - 1)/(rho + 1), a_f = rho/(rho + 1), gamma = 1/2 - a_m + a_f,
//           beta = (1 - a_m + a_f)^2 / 4. Here u = v_{1-af}, x = x_{1-af},
//           h_x = beta dt / gamma, h_f = (1 - a_f) gamma dt / (1 - a_m). It keeps the
//           acceleration a_n as history (the first step takes it from the equation
//           of motion at the initial state).
//
// References: Hairer, Norsett & Wanner, "Solving ODEs I", III.5 (variable-step
// BDF2); Newmark 1959; Chung & Hulbert 1993. Why not PETSc's TS (TSBDF, TSALPHA2,
// TSTHETA): docs/integrators.md.
#pragma once

#include <petscvec.h>

#include <array>
#include <string>
#include <utility>
#include <vector>

namespace softbody {

typedef enum { SCHEME_BE, SCHEME_BDF2, SCHEME_NEWMARK, SCHEME_ALPHA } TimeScheme;
// Names for -integrator (PetscOptionsEnum's list: names, enum name, prefix, null).
extern const char *const kTimeSchemes[];

// Generalized-alpha parameters from the spectral radius at infinite dt*omega.
struct AlphaParameters {
  PetscReal alpha_m = 0.5, alpha_f = 0.5, gamma = 0.5, beta = 0.25;
};
AlphaParameters AlphaFromRhoInf(PetscReal rho_inf);

// The vectors a step's combinations refer to: the old state x_n, v_n, a_n, the
// history of bdf2 (x_{n-1}, v_{n-1}), the solved u and x = x_b + h_x u.
enum StepVector { kXn, kXprev, kVn, kVprev, kAn, kU, kXsolved, kStepVectors };
typedef std::array<PetscReal, kStepVectors> Combination;  // coefficients, one per StepVector

struct StepCoefficients {
  PetscReal position_step = 0;  // h_x (s)
  PetscReal force_step = 0;     // h_f (s)
  // Before the solve (from x_n, x_{n-1}, v_n, v_{n-1}, a_n): x_b and u_b.
  Combination base_position{}, base_velocity{};
  // After the solve: x1, v1 and (alpha) a1.
  Combination end_position{}, end_velocity{}, end_acceleration{};
  // x1 as an affine function of the unknown alone, x1 = x_e + h_e u (x_e from
  // x_n, x_{n-1}, v_n, a_n; h_e in s): the map contact constraints act on, so
  // that they hold the step's end and not the solve's x (newmark: the
  // midpoint). be: x_e = x_n, h_e = dt; bdf2: x_e = x_b, h_e = h_x.
  Combination end_base{};
  PetscReal end_step = 0;
  bool uses_previous = false;       // needs x_{n-1}, v_{n-1}
  bool uses_acceleration = false;   // needs a_n
  bool gives_acceleration = false;  // gives a1 (end_acceleration)
  // x_b = x_n, u_b = v_n, x1 = x, v1 = u: backward Euler, nothing to combine.
  bool identity = false;
};

// A scheme's state beyond x and v (for checkpoints): its -integrator name,
// per-vertex vectors (PETSc order, 3 values per vertex, owned by the integrator)
// by dataset name, and scalars.
struct SchemeHistory {
  std::string scheme;
  std::vector<std::pair<std::string, Vec>> vectors;
  std::vector<double> scalars;
};

// Not collective. The step of `scheme` with step dt (s); previous_dt is the last
// step's size (s), 0 when the scheme has no history (bdf2 then takes a theta
// method step when theta_start, else a backward Euler step). rho_inf: alpha's
// spectral radius at infinity.
StepCoefficients SchemeStep(TimeScheme scheme, PetscReal dt, PetscReal previous_dt,
                            PetscReal rho_inf, bool theta_start);

}  // namespace softbody
