// Options nothing read: a typo is reported, not silently ignored.
//
// PETSc marks every option of its database that a query reads. At the end of a
// run the options the user gave (command line, -options_file, PETSC_OPTIONS)
// that nothing read are reported by rank 0 on stderr, one line each, with the
// nearest option name the program knows:
//     softbody: warning: option -ksp_rtoll was not used (did you mean -ksp_rtol?)
// The known names are the ones the program's own option calls document under
// -help: describers replay them against a private database holding only
// -help, with stdout captured, so neither the user's options nor the screen
// are touched. `-options_left 0` silences the report; `-options_left`
// (true) keeps PETSc's own listing at PetscFinalize as well.
#pragma once

#include <petscsys.h>

#include <functional>
#include <string>
#include <vector>

namespace softbody {

// Not collective. The names (with their leading '-') of the database's options
// that no query has read so far. Taken at the start of a run, before any preset
// is inserted, it is the set of options the user gave.
PetscErrorCode UnreadOptions(std::vector<std::string> *names);

// Collective. Reads options (PetscOptionsBegin/End blocks, *SetFromOptions of
// objects created for the purpose) into throwaway variables.
using Describer = std::function<PetscErrorCode()>;

// Collective. The option names (with '-') that the describers document when
// -help is set: they run with a private options database holding only -help
// pushed as the default, and what they print on stdout is captured instead. The
// names are complete on rank 0 (PETSc prints help there only).
PetscErrorCode DocumentedOptions(const std::vector<Describer> &describers,
                                 std::vector<std::string> *names);

// Not collective. The candidate closest to `name` by edit distance (insertion,
// deletion, substitution, transposition of neighbours), or "" when none is close
// enough to be a likely typo.
std::string NearestOptionName(const std::string &name, const std::vector<std::string> &candidates);

// Collective. Rank 0 prints one warning line on stderr for every option of
// `given` (see UnreadOptions) that is still unread, with the nearest name among
// those the describers document and PETSc's start-up options; nothing with
// -options_left 0. Returns without calling the describers when every option was
// read.
PetscErrorCode WarnUnusedOptions(MPI_Comm comm, const std::vector<std::string> &given,
                                 const std::vector<Describer> &describers);

}  // namespace softbody
