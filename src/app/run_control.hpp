// Run control: what a run tells its user while it goes, and how it stops.
//
// Progress: rank 0 keeps one line on stderr up to date, at most four times a
// second, when stderr is a terminal (also through mpirun: its own stderr) or
// with -progress (-progress 0: never):
//     step 120/500  t = 2.4 s  31.5 steps/s  ETA 12 s  solver its 17
// -quiet prints nothing but errors (no run summary; no progress line unless
// -progress asks for it).
//
// Signals: SIGINT and SIGTERM only set a flag (a second one ends the process at
// once). At the end of every step the ranks agree on it (one MPI_Allreduce of
// an int), so the run finishes the current step, writes its frame (and a
// checkpoint with -checkpoint_every), closes the file with complete = 0 and
// interrupted = the signal, says so in one line and exits with 128 + signal.
// (mpirun passes SIGINT/SIGTERM to the ranks and kills them after
// odls_base_sigkill_timeout seconds: raise it with `mpirun --mca
// odls_base_sigkill_timeout 30` when a step takes longer.)
#pragma once

#include <petscsys.h>

namespace softbody {

struct RunControlOptions {
  PetscBool quiet = PETSC_FALSE;          // -quiet
  PetscBool progress = PETSC_FALSE;       // show the progress line (-progress, or a terminal)
  PetscBool rank_messages = PETSC_FALSE;  // -log_rank_messages
};

// Collective. Reads -quiet, -progress and -log_rank_messages; decides on rank 0
// whether the progress line is shown.
PetscErrorCode ProcessRunControlOptions(MPI_Comm comm, RunControlOptions *options);

// Not collective. Installs the SIGINT/SIGTERM handlers (after PetscInitialize,
// replacing PETSc's for these two signals).
PetscErrorCode InstallStopHandlers();

// Collective. The signal any rank has received (0: none), the same on every rank.
PetscErrorCode AgreeOnStop(MPI_Comm comm, int *signal);

// "SIGINT", "SIGTERM", or "signal N".
const char *SignalName(int signal);

// Rank 0's progress line. Not collective: the other ranks do nothing.
class ProgressLine {
 public:
  // Not collective. Steps first_step + 1 .. last_step are to come.
  PetscErrorCode Start(MPI_Comm comm, const RunControlOptions &options, PetscInt first_step,
                       PetscInt last_step);
  // After step `step` at time `time` (s); `iterations` of its last solve.
  void Update(PetscInt step, PetscReal time, PetscInt iterations);
  // Prints the final state and ends the line.
  void Finish();

 private:
  void Print(bool final_line);
  bool enabled_ = false;
  PetscInt first_ = 0, last_ = 0, step_ = 0, iterations_ = 0;
  PetscReal time_ = 0;
  PetscLogDouble start_ = 0, printed_ = 0;
  size_t width_ = 0;
};

// Not collective. Ends a progress line left open on stderr (before an error message).
void EndProgressLine();

}  // namespace softbody
