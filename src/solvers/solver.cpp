#include "solvers/solver.hpp"

#include <sstream>
#include <string>

#include "solvers/supernodal/supernodal.hpp"
#include "solvers/warp/warp_preconditioner.hpp"

namespace softbody {

PetscErrorCode RegisterPreconditioners() {
  PetscFunctionBeginUser;
  PetscCall(RegisterSupernodalPC());
  PetscCall(RegisterWarpPC());
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ApplyPresetDefaults(const char *preset) {
  PetscFunctionBeginUser;
  PetscCall(RegisterPreconditioners());
  // PetscOptionsInsertString knows no comments: drop them line by line.
  std::istringstream lines(preset);
  std::string line, options;
  while (std::getline(lines, line)) options += line.substr(0, line.find('#')) + ' ';
  PetscCall(PetscOptionsInsertString(nullptr, options.c_str()));
  // Re-insert the command line (and its -options_file) so that it wins.
  int argc = 0;
  char **argv = nullptr;
  PetscCall(PetscGetArgs(&argc, &argv));
  PetscCall(PetscOptionsInsert(nullptr, &argc, &argv, nullptr));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CreateSolver(Mat A, Vec coordinates, KSP *ksp) {
  PetscFunctionBeginUser;
  PetscCall(RegisterPreconditioners());
  PetscCall(MatSetOption(A, MAT_SPD, PETSC_TRUE));
  PetscCall(MatSetOption(A, MAT_SPD_ETERNAL, PETSC_TRUE));
  MatNullSpace rigid_body_modes;
  PetscCall(MatNullSpaceCreateRigidBody(coordinates, &rigid_body_modes));
  PetscCall(MatSetNearNullSpace(A, rigid_body_modes));
  PetscCall(MatNullSpaceDestroy(&rigid_body_modes));
  PetscCall(KSPCreate(PetscObjectComm((PetscObject)A), ksp));
  PetscCall(KSPSetOperators(*ksp, A, A));
  PetscCall(KSPSetFromOptions(*ksp));
  // Iterative solvers start from the previous velocity (the solution vector's
  // content); a direct solve ignores any guess.
  PetscBool preonly;
  PetscCall(PetscObjectTypeCompare((PetscObject)*ksp, KSPPREONLY, &preonly));
  // The warp preconditioner starts from zero (warp_preconditioner.hpp);
  // -ksp_initial_guess_nonzero decides where given.
  PetscBool guess_set, warp;
  PC pc;
  PetscCall(KSPGetPC(*ksp, &pc));
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCWarp, &warp));
  PetscCall(PetscOptionsHasName(nullptr, nullptr, "-ksp_initial_guess_nonzero", &guess_set));
  if (!preonly && !guess_set)
    PetscCall(KSPSetInitialGuessNonzero(*ksp, warp ? PETSC_FALSE : PETSC_TRUE));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
