// The run summary printed by rank 0 at the end of a run.
#pragma once

#include <petscksp.h>

#include <string>

#include "contact/contact.hpp"
#include "fem/partition.hpp"
#include "io/output.hpp"
#include "io/scene.hpp"
#include "solvers/integrator.hpp"

namespace softbody {

struct RunTimes {
  PetscLogDouble setup = 0;   // s: reading, partitioning, assembly, factorisation
  PetscLogDouble loop = 0;    // s: the time steps (contact included), output excluded
  PetscLogDouble output = 0;  // s: gathering and writing frames
};

// The cost of one kind of time step: those in which contact acted (a solve
// under contact constraints, or the step's end response or collision guard
// changed x or v) or those in which it did not (issue 14 asks a contact step
// to cost at most 3 times a free one).
struct StepKindCost {
  PetscInt steps = 0;
  PetscLogDouble wall = 0;  // s, as the time loop's (this rank's clock)
  PetscLogDouble cpu = 0;   // s, this process's CPU time (ProcessCpuSeconds)
  PetscInt solves = 0, iterations = 0;
};

// This process's CPU time (s, CLOCK_PROCESS_CPUTIME_ID): unlike the wall
// clock, it does not grow when other processes share the cores.
PetscLogDouble ProcessCpuSeconds();

struct RunReport {
  PetscInt first_step = 0;        // step the run started from (a restart's checkpoint)
  PetscInt steps = 0;             // steps taken since the original start
  PetscInt checkpoint_step = -1;  // the last checkpoint written (-1: none)
  std::string restarted_from;     // -restart file ("": a fresh start)
  PetscReal final_time = 0;
  EnergySample energy;  // at the end
  PetscInt frames = 0;
  RunTimes times;
  StepKindCost contact_steps, free_steps;  // the time loop's steps by kind
};

// Collective (the solver description is queried collectively); prints on rank 0.
// ksp may be null when the scene has no unknowns.
PetscErrorCode PrintRunSummary(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                               const IntegratorOptions &integration, const OutputOptions &output,
                               const SolverStatistics &solver, KSP ksp,
                               const ContactSolver &contact, const RunReport &report);

// Rank 0 prints, on stderr, the one line that says a signal stopped the run and
// what the result file holds.
// Collective. -log_rank_messages: rank 0 prints, for every rank, the point-to-point
// messages and bytes PETSc's log counted there since the start, as -log_view's
// summary counts them (half of sent plus received: what a rank sends in a
// symmetric exchange), "  messages     rank R: N messages, B bytes".
PetscErrorCode PrintRankMessages(MPI_Comm comm);

PetscErrorCode PrintInterruption(MPI_Comm comm, int signal, const IntegratorOptions &integration,
                                 const OutputOptions &output, const RunReport &report);

}  // namespace softbody
