// The linear solver for A v = b, chosen on the command line.
//
// A preset (an options file from config/, compiled in) supplies the defaults; any
// -ksp_* / -pc_* option or -options_file on the command line overrides them.
// A is symmetric positive definite with block size 3; the solver gets the six
// rigid-body modes of the given coordinates as near-null space (for GAMG).
#pragma once

#include <petscksp.h>

#include <string>

namespace softbody {

// Presets compiled in from config/: the defaults of linear and corotational mode,
// and the scalable solver the supernodal factor gives way to.
extern const char *const kDirectPreset;        // config/direct.opts
extern const char *const kCorotationalPreset;  // config/cg-warp.opts
extern const char *const kScalablePreset;      // config/cg-gamg.opts

// The supernodal factor while it is affordable, else multigrid: what a
// supernodal PC was predicted to need and what it became.
struct SolverChoice {
  bool checked = false;   // the PC was supernodal, its set-up predicted
  bool scalable = false;  // over its limits: now GAMG (the KSP CG where it was preonly)
  std::string reason;     // for the run summary, e.g. "CG + GAMG: the split factor's ..."
};

// Collective. When pc is of type supernodal (options read, operator set):
// predicts its set-up (PCSupernodalPredict) before anything is allocated; over
// its limits (-pc_supernodal_budget_mb, -pc_supernodal_max_separator) sets the
// options database so that pc becomes GAMG (block size 3 and the near-null
// space of its operator) and, when ksp is given and preonly, ksp becomes CG
// with config/cg-gamg.opts's settings where the command line sets none, and
// reads them (KSPSetFromOptions, or PCSetFromOptions without ksp). Any other PC
// is left alone (choice->checked false).
PetscErrorCode ChooseFactorOrMultigrid(KSP ksp, PC pc, SolverChoice *choice);

// Not collective. Makes softbody's own PC types known to PETSc (once):
// "supernodal" (supernodal.hpp) and "warp" (warp_preconditioner.hpp).
PetscErrorCode RegisterPreconditioners();

// Collective. Inserts the preset's options where the command line sets none.
PetscErrorCode ApplyPresetDefaults(const char *preset);

// Collective. KSP on A (marked SPD), near-null space from coordinates
// (block size 3), options from the database; a supernodal PC only within its
// limits (ChooseFactorOrMultigrid; what was chosen and why in *choice).
PetscErrorCode CreateSolver(Mat A, Vec coordinates, KSP *ksp, SolverChoice *choice);

}  // namespace softbody
