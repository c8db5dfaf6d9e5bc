// softbody: implicit finite-element simulation of soft bodies on PETSc + MPI.
//
// Sample runs
//   mpirun -n 2 softbody -scene scenes/default-scene.txt -output results/default.h5
//   mpirun -n 2 softbody -scene S.txt -steps 200 -dt 0.01 -ksp_type cg -pc_type gamg -log_view
//   mpirun -n 2 softbody -scene S.txt -options_file config/cg-jacobi.opts -ksp_monitor
//   mpirun -n 2 softbody -scene S.txt -mode corotational -ksp_converged_reason
//   mpirun -n 2 softbody -scene S.txt -options_file config/practical3.opts -constraints C.txt
//   mpirun -n 2 softbody -scene S.txt -steps 1000 -output run.h5 -checkpoint_every 50
//   mpirun -n 2 softbody -scene S.txt -steps 2000 -restart run.h5    # continues run.h5
//
// Equations (linear and corotational): see integrator.hpp; collisions and
// constraints: contact.hpp. Data flow: scene -> free DOFs (METIS partition) ->
// element kernels on each rank's elements -> COO assembly -> KSP -> time loop
// (solve, then contact) -> HDF5 frames in natural vertex order; checkpoints and
// restart: checkpoint.hpp; progress line, -quiet and signals: run_control.hpp.
#include <petscksp.h>

#include <cstdio>
#include <cstring>
#include <optional>

#include "app/benchmark.hpp"
#include "app/log_stages.hpp"
#include "app/report.hpp"
#include "app/run_control.hpp"
#include "common/errors.hpp"
#include "contact/contact.hpp"
#include "fem/assembly.hpp"
#include "fem/deformation.hpp"
#include "fem/partition.hpp"
#include "io/checkpoint.hpp"
#include "io/output.hpp"
#include "io/scene.hpp"
#include "solvers/integrator.hpp"
#include "solvers/solver.hpp"

static const char help[] =
    "softbody: implicit finite-element soft-body simulation (PETSc + MPI).\n"
    "Usage: mpirun -n 2 softbody -scene SCENE.txt [-output OUT.h5] [options] [PETSc options]\n"
    "Solver presets: -options_file config/direct.opts (linear default), config/cg-warp.opts "
    "(corotational\n"
    "default), config/cg-gamg.opts, config/direct-mumps.opts, ...\n";

using namespace softbody;

