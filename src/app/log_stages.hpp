// The PETSc log stages of a run, so that -log_view shows where the time goes:
//   Set-up          reading, partitioning, state, solver creation
//   Assembly        element passes that fill A (and K): once in linear mode,
//                   every step in corotational mode
//   Factorisation   factorisation or preconditioner set-up (linear: once;
//                   corotational: GAMG's Galerkin products, rotations of the
//                   warp preconditioner, every step)
//   Step            the rest of a time step: right-hand side, solve, update
//   Contact         collision detection, constrained solves and responses
//   Output          gathering and writing frames
// Stages nest (PETSc pauses the outer one), so each stage's time in -log_view
// is its own.
#pragma once

#include <petscsys.h>
#include <petsctime.h>

namespace softbody {

struct LogStages {
  PetscLogStage setup = -1, assembly = -1, factorisation = -1, step = -1, contact = -1, output = -1;
};

// Collective on PETSC_COMM_WORLD the first time; registers the stages once.
PetscErrorCode RegisterLogStages();

// The registered stages (all -1 before RegisterLogStages).
const LogStages &Stages();

// Pushes a stage for the lifetime of the scope (nothing for stage -1).
class StageScope {
 public:
  explicit StageScope(PetscLogStage stage) : stage_(stage) {
    if (stage_ >= 0) PetscCallVoid(PetscLogStagePush(stage_));
  }
  ~StageScope() {
    if (stage_ >= 0) PetscCallVoid(PetscLogStagePop());
  }
  StageScope(const StageScope &) = delete;
  StageScope &operator=(const StageScope &) = delete;

 private:
  PetscLogStage stage_;
};

// A stopwatch for the lifetime of the scope: adds its wall time (s) to *total and
// pushes `stage` meanwhile, so that the run summary and -log_view agree.
class TimedStage {
 public:
  TimedStage(PetscLogStage stage, PetscLogDouble *total) : total_(total) {
    PetscCallVoid(PetscLogStagePush(stage));
    PetscCallVoid(PetscTime(&start_));
  }
  ~TimedStage() {
    PetscLogDouble end;
    PetscCallVoid(PetscTime(&end));
    *total_ += end - start_;
    PetscCallVoid(PetscLogStagePop());
  }
  TimedStage(const TimedStage &) = delete;
  TimedStage &operator=(const TimedStage &) = delete;

 private:
  PetscLogDouble *total_, start_ = 0;
};

}  // namespace softbody
