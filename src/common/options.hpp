// Checking option values before PETSc parses them.
//
// PETSc's own parser stops with a traceback on a malformed value (and from inside
// a PetscOptionsBegin/End block it cannot even unwind cleanly). Every module
// therefore checks the syntax of its options first, so that "-dt abc" is a one-line
// user error naming the option, like every other input error.
#pragma once

#include <petscsys.h>

#include <initializer_list>

namespace softbody {

struct OptionSyntax {
  enum Kind { kReal, kRealList, kInteger, kChoice, kBool } kind;  // kRealList: comma-separated
  const char *name;                                               // "-dt"
  const char *const *choices = nullptr;  // kChoice: PetscOptionsEnum-style list
};

// Collective. Fails with PETSC_ERR_USER_INPUT "option -dt: 'abc' is not a
// number" for a value that does not parse (reals must also be finite).
PetscErrorCode CheckOptionSyntax(MPI_Comm comm, std::initializer_list<OptionSyntax> options);

}  // namespace softbody
