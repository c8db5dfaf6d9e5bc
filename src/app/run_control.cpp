#include "app/run_control.hpp"

#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "common/options.hpp"

namespace softbody {

namespace {

// Shortest time between two updates of the progress line (s): four a second
// reads as live without flooding a slow terminal or a log file.
constexpr double kProgressInterval = 0.25;
// Durations above this (s, about four months) print as "?": an ETA that long
// comes from a rate measured over too few steps.
constexpr double kLongestDuration = 1e7;

volatile std::sig_atomic_t g_stop_signal = 0;
bool g_line_open = false;  // rank 0: a progress line without its newline yet

extern "C" void RecordStopSignal(int signal) {
  if (g_stop_signal) {  // the second one: stop now, as the default action would
    std::signal(signal, SIG_DFL);
    std::raise(signal);
    return;
  }
  g_stop_signal = signal;
}

// "12 s", "3 min 20 s", "2 h 05 min".
std::string Duration(double seconds) {
  char text[32];
  if (!(seconds >= 0) || seconds > kLongestDuration) return "?";
  const long s = static_cast<long>(seconds + 0.5);
  if (s < 60)
    std::snprintf(text, sizeof(text), "%ld s", s);
  else if (s < 3600)
    std::snprintf(text, sizeof(text), "%ld min %02ld s", s / 60, s % 60);
  else
    std::snprintf(text, sizeof(text), "%ld h %02ld min", s / 3600, (s % 3600) / 60);
  return text;
}

// Whether stderr reaches a terminal: directly, or through mpirun, which passes
// the ranks' stderr through a pipe and writes it to its own stderr (a rank's
// parent is mpirun on mpirun's node; Linux: /proc/<parent>/fd/2).
bool StderrIsTerminal() {
  if (isatty(STDERR_FILENO)) return true;
  if (!std::getenv("OMPI_COMM_WORLD_SIZE")) return false;
  char link[64], target[256];
  std::snprintf(link, sizeof(link), "/proc/%d/fd/2", static_cast<int>(getppid()));
  const ssize_t length = readlink(link, target, sizeof(target) - 1);
  if (length <= 0) return false;
  target[length] = '\0';
  return std::strncmp(target, "/dev/pts/", 9) == 0 || std::strncmp(target, "/dev/tty", 8) == 0;
}

}  // namespace

PetscErrorCode ProcessRunControlOptions(MPI_Comm comm, RunControlOptions *o) {
  PetscFunctionBeginUser;
  PetscBool progress_set = PETSC_FALSE;
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kBool, "-quiet"},
                                     {OptionSyntax::kBool, "-progress"},
                                     {OptionSyntax::kBool, "-log_rank_messages"}}));
  PetscOptionsBegin(comm, nullptr, "Run control", nullptr);
  PetscCall(PetscOptionsBool("-quiet",
                             "Print nothing but errors (no run summary, no progress line)", nullptr,
                             o->quiet, &o->quiet, nullptr));
  PetscCall(
      PetscOptionsBool("-progress",
                       "Progress line on stderr (step, time, steps/s, ETA, solver iterations); "
                       "default: when stderr is a terminal and not -quiet",
                       nullptr, o->progress, &o->progress, &progress_set));
  PetscCall(PetscOptionsBool(
      "-log_rank_messages",
      "At the end, one line per rank: the point-to-point messages and bytes PETSc logged on it "
      "(half of those sent and received, as -log_view counts them; also with -quiet)",
      nullptr, o->rank_messages, &o->rank_messages, nullptr));
  PetscOptionsEnd();
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (!progress_set)
    o->progress = rank == 0 && !o->quiet && StderrIsTerminal() ? PETSC_TRUE : PETSC_FALSE;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode InstallStopHandlers() {
  PetscFunctionBeginUser;
  struct sigaction action = {};
  action.sa_handler = RecordStopSignal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;
  for (int signal : {SIGINT, SIGTERM})
    PetscCheck(sigaction(signal, &action, nullptr) == 0, PETSC_COMM_SELF, PETSC_ERR_SYS,
               "cannot install the handler of %s", SignalName(signal));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode AgreeOnStop(MPI_Comm comm, int *signal) {
  PetscFunctionBeginUser;
  const int local = g_stop_signal;
  PetscCallMPI(MPI_Allreduce(&local, signal, 1, MPI_INT, MPI_MAX, comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

const char *SignalName(int signal) {
  static char other[32];
  if (signal == SIGINT) return "SIGINT";
  if (signal == SIGTERM) return "SIGTERM";
  std::snprintf(other, sizeof(other), "signal %d", signal);
  return other;
}

PetscErrorCode ProgressLine::Start(MPI_Comm comm, const RunControlOptions &options,
                                   PetscInt first_step, PetscInt last_step) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  enabled_ = rank == 0 && options.progress && last_step > first_step;
  first_ = step_ = first_step;
  last_ = last_step;
  PetscCall(PetscTime(&start_));
  printed_ = start_;
  PetscFunctionReturn(PETSC_SUCCESS);
}

void ProgressLine::Update(PetscInt step, PetscReal time, PetscInt iterations) {
  if (!enabled_) return;
  step_ = step;
  time_ = time;
  iterations_ = iterations;
  PetscLogDouble now;
  PetscCallVoid(PetscTime(&now));
  // The first step prints at once (the user sees the line and an ETA straight
  // away), later ones at most four times a second; Finish prints the last.
  if (step == last_ || (step != first_ + 1 && now - printed_ < kProgressInterval)) return;
  printed_ = now;
  Print(false);
}

void ProgressLine::Finish() {
  if (!enabled_) return;
  Print(true);
  enabled_ = false;
}

void ProgressLine::Print(bool final_line) {
  PetscLogDouble now;
  PetscCallVoid(PetscTime(&now));
  const double elapsed = now - start_, done = static_cast<double>(step_ - first_);
  const double rate = elapsed > 0 ? done / elapsed : 0;
  char text[160];
  int n = std::snprintf(text, sizeof(text),
                        "step %" PetscInt_FMT "/%" PetscInt_FMT "  t = %.6g s  %.3g steps/s", step_,
                        last_, (double)time_, rate);
  if (!final_line && rate > 0)
    n += std::snprintf(text + n, sizeof(text) - n, "  ETA %s",
                       Duration((last_ - step_) / rate).c_str());
  if (final_line)
    n += std::snprintf(text + n, sizeof(text) - n, "  in %s", Duration(elapsed).c_str());
  std::snprintf(text + n, sizeof(text) - n, "  solver its %" PetscInt_FMT, iterations_);
  std::string line(text);
  const size_t width = line.size();
  if (line.size() < width_) line.append(width_ - line.size(), ' ');  // cover a longer previous line
  width_ = width;
  std::fprintf(stderr, "\r%s%s", line.c_str(), final_line ? "\n" : "");
  std::fflush(stderr);
  g_line_open = !final_line;
}

void EndProgressLine() {
  if (!g_line_open) return;
  std::fputc('\n', stderr);
  g_line_open = false;
}

}  // namespace softbody
