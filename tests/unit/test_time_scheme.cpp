// The time schemes' coefficients (solvers/time_scheme.hpp) against independent
// facts: Chung & Hulbert's parameters at rho_inf = 0.5 (their closed forms give
// alpha_m = 0, alpha_f = 1/3, gamma = 5/6, beta = 4/9), generalized-alpha at
// rho_inf = 1 being the trapezoidal rule, BDF2's textbook coefficients at a
// constant and at a doubled step, and every second-order scheme integrating a
// uniformly accelerated motion x(t) = x0 + v0 t + g t^2 / 2 exactly.
#include <gtest/gtest.h>

#include <cmath>

#include "solvers/time_scheme.hpp"

namespace softbody {
namespace {

// Round-off of a handful of operations on numbers of order one.
constexpr double kTight = 1e-14;

TEST(TimeScheme, AlphaParametersAtRhoInfOneHalf) {
  const AlphaParameters p = AlphaFromRhoInf(0.5);
  EXPECT_NEAR(p.alpha_m, 0.0, kTight);
  EXPECT_NEAR(p.alpha_f, 1.0 / 3.0, kTight);
  EXPECT_NEAR(p.gamma, 5.0 / 6.0, kTight);
  EXPECT_NEAR(p.beta, 4.0 / 9.0, kTight);
}

TEST(TimeScheme, AlphaAtRhoInfOneIsNewmark) {
  const double dt = 0.01;
  const StepCoefficients alpha = SchemeStep(SCHEME_ALPHA, dt, dt, 1.0, true);
  const StepCoefficients newmark = SchemeStep(SCHEME_NEWMARK, dt, dt, 0.9, true);
  EXPECT_NEAR(alpha.position_step, newmark.position_step, kTight * dt);
  EXPECT_NEAR(alpha.force_step, newmark.force_step, kTight * dt);
  for (int i = 0; i < kStepVectors; ++i) {
    EXPECT_NEAR(alpha.base_position[i], newmark.base_position[i], kTight) << i;
    EXPECT_NEAR(alpha.base_velocity[i], newmark.base_velocity[i], kTight) << i;
    EXPECT_NEAR(alpha.end_position[i], newmark.end_position[i], kTight) << i;
    EXPECT_NEAR(alpha.end_velocity[i], newmark.end_velocity[i], kTight) << i;
  }
}

TEST(TimeScheme, Bdf2Coefficients) {
  // Constant step: y1 - 4/3 y0 + 1/3 y_-1 = 2/3 dt y1'.
  const StepCoefficients constant = SchemeStep(SCHEME_BDF2, 0.3, 0.3, 0.9, true);
  EXPECT_NEAR(constant.base_position[kXn], 4.0 / 3.0, kTight);
  EXPECT_NEAR(constant.base_position[kXprev], -1.0 / 3.0, kTight);
  EXPECT_NEAR(constant.base_velocity[kVn], 4.0 / 3.0, kTight);
  EXPECT_NEAR(constant.base_velocity[kVprev], -1.0 / 3.0, kTight);
  EXPECT_NEAR(constant.position_step, 0.2, kTight);
  // Doubled step (w = 2): y1 - 9/5 y0 + 4/5 y_-1 = 3/5 dt y1'.
  const StepCoefficients doubled = SchemeStep(SCHEME_BDF2, 0.2, 0.1, 0.9, true);
  EXPECT_NEAR(doubled.base_position[kXn], 9.0 / 5.0, kTight);
  EXPECT_NEAR(doubled.base_position[kXprev], -4.0 / 5.0, kTight);
  EXPECT_NEAR(doubled.position_step, 0.12, kTight);
  // Without history: the theta start (A as BDF2's) or backward Euler.
  EXPECT_NEAR(SchemeStep(SCHEME_BDF2, 0.3, 0, 0.9, true).position_step, 0.2, kTight);
  EXPECT_TRUE(SchemeStep(SCHEME_BDF2, 0.3, 0, 0.9, false).identity);
}

// One step of a scheme on x'' = g (M = 1, no stiffness, no damping) from the exact
// state of x(t) = x0 + v0 t + g t^2 / 2 at t = 0 (history at t = -previous_dt).
void ExpectExactForUniformAcceleration(TimeScheme scheme, double dt, double previous_dt) {
  const double x0 = 0.3, v0 = -1.7, g = 9.81;
  const StepCoefficients s = SchemeStep(scheme, dt, previous_dt, 0.7, true);
  std::array<double, kStepVectors> state{};
  state[kXn] = x0;
  state[kVn] = v0;
  state[kXprev] = x0 - v0 * previous_dt + 0.5 * g * previous_dt * previous_dt;
  state[kVprev] = v0 - g * previous_dt;
  state[kAn] = g;
  double xb = 0, ub = 0;
  for (int i = 0; i < kStepVectors; ++i) {
    xb += s.base_position[i] * state[i];
    ub += s.base_velocity[i] * state[i];
  }
  // M (u - u_b) = h_f g, x = x_b + h_x u.
  state[kU] = ub + s.force_step * g;
  state[kXsolved] = xb + s.position_step * state[kU];
  double x1 = 0, v1 = 0;
  for (int i = 0; i < kStepVectors; ++i) {
    x1 += s.end_position[i] * state[i];
    v1 += s.end_velocity[i] * state[i];
  }
  EXPECT_NEAR(x1, x0 + v0 * dt + 0.5 * g * dt * dt, 1e-13) << kTimeSchemes[scheme];
  EXPECT_NEAR(v1, v0 + g * dt, 1e-13) << kTimeSchemes[scheme];
}

TEST(TimeScheme, SecondOrderSchemesExactForUniformAcceleration) {
  for (TimeScheme scheme : {SCHEME_BDF2, SCHEME_NEWMARK, SCHEME_ALPHA}) {
    ExpectExactForUniformAcceleration(scheme, 0.01, 0.01);
    ExpectExactForUniformAcceleration(scheme, 0.02, 0.005);
  }
}

// The end map x1 = x_e + h_e u (what contact constraints act on) against the
// scheme's own x1 from the solved x = x_b + h_x u, for arbitrary states and u,
// and its known forms: be x_e = x_n, h_e = dt; newmark x_e = x_n, h_e = dt (not
// the solve's midpoint, h_x = dt/2).
TEST(TimeScheme, EndMapGivesTheSchemesEndPosition) {
  const double dt = 0.02;
  for (TimeScheme scheme : {SCHEME_BE, SCHEME_BDF2, SCHEME_NEWMARK, SCHEME_ALPHA})
    for (const double previous_dt : {0.0, 0.01, 0.02}) {
      const StepCoefficients s = SchemeStep(scheme, dt, previous_dt, 0.6, true);
      std::array<double, kStepVectors> state{};
      state[kXn] = 0.3;
      state[kXprev] = 0.25;
      state[kVn] = -1.7;
      state[kVprev] = 2.1;
      state[kAn] = 9.81;
      for (const double u : {-3.0, 0.0, 4.5}) {
        double xb = 0, xe = 0;
        for (int i = 0; i < kStepVectors; ++i) {
          xb += s.base_position[i] * state[i];
          xe += s.end_base[i] * state[i];
        }
        state[kU] = u;
        state[kXsolved] = xb + s.position_step * u;
        double x1 = 0;
        for (int i = 0; i < kStepVectors; ++i) x1 += s.end_position[i] * state[i];
        EXPECT_NEAR(xe + s.end_step * u, x1, kTight) << kTimeSchemes[scheme] << " " << previous_dt;
      }
    }
  const StepCoefficients be = SchemeStep(SCHEME_BE, dt, 0, 0.9, true);
  const StepCoefficients newmark = SchemeStep(SCHEME_NEWMARK, dt, dt, 0.9, true);
  for (const StepCoefficients &s : {be, newmark}) {
    EXPECT_NEAR(s.end_step, dt, kTight * dt);
    for (int i = 0; i < kStepVectors; ++i) EXPECT_EQ(s.end_base[i], i == kXn ? 1.0 : 0.0) << i;
  }
  EXPECT_NEAR(newmark.position_step, dt / 2, kTight * dt);
}

}  // namespace
}  // namespace softbody
