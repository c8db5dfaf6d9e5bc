// PC type "supernodal": sparse Cholesky factorisation of A by CHOLMOD's
// supernodal method (SuiteSparse; Chen, Davis, Hager & Rajamanickam 2008), on
// rank 0.
//
// A (MATAIJ, symmetric positive definite; only its upper triangle by rows is
// read) is gathered to rank 0 when there is more than one rank, ordered once
// (CHOLMOD's choice of AMD and METIS, whichever fills less), and refactorised
// numerically whenever its values change. Each application gathers the
// right-hand side to rank 0, runs the two triangular solves there and scatters
// the solution back.
//
// Why one rank: a solve with the factor streams the factor's entries twice and
// does two flops per entry, so it runs at the speed of memory. Where the ranks
// share one memory bus (one machine) a distributed factor gains nothing in the
// solve, and MUMPS's distributed solve cost 1.5 times its one-rank time on the
// 2-core machine of the README; its factorisation is faster on many ranks
// (config/direct-mumps.opts).
//
// Options (prefix of the PC): -pc_supernodal_ordering best|amd|metis.
#pragma once

#include <petscksp.h>

namespace softbody {

inline constexpr const char kPCSupernodal[] = "supernodal";

// Not collective. Registers the PC type (once).
PetscErrorCode RegisterSupernodalPC();

// Collective. Entries of the factor L after the last set-up: stored (what a
// solve streams, supernodal blocks with their explicit zeros) and structural
// nonzeros (lnz); flops of the factorisation. Zeros before any set-up.
PetscErrorCode PCSupernodalGetFactorSize(PC pc, double *stored_entries, double *nonzeros,
                                         double *factor_flops);

}  // namespace softbody
