#include "solvers/time_scheme.hpp"

namespace softbody {

const char *const kTimeSchemes[] = {"be",         "bdf2",    "newmark", "alpha",
                                    "TimeScheme", "SCHEME_", nullptr};

AlphaParameters AlphaFromRhoInf(PetscReal rho_inf) {
  AlphaParameters p;
  p.alpha_m = (2 * rho_inf - 1) / (rho_inf + 1);
  p.alpha_f = rho_inf / (rho_inf + 1);
  p.gamma = 0.5 - p.alpha_m + p.alpha_f;
  const PetscReal shift = 1 - p.alpha_m + p.alpha_f;
  p.beta = 0.25 * shift * shift;
  return p;
}

namespace {

// BDF2's start: the theta method with theta = 2/3 has BDF2's step sizes at a
// constant dt (h = 2/3 dt), so the first step needs no factorisation of its own;
// it is A-stable and its local error O(dt^2) leaves the global error O(dt^2).
constexpr PetscReal kBdf2StartTheta = 2.0 / 3.0;

StepCoefficients BackwardEuler(PetscReal dt) {
  StepCoefficients s;
  s.position_step = s.force_step = dt;
  s.base_position[kXn] = 1;
  s.base_velocity[kVn] = 1;
  s.end_position[kXsolved] = 1;
  s.end_velocity[kU] = 1;
  s.identity = true;
  return s;
}

// The theta method on x' = v, M v' = F: x1 = x_n + dt (theta v1 + (1 - theta) v_n),
// v1 = v_n + dt (theta a1 + (1 - theta) a_n): h_x = h_f = theta dt,
// x_b = x_n + (1 - theta) dt v_n, u_b = v_n + (1 - theta) dt a_n.
StepCoefficients Theta(PetscReal dt, PetscReal theta) {
  StepCoefficients s;
  s.position_step = s.force_step = theta * dt;
  s.base_position[kXn] = 1;
  s.base_position[kVn] = (1 - theta) * dt;
  s.base_velocity[kVn] = 1;
  s.base_velocity[kAn] = (1 - theta) * dt;
  s.end_position[kXsolved] = 1;
  s.end_velocity[kU] = 1;
  s.uses_acceleration = true;
  return s;
}

// Variable-step BDF2 (time_scheme.hpp), w = dt / previous_dt; without history
// the theta method with theta = 2/3 (A as BDF2's at a constant step) or
// backward Euler.
StepCoefficients Bdf2(PetscReal dt, PetscReal previous_dt, bool theta_start) {
  if (previous_dt <= 0) return theta_start ? Theta(dt, kBdf2StartTheta) : BackwardEuler(dt);
  const PetscReal w = dt / previous_dt, denominator = 1 + 2 * w;
  const PetscReal current = (1 + w) * (1 + w) / denominator, previous = -w * w / denominator;
  StepCoefficients s;
  s.position_step = s.force_step = (1 + w) / denominator * dt;
  s.base_position[kXn] = s.base_velocity[kVn] = current;
  s.base_position[kXprev] = s.base_velocity[kVprev] = previous;
  s.end_position[kXsolved] = 1;
  s.end_velocity[kU] = 1;
  s.uses_previous = true;
  return s;
}

// Implicit midpoint form of Newmark (1/4, 1/2): u = (v_n + v1) / 2.
StepCoefficients Newmark(PetscReal dt) {
  StepCoefficients s;
  s.position_step = s.force_step = 0.5 * dt;
  s.base_position[kXn] = 1;
  s.base_velocity[kVn] = 1;
  s.end_position[kXn] = 1;
  s.end_position[kU] = dt;
  s.end_velocity[kVn] = -1;
  s.end_velocity[kU] = 2;
  return s;
}

// Generalized-alpha with u = v_{1-af}, x = x_{1-af} (time_scheme.hpp).
StepCoefficients GeneralizedAlpha(PetscReal dt, PetscReal rho_inf) {
  const AlphaParameters p = AlphaFromRhoInf(rho_inf);
  const PetscReal af = p.alpha_f, am = p.alpha_m, g = p.gamma, b = p.beta;
  StepCoefficients s;
  s.position_step = b * dt / g;
  s.force_step = (1 - af) * g * dt / (1 - am);
  const PetscReal hx = s.position_step, hf = s.force_step;
  // Predictors v_p = v_n + (1-af)(1-g) dt a_n, x_p = x_n + (1-af)(dt v_n + dt^2 (1/2-b) a_n);
  // x_b = x_p - h_x v_p, u_b = v_p - h_f a_m a_n.
  s.base_position[kXn] = 1;
  s.base_position[kVn] = (1 - af) * dt - hx;
  s.base_position[kAn] = (1 - af) * dt * dt * (0.5 - b) - hx * (1 - af) * (1 - g) * dt;
  s.base_velocity[kVn] = 1;
  s.base_velocity[kAn] = (1 - af) * (1 - g) * dt - hf * am;
  // a1 = (u - v_p) / ((1-af) g dt); Newmark's updates of x and v with it.
  const PetscReal to_acceleration = 1 / ((1 - af) * g * dt);
  s.end_acceleration[kU] = to_acceleration;
  s.end_acceleration[kVn] = -to_acceleration;
  s.end_acceleration[kAn] = -(1 - g) / g;
  s.end_velocity[kU] = 1 / (1 - af);
  s.end_velocity[kVn] = 1 - 1 / (1 - af);
  s.end_position[kXn] = 1;
  s.end_position[kVn] = dt - b * dt * dt * to_acceleration;
  s.end_position[kAn] = dt * dt * (0.5 - b) - b * dt * dt * (1 - g) / g;
  s.end_position[kU] = b * dt * dt * to_acceleration;
  s.uses_acceleration = true;
  s.gives_acceleration = true;
  return s;
}

// x1 = end_position(x_n, ..., u, x_b + h_x u) written as x_e + h_e u.
StepCoefficients WithEndMap(StepCoefficients s) {
  const PetscReal through_solved = s.end_position[kXsolved];
  s.end_step = s.end_position[kU] + through_solved * s.position_step;
  for (int k = 0; k < kStepVectors; ++k)
    s.end_base[k] = s.end_position[k] + through_solved * s.base_position[k];
  s.end_base[kU] = s.end_base[kXsolved] = 0;
  return s;
}

StepCoefficients SchemeOf(TimeScheme scheme, PetscReal dt, PetscReal previous_dt, PetscReal rho_inf,
                          bool theta_start) {
  switch (scheme) {
    case SCHEME_BDF2:
      return Bdf2(dt, previous_dt, theta_start);
    case SCHEME_NEWMARK:
      return Newmark(dt);
    case SCHEME_ALPHA:
      return GeneralizedAlpha(dt, rho_inf);
    case SCHEME_BE:
    default:
      return BackwardEuler(dt);
  }
}

}  // namespace

StepCoefficients SchemeStep(TimeScheme scheme, PetscReal dt, PetscReal previous_dt,
                            PetscReal rho_inf, bool theta_start) {
  return WithEndMap(SchemeOf(scheme, dt, previous_dt, rho_inf, theta_start));
}

}  // namespace softbody