namespace {

// Lists the solver's options under -help (there is no scene to set up).
PetscErrorCode PrintSolverHelp(MPI_Comm comm) {
  PetscFunctionBeginUser;
  KSP ksp;
  PetscCall(ApplyPresetDefaults(kDirectPreset));
  PetscCall(KSPCreate(comm, &ksp));
  PetscCall(KSPSetFromOptions(ksp));
  PetscCall(KSPDestroy(&ksp));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Prescribed deformations due at `time` (s), applied to the state at that time.
PetscErrorCode ApplyDeformations(const Scene &scene, const DofLayout &layout, PetscReal time,
                                 PetscReal dt, const State &state, ImplicitEuler *integrator,
                                 std::vector<Deformation> *deformations) {
  PetscFunctionBeginUser;
  if (deformations->empty()) PetscFunctionReturn(PETSC_SUCCESS);
  bool changed;
  PetscCall(ApplyDueDeformations(scene, layout, time, 0.5 * dt, state.lumped_mass, state.positions,
                                 deformations, &changed));
  if (changed) integrator->PositionsChanged();
  PetscFunctionReturn(PETSC_SUCCESS);
}

// A stopwatch that adds the wall time of a scope to a total and logs the scope
// as a PETSc stage (-log_view).
class Timed {
 public:
  Timed(PetscLogStage stage, PetscLogDouble *total) : total_(total) {
    PetscCallVoid(PetscLogStagePush(stage));
    PetscCallVoid(PetscTime(&start_));
  }
  ~Timed() {
    PetscLogDouble end;
    PetscCallVoid(PetscTime(&end));
    *total_ += end - start_;
    PetscCallVoid(PetscLogStagePop());
  }

 private:
  PetscLogDouble *total_, start_ = 0;
};

// Collective. Stores the loop state after `step` as a checkpoint in the result file.
PetscErrorCode Checkpoint(ResultWriter *writer, PetscInt step, PetscReal time,
                          const std::vector<Deformation> &deformations,
                          const ContactSolver &contact, const State &state) {
  PetscFunctionBeginUser;
  LoopState loop;
  loop.step = step;
  loop.time = time;
  loop.frames = writer->frames();
  for (const Deformation &d : deformations) loop.deformations_applied.push_back(d.applied ? 1 : 0);
  PetscCall(contact.GatherRestingContacts(&loop.resting_contacts));
  PetscCall(WriteCheckpoint(writer, loop, state.positions, state.velocities));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. What a restart takes over from its checkpoint besides x and v:
// the loop state, and the solver state of the original run (primed with that
// run's first step: its initial positions, deformed as due at t = 0).
PetscErrorCode Resume(const LoopState &loop, const Scene &scene, const DofLayout &layout,
                      const State &state, Vec initial_positions, PetscReal dt_first,
                      ImplicitEuler *integrator, ContactSolver *contact,
                      std::vector<Deformation> *deformations) {
  PetscFunctionBeginUser;
  std::vector<Deformation> at_start = *deformations;
  bool changed;
  PetscCall(ApplyDueDeformations(scene, layout, 0.0, 0.5 * dt_first, state.lumped_mass,
                                 initial_positions, &at_start, &changed));
  if (layout.num_free() > 0) PetscCall(integrator->PrimeSolver(initial_positions, dt_first));
  for (size_t i = 0; i < deformations->size(); ++i)
    (*deformations)[i].applied = loop.deformations_applied[i] != 0;
  contact->RestoreRestingContacts(loop.resting_contacts);
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode Run(MPI_Comm comm, int *exit_code) {
  PetscFunctionBeginUser;
  PetscCall(RegisterLogStages());
  const PetscLogStage setup_stage = Stages().setup, step_stage = Stages().step,
                      output_stage = Stages().output;
  RunReport report;
  std::optional<Timed> setup_timer(std::in_place, setup_stage, &report.times.setup);

  // 1. Options of every module; -help lists them and stops.
  SceneOptions scene_options;
  std::string deform_text;
  IntegratorOptions integration;
  ContactOptions contact_options;
  OutputOptions output;
  CheckpointOptions checkpoints;
  RunControlOptions control;
  BenchmarkOptions bench_options;
  PetscCall(ProcessSceneOptions(comm, &scene_options));
  PetscCall(ProcessIntegratorOptions(comm, &integration));
  PetscCall(ProcessContactOptions(comm, &contact_options));
  PetscCall(ProcessDeformationOptions(comm, &deform_text));
  PetscCall(ProcessOutputOptions(comm, &output));
  PetscCall(ProcessCheckpointOptions(comm, output, &checkpoints));
  PetscCall(ProcessRunControlOptions(comm, &control));
  PetscCall(ProcessBenchmarkOptions(comm, &bench_options));
  PetscBool help;
  PetscCall(PetscOptionsHasHelp(nullptr, &help));
  if (help) {
    setup_timer.reset();
    PetscCall(PrintSolverHelp(comm));
    PetscFunctionReturn(PETSC_SUCCESS);
  }

  // 2. Fail early: the output can be written, the restart file has a checkpoint.
  //    A restart without -output continues the restart file itself.
  const bool restart = !checkpoints.restart_path.empty();
  if (restart && output.path.empty()) output.path = checkpoints.restart_path;
  if (!output.path.empty()) PetscCall(CheckOutputPath(comm, "-output", output.path));
  if (restart) PetscCall(CheckRestartFile(comm, checkpoints.restart_path));

  // 3. Every rank reads and validates the scene and its meshes.
  Scene scene;
  PetscCall(LoadScene(comm, scene_options, &scene));
  std::vector<Deformation> deformations;
  PetscCall(ParseDeformations(comm, deform_text, scene, &deformations));
  // Bodies that nothing can set in motion add no unknowns (partition.hpp); not on
  // a restart (its bodies move as the checkpoint says) or when -export_matrices
  // asks for the matrices of every free body.
  if (!restart && output.matrix_dir.empty()) {
    MotionSources sources{integration.gravity.squaredNorm() > 0, bool(contact_options.ground),
                          !contact_options.constraints_path.empty() || contact_options.edge_bounds,
                          std::vector<bool>(scene.bodies.size(), false)};
    for (const Deformation &d : deformations) sources.deformed[d.body] = true;
    MarkBodiesAtRest(sources, &scene);
  }

  // 4. Free vertices, METIS partition, contiguous block per rank.
  DofLayout layout;
  PetscCall(BuildDofLayout(comm, scene, &layout));
  const bool has_unknowns = layout.num_free() > 0;

  // 5. This rank's elements, the lumped mass and the initial state; a restart
  //    replaces the state by its checkpoint's (checked against the scene).
  const LocalElements elements = CollectLocalElements(scene, layout);
  State state;
  PetscCall(CreateState(comm, scene, layout, elements, &state));
  LoopState start;
  Vec initial_positions = nullptr;  // a restart: the original run's, to prime the solver
  if (restart) {
    PetscCall(VecDuplicate(state.positions, &initial_positions));
    PetscCall(VecCopy(state.positions, initial_positions));
    PetscCall(ReadCheckpoint(comm, checkpoints.restart_path, scene, layout, deformations.size(),
                             integration.steps, state.positions, state.velocities, &start));
  }

  // 6. The output file, before the costly set-up: new, or continuing the
  //    restart file's frames up to its checkpoint.
  ResultWriter file;
  ResultWriter *writer = output.path.empty() ? nullptr : &file;
  const Continuation continuation{checkpoints.restart_path, start.frames};
  if (writer)
    PetscCall(writer->Open(comm, output, scene, layout, state.positions,
                           restart ? &continuation : nullptr));

  // 7. A = (1 + a dt) M + (b dt + dt^2) K and its solver (linear: factorised once);
  //    collision structures and constraints, only as far as the scene needs them.
  ImplicitEuler integrator;
  const PetscReal dt_first = TimeStepAt(integration, 0.0);
  integration.dt = TimeStepAt(integration, start.time);
  if (has_unknowns) {
    PetscCall(integrator.Setup(comm, scene, layout, elements, state.rest_positions,
                               state.lumped_mass, integration));
    PetscCall(integrator.SetBodies(OwnedVertexBodies(scene, layout),
                                   static_cast<int>(scene.bodies.size())));
  }
  if (!output.matrix_dir.empty() && has_unknowns)
    PetscCall(ExportMatrices(output.matrix_dir, layout, elements, integration.shear_scale,
                             state.lumped_mass, integration.alpha, integration.beta));
  ContactSolver contact;
  contact_options.gravity = integration.gravity.norm();
  PetscCall(contact.Setup(comm, scene, layout, state.lumped_mass, contact_options));

  // 8. A fresh start applies the deformations due at t = 0 and writes frame 0;
  //    a restart takes over the checkpoint's loop state.
  if (restart) {
    PetscCall(Resume(start, scene, layout, state, initial_positions, dt_first, &integrator,
                     &contact, &deformations));
    PetscCall(VecDestroy(&initial_positions));
  } else {
    PetscCall(
        ApplyDeformations(scene, layout, 0.0, integration.dt, state, &integrator, &deformations));
  }
  if (has_unknowns)
    PetscCall(integrator.Energies(state.positions, state.velocities, &report.energy));
  setup_timer.reset();
  if (writer && !restart) {
    Timed timer(output_stage, &report.times.output);
    PetscCall(writer->WriteFrame(0.0, state.positions, state.velocities, report.energy));
  }

  // 9. Time loop: solve, then collisions and constraints; a frame every
  //    -output_every steps, a checkpoint every -checkpoint_every steps. After
  //    SIGINT/SIGTERM the ranks stop together after the step, with its frame.
  ProgressLine progress;
  Benchmark benchmark(bench_options);
  PetscCall(progress.Start(comm, control, start.step, integration.steps));
  report.first_step = report.steps = start.step;
  PetscReal time = report.final_time = start.time;
  int stop_signal;
  PetscCall(AgreeOnStop(comm, &stop_signal));
  for (PetscInt step = start.step + 1; step <= integration.steps && !stop_signal; ++step) {
    const PetscLogDouble loop_before = report.times.loop;
    {
      Timed timer(step_stage, &report.times.loop);
      const PetscReal dt = TimeStepAt(integration, time);
      if (has_unknowns && dt != integrator.time_step()) PetscCall(integrator.SetTimeStep(dt));
      if (has_unknowns) PetscCall(integrator.Step(state.positions, state.velocities, &contact));
      time += dt;
      // Deformations due by the new time: the frame at that time shows them.
      PetscCall(ApplyDeformations(scene, layout, time, dt, state, &integrator, &deformations));
    }
    PetscCall(AgreeOnStop(comm, &stop_signal));
    const bool last = step == integration.steps || stop_signal;
    const bool frame = writer && (step % output.every == 0 || stop_signal);
    if (has_unknowns && (frame || last)) {
      // The corotational element pass behind the energies is reused by the next step.
      Timed timer(step_stage, &report.times.loop);
      PetscCall(integrator.Energies(state.positions, state.velocities, &report.energy));
    }
    benchmark.RecordStep(report.times.loop - loop_before, integrator.statistics());
    report.steps = step;
    report.final_time = time;
    if (frame) {
      Timed timer(output_stage, &report.times.output);
      PetscCall(writer->WriteFrame(time, state.positions, state.velocities, report.energy));
    }
    if (checkpoints.every > 0 && (step % checkpoints.every == 0 || last)) {
      Timed timer(output_stage, &report.times.output);
      PetscCall(Checkpoint(writer, step, time, deformations, contact, state));
      report.checkpoint_step = step;
    }
    progress.Update(step, time, integrator.statistics().last_iterations);
  }
  progress.Finish();
  if (has_unknowns) PetscCall(benchmark.Finish(comm, scene, &integrator, state.positions));
  if (writer) {
    const SolverStatistics &solver = integrator.statistics();
    std::vector<std::pair<std::string, double>> statistics{
        {"setup_seconds", report.times.setup},
        {"loop_seconds", report.times.loop},
        {"output_seconds", report.times.output},
        {"steps", double(report.steps)},
        {"first_step", double(report.first_step)},
        {"final_time", report.final_time},
        {"ranks", double(layout.size)},
        {"dofs", 3.0 * layout.num_free()},
        {"solves", double(solver.solves)},
        {"solver_iterations", double(solver.total_iterations)},
        {"contact_solves", double(solver.contact_solves)},
        {"newton_iterations", double(solver.newton_iterations)},
        {"max_newton_iterations", double(solver.max_newton_iterations)},
        {"newton_stopped_short", double(solver.newton_stopped_short)},
        {"fallback_solves", double(solver.fallback_solves)},
        {"contact_seconds", contact.statistics().seconds}};
    statistics.insert(statistics.end(), benchmark.attributes().begin(),
                      benchmark.attributes().end());
    PetscCall(writer->Close(statistics, stop_signal));
    report.frames = writer->frames();
  }

  // 10. Summary on rank 0 (not with -quiet); an interrupted run says so and
  //     exits with 128 + the signal.
  report.restarted_from = checkpoints.restart_path;
  if (!control.quiet)
    PetscCall(PrintRunSummary(comm, scene, layout, integration, output, integrator.statistics(),
                              has_unknowns ? integrator.solver() : nullptr, contact, report));
  if (stop_signal) {
    PetscCall(PrintInterruption(comm, stop_signal, integration, output, report));
    *exit_code = 128 + stop_signal;
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Every -options_file on the command line can be opened; otherwise rank 0 says
// which cannot. Not collective beyond MPI_Comm_rank.
bool OptionsFilesReadable(int argc, char **argv) {
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "-options_file") != 0) continue;
    const char *path = i + 1 < argc ? argv[i + 1] : "";
    if (std::FILE *file = std::fopen(path, "r")) {
      std::fclose(file);
      continue;
    }
    if (rank == 0)
      std::fprintf(stderr, "softbody: error: option -options_file: cannot open '%s'\n", path);
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char **argv) {
  // MPI first: an unreadable -options_file is reported as one line by rank 0,
  // before PETSc would stop inside PetscInitialize with a traceback.
  MPI_Init(&argc, &argv);
  if (!OptionsFilesReadable(argc, argv)) {
    MPI_Finalize();
    return 1;
  }
  PetscCall(PetscInitialize(&argc, &argv, nullptr, help));
  PetscCall(InstallErrorHandler());
  PetscCall(InstallStopHandlers());
  int exit_code = 0;
  const PetscErrorCode status = Run(PETSC_COMM_WORLD, &exit_code);
  PetscCall(PetscFinalize());
  MPI_Finalize();
  return status == PETSC_SUCCESS ? exit_code : 1;
}
