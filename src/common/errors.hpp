// Error model of softbody.
//
// Parsers and validators throw InputError with a message that names the file and
// line (or the option) at fault. At the module boundary (the PetscErrorCode
// functions) the exception becomes a PETSc error of class PETSC_ERR_USER_INPUT.
// The handler installed by InstallErrorHandler() prints such an error, and a
// linear solve that did not converge (PETSC_ERR_NOT_CONVERGED), as one line,
// "softbody: error: <message>", on rank 0 only; every other PETSc error keeps
// PETSc's usual traceback. Input read by one rank is broadcast with its verdict, and
// input every rank reads is the same on every rank, so every rank raises the same
// input error and all of them exit non-zero without waiting on each other.
#pragma once

#include <petscsys.h>

#include <new>
#include <stdexcept>
#include <string>

namespace softbody {

class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "path:line: what" (line <= 0 leaves the line out).
std::string Where(const std::string &path, long line, const std::string &what);

// Not collective. Installs the one-line handler for user-input errors.
PetscErrorCode InstallErrorHandler();

// A tool's whole main: PetscInitialize with `help`, the one-line error handler,
// run(PETSC_COMM_WORLD, argc, argv), PetscFinalize; returns the exit status (0
// when run succeeded).
using ToolBody = PetscErrorCode (*)(MPI_Comm comm, int argc, char **argv);
int RunTool(int argc, char **argv, const char *help, ToolBody run);

}  // namespace softbody

// Runs `statement`; an InputError it throws becomes a collective PETSc user-input
// error on `comm`. Use only in functions returning PetscErrorCode.
#define SOFTBODY_CATCH_INPUT(comm, statement)                            \
  do {                                                                   \
    try {                                                                \
      statement;                                                         \
    } catch (const softbody::InputError &input_error_) {                 \
      SETERRQ(comm, PETSC_ERR_USER_INPUT, "%s", input_error_.what());    \
    } catch (const std::bad_alloc &) {                                   \
      SETERRQ(comm, PETSC_ERR_MEM, "out of memory while reading input"); \
    }                                                                    \
  } while (0)
