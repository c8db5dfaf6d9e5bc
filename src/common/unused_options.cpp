#include "common/unused_options.hpp"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <sstream>

namespace softbody {

namespace {

// PETSc's start-up options (listed by PetscInitialize under -help, which cannot
// be replayed): known names for suggestions such as -log_veiw -> -log_view.
constexpr const char *kStartupOptions[] = {"-help",
                                           "-version",
                                           "-options_file",
                                           "-options_left",
                                           "-options_view",
                                           "-options_monitor",
                                           "-log_view",
                                           "-log_trace",
                                           "-log_exclude",
                                           "-info",
                                           "-malloc_debug",
                                           "-malloc_dump",
                                           "-malloc_view",
                                           "-malloc_info",
                                           "-memory_view",
                                           "-on_error_abort",
                                           "-fp_trap",
                                           "-start_in_debugger",
                                           "-on_error_attach_debugger",
                                           "-no_signal_handler",
                                           "-get_total_flops",
                                           "-petsc_sleep",
                                           "-debugger_ranks",
                                           "-stop_for_debugger",
                                           "-tmp",
                                           "-shared_tmp",
                                           "-not_shared_tmp"};

// Options PETSc reads only inside PetscFinalize, after this report.
constexpr const char *kReadAtFinalize[] = {"-options_view"};

// A suggestion is made when at most this many edits separate the typed name
// from a known one, counted on the name without its '-'...
constexpr size_t kMostEditsForSuggestion = 3;
// ...and at most one edit per this many characters of the typed name, so that a
// short name is not "corrected" into an unrelated one (-dx is not -dt's typo
// more than -mode's).
constexpr size_t kCharactersPerEdit = 3;

// Not collective. Runs `describe` with this process's stdout (file descriptor 1,
// where PETSc prints help: PetscHelpPrintf and the lists of types) sent to a
// temporary file, and returns what it printed.
PetscErrorCode CaptureStdout(const std::function<PetscErrorCode()> &describe, std::string *text) {
  PetscFunctionBeginUser;
  std::FILE *capture = std::tmpfile();
  PetscCheck(capture, PETSC_COMM_SELF, PETSC_ERR_FILE_OPEN, "no temporary file for the help text");
  std::fflush(stdout);
  const int saved_stdout = dup(STDOUT_FILENO);
  dup2(fileno(capture), STDOUT_FILENO);
  const PetscErrorCode status = describe();
  std::fflush(stdout);
  dup2(saved_stdout, STDOUT_FILENO);
  close(saved_stdout);
  std::rewind(capture);
  text->clear();
  for (int c; (c = std::fgetc(capture)) != EOF;) text->push_back(static_cast<char>(c));
  std::fclose(capture);
  PetscCall(status);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The option names that open lines of help text ("  -ksp_rtol <1e-05 : ...").
std::vector<std::string> NamesInHelp(const std::string &help) {
  std::vector<std::string> names;
  std::istringstream lines(help);
  std::string line;
  while (std::getline(lines, line)) {
    const size_t dash = line.find_first_not_of(' ');
    if (dash == std::string::npos || line[dash] != '-' || dash + 1 >= line.size() ||
        !std::isalpha(static_cast<unsigned char>(line[dash + 1])))
      continue;
    size_t end = dash + 1;
    while (end < line.size() &&
           (std::isalnum(static_cast<unsigned char>(line[end])) || line[end] == '_'))
      ++end;
    names.push_back(line.substr(dash, end - dash));
  }
  return names;
}

// Optimal string alignment distance: insertions, deletions, substitutions and
// transpositions of neighbouring characters each count one edit.
size_t EditDistance(const std::string &a, const std::string &b) {
  std::vector<std::vector<size_t>> d(a.size() + 1, std::vector<size_t>(b.size() + 1));
  for (size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (size_t i = 1; i <= a.size(); ++i)
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t substitution = d[i - 1][j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1);
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, substitution});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  return d[a.size()][b.size()];
}

}  // namespace

PetscErrorCode UnreadOptions(std::vector<std::string> *names) {
  PetscFunctionBeginUser;
  PetscInt count;
  char **left_names, **left_values;
  PetscCall(PetscOptionsLeftGet(nullptr, &count, &left_names, &left_values));
  names->clear();
  for (PetscInt i = 0; i < count; ++i) names->push_back(std::string("-") + left_names[i]);
  PetscCall(PetscOptionsLeftRestore(nullptr, &count, &left_names, &left_values));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode DocumentedOptions(const std::vector<Describer> &describers,
                                 std::vector<std::string> *names) {
  PetscFunctionBeginUser;
  PetscOptions help_only;
  PetscCall(PetscOptionsCreate(&help_only));
  PetscCall(PetscOptionsSetValue(help_only, "-help", nullptr));
  PetscCall(PetscOptionsPush(help_only));
  std::string help;
  const PetscErrorCode status = CaptureStdout(
      [&describers] {
        for (const Describer &describe : describers) {
          // PETSc prints each options section (prefix and title) once per run:
          // forget the sections printed so far, so that describe's are printed.
          PetscCall(PetscOptionsHelpPrintedDestroy(&PetscOptionsHelpPrintedSingleton));
          PetscCall(describe());
        }
        return PETSC_SUCCESS;
      },
      &help);
  PetscCall(PetscOptionsHelpPrintedDestroy(&PetscOptionsHelpPrintedSingleton));
  PetscCall(PetscOptionsPop());
  PetscCall(PetscOptionsDestroy(&help_only));
  PetscCall(status);
  *names = NamesInHelp(help);
  PetscFunctionReturn(PETSC_SUCCESS);
}

std::string NearestOptionName(const std::string &name, const std::vector<std::string> &candidates) {
  const std::string typed = name.substr(name.find_first_not_of('-'));
  const size_t allowed = std::min(kMostEditsForSuggestion, typed.size() / kCharactersPerEdit);
  std::string nearest;
  size_t best = allowed + 1;
  for (const std::string &candidate : candidates) {
    const size_t distance = EditDistance(typed, candidate.substr(1));
    if (distance < best) {
      best = distance;
      nearest = candidate;
    }
  }
  return nearest;
}

PetscErrorCode WarnUnusedOptions(MPI_Comm comm, const std::vector<std::string> &given,
                                 const std::vector<Describer> &describers) {
  PetscFunctionBeginUser;
  PetscBool report = PETSC_TRUE;
  PetscCall(PetscOptionsGetBool(nullptr, nullptr, "-options_left", &report, nullptr));
  if (!report) PetscFunctionReturn(PETSC_SUCCESS);
  std::vector<std::string> unread, unused;
  PetscCall(UnreadOptions(&unread));
  for (const std::string &option : given)
    if (std::find(unread.begin(), unread.end(), option) != unread.end() &&
        std::find(std::begin(kReadAtFinalize), std::end(kReadAtFinalize), option) ==
            std::end(kReadAtFinalize))
      unused.push_back(option);
  int any = !unused.empty();  // describe is collective: every rank joins when one needs it
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &any, 1, MPI_INT, MPI_MAX, comm));
  if (!any) PetscFunctionReturn(PETSC_SUCCESS);

  std::vector<std::string> known;
  PetscCall(DocumentedOptions(describers, &known));
  known.insert(known.end(), std::begin(kStartupOptions), std::end(kStartupOptions));
  std::sort(known.begin(), known.end());
  known.erase(std::unique(known.begin(), known.end()), known.end());
  for (const std::string &option : unused) {
    const std::string nearest = NearestOptionName(option, known);
    const std::string hint =
        nearest.empty() || nearest == option ? "" : " (did you mean " + nearest + "?)";
    PetscCall(PetscFPrintf(comm, PETSC_STDERR, "softbody: warning: option %s was not used%s\n",
                           option.c_str(), hint.c_str()));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
