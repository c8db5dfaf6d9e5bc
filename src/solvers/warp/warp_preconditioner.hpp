// PC type "warp": the linear system's factorisation, rotated per vertex, as
// preconditioner of the corotational system (the "warped" preconditioner of
// SOFA's corotational solvers; Mueller & Gross 2004 use the same warping for
// the stiffness itself).
//
// The corotational A(R) = (1 + a dt) M + (b dt + dt^2) sum_e R_e K_e R_e^T
// differs from the linear A0 = (1 + a dt) M + (b dt + dt^2) K mostly by the
// rotations. With one rotation R_v per vertex (the polar rotation of the
// volume-weighted mean deformation gradient of its tets) and
// Q = blockdiag(R_v),
//     A(R) ~ Q A0 Q^T,   so   P^-1 = Q A0^-1 Q^T,
// which is symmetric positive definite (CG can use it) and exact where a
// neighbourhood turns rigidly. A0 is factorised once per time step size by the
// inner PC (options prefix -warp_, default -warp_pc_type supernodal in single
// precision: half the bytes per solve, and a preconditioner needs no more;
// GAMG's cycle instead where the factor is over its limits, solver.hpp); a
// step costs the rotations and, per CG iteration, two block-diagonal products and
// one pair of triangular solves.
//
// CG with this preconditioner starts from zero (solver.cpp) unless
// -ksp_initial_guess_nonzero is given: its first application is about as good a
// start as the previous velocity, and with a non-zero start PETSc's tolerance
// test, relative to |B b|, costs one more application per solve.
#pragma once

#include <petscksp.h>

#include "solvers/solver.hpp"

namespace softbody {

inline constexpr const char kPCWarp[] = "warp";

// Not collective. Registers the PC type (once).
PetscErrorCode RegisterWarpPC();

// Collective. The linear matrix A0 (same layout as A); its inner factorisation is
// redone at the next set-up whenever A0's values have changed.
PetscErrorCode PCWarpSetLinearOperator(PC pc, Mat linear);

// Not collective. Per owned vertex a rotation, 9 values row-major (the
// preconditioner applies R_v^T, then A0^-1, then R_v); copied.
PetscErrorCode PCWarpSetRotations(PC pc, PetscInt vertices, const double *rotations);

// Not collective. What the inner PC became at the first set-up (the factor
// while affordable, else GAMG: ChooseFactorOrMultigrid); empty before.
PetscErrorCode PCWarpGetInnerChoice(PC pc, SolverChoice *choice);

// Collective. The inner PC (factor of A0); null before PCSetUp.
PetscErrorCode PCWarpGetInnerPC(PC pc, PC *inner);

}  // namespace softbody
