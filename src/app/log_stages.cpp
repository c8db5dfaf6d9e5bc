#include "app/log_stages.hpp"

namespace softbody {

namespace {
LogStages stages;
}

PetscErrorCode RegisterLogStages() {
  PetscFunctionBeginUser;
  if (stages.setup >= 0) PetscFunctionReturn(PETSC_SUCCESS);
  PetscCall(PetscLogStageRegister("Set-up", &stages.setup));
  PetscCall(PetscLogStageRegister("Assembly", &stages.assembly));
  PetscCall(PetscLogStageRegister("Factorisation", &stages.factorisation));
  PetscCall(PetscLogStageRegister("Step", &stages.step));
  PetscCall(PetscLogStageRegister("Contact", &stages.contact));
  PetscCall(PetscLogStageRegister("Output", &stages.output));
  PetscFunctionReturn(PETSC_SUCCESS);
}

const LogStages &Stages() {
  return stages;
}

}  // namespace softbody
