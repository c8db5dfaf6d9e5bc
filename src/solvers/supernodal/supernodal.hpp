// PC type "supernodal": sparse Cholesky factorisation of A by CHOLMOD's
// supernodal method (SuiteSparse; Chen, Davis, Hager & Rajamanickam 2008).
//
// A (MATAIJ, symmetric positive definite; only its upper triangle by rows is
// read) is ordered once (CHOLMOD's choice of AMD and METIS, whichever fills
// less) and refactorised numerically whenever its values change. A solve
// streams the factor's entries twice (forward, backward) at two flops per entry:
// it runs at the speed of memory.
//
// One rank: CHOLMOD's factor and solve (double precision), or a single-precision
// copy of the factor with softbody's own sweeps (half the bytes).
// Several ranks: the factor is split at a separator (the DOFs coupled to a
// higher rank): every rank factors the piece of A of its own interior plus the
// separator, rank 0 the separator's dense Schur complement, and a solve sweeps
// all interiors at once (each rank streaming its own part of the factor, the
// ranks' memory bandwidths adding up) around one small dense solve on rank 0
// (supernodal.cpp, struct Split). A separator of a few thousand DOFs suits a few
// ranks; MUMPS (config/direct-mumps.opts) for many.
//
// A matrix that is not numerically positive definite fails the set-up on every
// rank together (PCGetFailedReason: PC_FACTOR_NUMERIC_ZEROPIVOT; applications
// return NaN), so the KSP stops with DIVERGED_PC_FAILED everywhere.
//
// Options (prefix of the PC): -pc_supernodal_ordering best|amd|metis,
// -pc_supernodal_precision double|single.
#pragma once

#include <petscksp.h>

namespace softbody {

inline constexpr const char kPCSupernodal[] = "supernodal";

// Not collective. Registers the PC type (once).
PetscErrorCode RegisterSupernodalPC();

// Not collective. Solves in single precision (true) or double (false, the
// default); -pc_supernodal_precision overrides it at PCSetFromOptions.
PetscErrorCode PCSupernodalSetSinglePrecision(PC pc, bool single);

// Collective. Entries of the factor L after the last set-up: stored (what a
// solve streams, supernodal blocks with their explicit zeros) and structural
// nonzeros (lnz; on several ranks the entries the ranks' sweeps and the dense
// separator factor stream); flops of the factorisation; bytes per entry in
// the solves (8, or 4 in single precision). Zeros before any set-up.
PetscErrorCode PCSupernodalGetFactorSize(PC pc, double *stored_entries, double *nonzeros,
                                         double *factor_flops, int *bytes_per_entry);

}  // namespace softbody
