// The linear solver for A v = b, chosen on the command line.
//
// A preset (an options file from config/, compiled in) supplies the defaults; any
// -ksp_* / -pc_* option or -options_file on the command line overrides them.
// A is symmetric positive definite with block size 3; the solver gets the six
// rigid-body modes of the given coordinates as near-null space (for GAMG).
#pragma once

#include <petscksp.h>

namespace softbody {

// Presets compiled in from config/: the defaults of linear and corotational mode.
extern const char *const kDirectPreset;        // config/direct.opts
extern const char *const kCorotationalPreset;  // config/cg-warp.opts

// Not collective. Makes softbody's own PC types known to PETSc (once):
// "supernodal" (supernodal.hpp) and "warp" (warp_preconditioner.hpp).
PetscErrorCode RegisterPreconditioners();

// Collective. Inserts the preset's options where the command line sets none.
PetscErrorCode ApplyPresetDefaults(const char *preset);

// Collective. KSP on A (marked SPD), near-null space from coordinates
// (block size 3), options from the database.
PetscErrorCode CreateSolver(Mat A, Vec coordinates, KSP *ksp);

}  // namespace softbody
