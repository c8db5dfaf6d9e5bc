// The driver of a run, as its steps:
//   1. options of every module (-help lists them and stops);
//   2. set-up: check the files, read the scene, partition, initial state, open
//      the output, set up the solvers, apply what is due at the start and write
//      frame 0 (a restart takes over its checkpoint instead);
//   3. the time loop: per step a solve, then collisions and constraints, then the
//      deformations due; a frame every -output_every steps, a checkpoint every
//      -checkpoint_every steps; after SIGINT/SIGTERM the ranks stop together;
//   4. closing the result file with the run's statistics;
//   5. the summary on rank 0, and a warning for every option nothing read.
// Every public method is collective on the communicator given to the constructor.
#pragma once

#include <petscksp.h>

#include <optional>
#include <string>
#include <vector>

#include "app/benchmark.hpp"
#include "app/log_stages.hpp"
#include "app/report.hpp"
#include "app/run_control.hpp"
#include "contact/contact.hpp"
#include "fem/assembly.hpp"
#include "fem/deformation.hpp"
#include "fem/partition.hpp"
#include "io/checkpoint.hpp"
#include "io/output.hpp"
#include "io/scene.hpp"
#include "solvers/integrator.hpp"

namespace softbody {

// Every module's options.
struct RunOptions {
  SceneOptions scene;
  PartitionOptions partition;
  std::string deformations;  // -deform, parsed once the scene is known
  IntegratorOptions integration;
  ContactOptions contact;
  OutputOptions output;
  CheckpointOptions checkpoints;
  RunControlOptions control;
  BenchmarkOptions bench;
};

// Collective. Reads every module's options; under -help prints their help.
PetscErrorCode ProcessRunOptions(MPI_Comm comm, RunOptions *options);

class Simulation {
 public:
  explicit Simulation(MPI_Comm comm) : comm_(comm) {}
  ~Simulation();
  Simulation(const Simulation &) = delete;
  Simulation &operator=(const Simulation &) = delete;

  // Collective. The whole run. *exit_code: 0, or 128 + the signal that stopped it.
  PetscErrorCode Run(int *exit_code);

 private:
  PetscErrorCode SetUp();
  PetscErrorCode CheckFiles();
  PetscErrorCode ReadScene();
  PetscErrorCode DistributeMesh();
  PetscErrorCode CreateInitialState();
  PetscErrorCode OpenOutput();
  PetscErrorCode SetUpContact();
  PetscErrorCode SetUpSolvers();
  PetscErrorCode StartTimeLoop();
  PetscErrorCode TimeLoop();
  PetscErrorCode Step();
  PetscErrorCode RecordStep(PetscInt step, PetscLogDouble loop_before);
  PetscErrorCode Checkpoint(PetscInt step);
  PetscErrorCode CloseOutput();
  PetscErrorCode PrintSummary(int *exit_code);
  PetscErrorCode WarnUnusedOptions();
  PetscErrorCode ApplyDeformations(PetscReal time, PetscReal dt);
  PetscErrorCode Resume();

  bool restart() const { return !options_.checkpoints.restart_path.empty(); }
  bool has_unknowns() const { return layout_.num_free() > 0; }

  MPI_Comm comm_;
  std::vector<std::string> given_options_;  // the user's, before any preset
  RunReport report_;
  std::optional<TimedStage> setup_timer_;  // the set-up's time, until frame 0
  RunOptions options_;
  Scene scene_;
  std::vector<Deformation> deformations_;
  MeshHolding holding_ = MeshHolding::kSlabs;  // how the meshes are held (DistributeScene)
  MeshShare share_;  // this rank's shares of the meshes (set-up only: freed after contact's)
  DofLayout layout_;
  LocalTets tets_;  // the free tets with an owned vertex (set-up only: the integrator takes them)
  LocalElements elements_;
  State state_;
  LoopState start_;                  // where the loop starts: step 0, or a checkpoint's
  Vec initial_positions_ = nullptr;  // a restart: the original run's, to prime the solver
  ResultWriter file_;
  ResultWriter *writer_ = nullptr;  // &file_ with -output (or -restart), else null
  ImplicitEuler integrator_;
  PetscReal dt_first_ = 0;  // s: the original run's first time step
  ContactSolver contact_;
  ProgressLine progress_;
  std::optional<Benchmark> benchmark_;
  PetscReal time_ = 0;   // s
  int stop_signal_ = 0;  // the signal every rank agreed to stop on (0: none)
};

}  // namespace softbody
