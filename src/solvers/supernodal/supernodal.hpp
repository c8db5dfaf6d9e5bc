// PC type "supernodal": sparse Cholesky factorisation of A by CHOLMOD's
// supernodal method (SuiteSparse; Chen, Davis, Hager & Rajamanickam 2008).
//
// A (MATAIJ, symmetric positive definite; only its upper triangle by rows is
// read) is ordered once (CHOLMOD's choice of AMD and METIS, whichever fills
// less) and refactorised numerically whenever its values change. A solve
// streams the factor's entries twice (forward, backward) at two flops per entry:
// it runs at the speed of memory.
//
// One rank: CHOLMOD's factor copied into softbody's streaming layout with its
// own sweeps (tiled_factor.hpp), in double precision or single (half the
// bytes); CHOLMOD's values are released behind the copy as it
// is made and dropped after it, so a set-up peaks at about one factor in double
// (release_pages.hpp). The split factor's pieces on several ranks are copied alike.
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
// -pc_supernodal_precision double|single, and the limits within which softbody's
// default solvers keep the factor (SupernodalLimits, solver.hpp):
// -pc_supernodal_budget_mb, -pc_supernodal_max_separator.
#pragma once

#include <petscksp.h>

namespace softbody {

inline constexpr const char kPCSupernodal[] = "supernodal";

// Not collective. Registers the PC type (once).
PetscErrorCode RegisterSupernodalPC();

// Not collective. Solves in single precision (true) or double (false, the
// default); -pc_supernodal_precision overrides it at PCSetFromOptions.
PetscErrorCode PCSupernodalSetSinglePrecision(PC pc, bool single);

// Not collective. Restricts PCMatApply on one rank to the rows `rows` (local
// indices) of Y, whose values are then the full solve's bit for bit, the other
// rows left unspecified; the backward sweeps visit only the supernodes those
// rows depend on (TiledFactor::SetSolveTargets). count 0 restores full
// solves. PCApply, and PCMatApply on several ranks, are not affected.
PetscErrorCode PCSupernodalSetSolveTargets(PC pc, PetscInt count, const PetscInt rows[]);

// Collective. Entries of the factor L after the last set-up: stored (CHOLMOD's
// supernodal blocks with their explicit zeros, a little more than the copy a
// solve streams) and structural
// nonzeros (lnz; on several ranks the entries the ranks' sweeps and the dense
// separator factor stream); flops of the factorisation; bytes per entry in
// the solves (8, or 4 in single precision). Zeros before any set-up.
PetscErrorCode PCSupernodalGetFactorSize(PC pc, double *stored_entries, double *nonzeros,
                                         double *factor_flops, int *bytes_per_entry);

// When the factor is affordable (options -pc_supernodal_budget_mb and
// -pc_supernodal_max_separator).
struct SupernodalLimits {
  double budget_mb = 0;  // per rank, MB (2^20 bytes); <= 0 before the options are read
  // n_S above which rank 0's dense separator factor (n_S^3 / 3 flops, alone,
  // at every refactorisation) costs more than the split saves: 5 000 DOFs are
  // 4.2e10 flops, about 15 s on one core here, as long as one rank's whole
  // factor of the 2e5-tet beam (docs/performance.md: its 8 949 took 89 s).
  PetscInt max_separator = 5000;
};

// What a set-up would allocate, predicted from A's pattern before any of it is.
struct SupernodalPrediction {
  SupernodalLimits limits;          // the PC's, at the prediction
  bool affordable = false;          // bytes within the budget and n_S within the largest separator
  PetscInt64 separator = 0;         // n_S, DOFs of the separator (0 on one rank)
  double separator_bytes = 0;       // the separator's dense blocks, on rank 0 (the most)
  bool analysed = false;            // the symbolic factors were computed (below)
  double factor_entries = 0;        // largest rank: entries of CHOLMOD's factor (xsize)
  double factor_entries_total = 0;  // the same summed over the ranks
  // Largest rank: the factor in double while its copy for the solves replaces
  // it, and the separator's blocks, bytes (only separator_bytes when not analysed).
  double bytes = 0;
};

// Not collective. Bytes of the separator's dense blocks for n_S = separator
// (the trailing block of a rank's factor and its Schur contribution in double,
// MPI's reduction buffer, and on rank 0 the dense factor at bytes_per_entry).
double SupernodalSeparatorBytes(PetscInt64 separator, int bytes_per_entry);

// Collective. Predicts the set-up of the PC on its operator (set, type
// supernodal, options read): on several ranks counts the separator (64-bit)
// and, only when its dense blocks and n_S are within the PC's limits, builds
// the split structure and CHOLMOD's symbolic factors; on one rank the symbolic
// factor of A. The symbolic work is kept, so the next set-up on the same
// pattern does not redo it; nothing of the numeric factor is allocated.
PetscErrorCode PCSupernodalPredict(PC pc, SupernodalPrediction *prediction);

}  // namespace softbody
