#include "common/errors.hpp"

#include <cstdio>

#include "app/run_control.hpp"

namespace softbody {

std::string Where(const std::string &path, long line, const std::string &what) {
  if (line <= 0) return path + ": " + what;
  return path + ":" + std::to_string(line) + ": " + what;
}

namespace {

PetscErrorCode OneLineInputErrorHandler(MPI_Comm comm, int line, const char *function,
                                        const char *file, PetscErrorCode code, PetscErrorType type,
                                        const char *message, void *ctx) {
  if (code != PETSC_ERR_USER_INPUT && code != PETSC_ERR_NOT_CONVERGED)
    return PetscTraceBackErrorHandler(comm, line, function, file, code, type, message, ctx);
  if (type == PETSC_ERROR_INITIAL) {
    PetscMPIInt rank = 0;
    MPI_Comm_rank(comm, &rank);
    if (rank == 0) {
      EndProgressLine();
      std::fprintf(stderr, "softbody: error: %s\n", message);
      std::fflush(stderr);
    }
  }
  return code;
}

}  // namespace

PetscErrorCode InstallErrorHandler() {
  PetscFunctionBeginUser;
  PetscCall(PetscPushErrorHandler(OneLineInputErrorHandler, nullptr));
  PetscFunctionReturn(PETSC_SUCCESS);
}

int RunTool(int argc, char **argv, const char *help, ToolBody run) {
  PetscCall(PetscInitialize(&argc, &argv, nullptr, help));
  PetscCall(InstallErrorHandler());
  const PetscErrorCode status = run(PETSC_COMM_WORLD, argc, argv);
  PetscCall(PetscFinalize());
  return status == PETSC_SUCCESS ? 0 : 1;
}

}  // namespace softbody
