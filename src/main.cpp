// softbody: implicit finite-element simulation of soft bodies on PETSc + MPI.
//
// Sample runs
//   mpirun -n 2 softbody -scene scenes/default-scene.txt -output results/default.h5
//   mpirun -n 2 softbody -scene S.txt -steps 200 -dt 0.01 -ksp_type cg -pc_type gamg -log_view
//   mpirun -n 2 softbody -scene S.txt -options_file config/cg-jacobi.opts -ksp_monitor
//   mpirun -n 2 softbody -scene S.txt -mode corotational -ksp_converged_reason
//   mpirun -n 2 softbody -scene S.txt -options_file config/practical3.opts -constraints C.txt
//
// Equations (linear and corotational): see integrator.hpp; collisions and
// constraints: contact.hpp. Data flow: scene -> free DOFs (METIS partition) ->
// element kernels on each rank's elements -> COO assembly -> KSP -> time loop
// (solve, then contact) -> HDF5 frames in natural vertex order.
#include <petscksp.h>

#include <cstdio>
#include <cstring>
#include <optional>

#include "assembly.hpp"
#include "benchmark.hpp"
#include "contact.hpp"
#include "deformation.hpp"
#include "errors.hpp"
#include "integrator.hpp"
#include "log_stages.hpp"
#include "output.hpp"
#include "partition.hpp"
#include "report.hpp"
#include "scene.hpp"
#include "solver.hpp"

static const char help[] =
    "softbody: implicit finite-element soft-body simulation (PETSc + MPI).\n"
    "Usage: mpirun -n 2 softbody -scene SCENE.txt [-output OUT.h5] [options] [PETSc options]\n"
    "Solver presets: -options_file config/direct.opts (linear default), config/cg-warp.opts (corotational\n"
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

PetscErrorCode Run(MPI_Comm comm) {
  PetscFunctionBeginUser;
  PetscCall(RegisterLogStages());
  const PetscLogStage setup_stage = Stages().setup, step_stage = Stages().step, output_stage = Stages().output;
  RunReport report;
  std::optional<Timed> setup_timer(std::in_place, setup_stage, &report.times.setup);

  // 1. Options of every module; -help lists them and stops.
  SceneOptions scene_options;
  std::string deform_text;
  IntegratorOptions integration;
  ContactOptions contact_options;
  OutputOptions output;
  BenchmarkOptions bench_options;
  PetscCall(ProcessSceneOptions(comm, &scene_options));
  PetscCall(ProcessIntegratorOptions(comm, &integration));
  PetscCall(ProcessContactOptions(comm, &contact_options));
  PetscCall(ProcessDeformationOptions(comm, &deform_text));
  PetscCall(ProcessOutputOptions(comm, &output));
  PetscCall(ProcessBenchmarkOptions(comm, &bench_options));
  PetscBool help;
  PetscCall(PetscOptionsHasHelp(nullptr, &help));
  if (help) {
    setup_timer.reset();
    PetscCall(PrintSolverHelp(comm));
    PetscFunctionReturn(PETSC_SUCCESS);
  }

  // 2. Every rank reads and validates the scene and its meshes.
  Scene scene;
  PetscCall(LoadScene(comm, scene_options, &scene));
  std::vector<Deformation> deformations;
  PetscCall(ParseDeformations(comm, deform_text, scene, &deformations));
  {  // Bodies that nothing can set in motion add no unknowns (partition.hpp).
    MotionSources sources{integration.gravity.squaredNorm() > 0, bool(contact_options.ground),
                          !contact_options.constraints_path.empty() || contact_options.edge_bounds,
                          std::vector<bool>(scene.bodies.size(), false)};
    for (const Deformation &d : deformations) sources.deformed[d.body] = true;
    MarkBodiesAtRest(sources, &scene);
  }

  // 3. Free vertices, METIS partition, contiguous block per rank.
  DofLayout layout;
  PetscCall(BuildDofLayout(comm, scene, &layout));
  const bool has_unknowns = layout.num_free() > 0;

  // 4. This rank's elements, the lumped mass and the initial state.
  const LocalElements elements = CollectLocalElements(scene, layout);
  State state;
  PetscCall(CreateState(comm, scene, layout, elements, &state));

  // 5. A = (1 + a dt) M + (b dt + dt^2) K and its solver (linear: factorised once);
  //    collision structures and constraints, only as far as the scene needs them.
  ImplicitEuler integrator;
  integration.dt = TimeStepAt(integration, 0.0);
  if (has_unknowns)
    PetscCall(integrator.Setup(comm, scene, layout, elements, state.rest_positions, state.lumped_mass,
                               integration));
  if (!output.matrix_dir.empty() && has_unknowns)
    PetscCall(ExportMatrices(output.matrix_dir, layout, elements, integration.shear_scale,
                             state.lumped_mass, integration.alpha, integration.beta));
  ContactSolver contact;
  contact_options.gravity = integration.gravity.norm();
  PetscCall(contact.Setup(comm, scene, layout, state.lumped_mass, contact_options));

  // 6. Deformations due at t = 0, the output file with the mesh, frame 0.
  PetscCall(ApplyDeformations(scene, layout, 0.0, integration.dt, state, &integrator, &deformations));
  ResultWriter file;
  ResultWriter *writer = output.path.empty() ? nullptr : &file;
  if (writer) PetscCall(writer->Open(comm, output.path, scene, layout, state.positions));
  if (has_unknowns) PetscCall(integrator.Energies(state.positions, state.velocities, &report.energy));
  setup_timer.reset();
  if (writer) {
    Timed timer(output_stage, &report.times.output);
    PetscCall(writer->WriteFrame(0.0, state.positions, state.velocities, report.energy));
  }

  // 7. Time loop: solve, then collisions and constraints; a frame every
  //    -output_every steps.
  PetscReal time = 0;
  Benchmark benchmark(bench_options);
  for (PetscInt step = 1; step <= integration.steps; ++step) {
    const bool frame = writer && step % output.every == 0;
    const PetscLogDouble loop_before = report.times.loop;
    {
      Timed timer(step_stage, &report.times.loop);
      const PetscReal dt = TimeStepAt(integration, time);
      if (has_unknowns && dt != integrator.time_step()) PetscCall(integrator.SetTimeStep(dt));
      if (has_unknowns) PetscCall(integrator.Step(state.positions, state.velocities, &contact));
      time += dt;
      // Deformations due by the new time: the frame at that time shows them.
      PetscCall(ApplyDeformations(scene, layout, time, dt, state, &integrator, &deformations));
      // The corotational element pass behind the energies is reused by the next step.
      if (has_unknowns && (frame || step == integration.steps))
        PetscCall(integrator.Energies(state.positions, state.velocities, &report.energy));
    }
    benchmark.RecordStep(report.times.loop - loop_before, integrator.statistics());
    report.steps = step;
    report.final_time = time;
    if (frame) {
      Timed timer(output_stage, &report.times.output);
      PetscCall(writer->WriteFrame(time, state.positions, state.velocities, report.energy));
    }
  }
  if (has_unknowns) PetscCall(benchmark.Finish(comm, scene, &integrator, state.positions));
  if (writer) {
    const SolverStatistics &solver = integrator.statistics();
    std::vector<std::pair<std::string, double>> statistics{{"setup_seconds", report.times.setup},
                             {"loop_seconds", report.times.loop},
                             {"output_seconds", report.times.output},
                             {"steps", double(report.steps)},
                             {"final_time", report.final_time},
                             {"ranks", double(layout.size)},
                             {"dofs", 3.0 * layout.num_free()},
                             {"solves", double(solver.solves)},
                             {"solver_iterations", double(solver.total_iterations)},
                             {"contact_solves", double(solver.contact_solves)},
                             {"contact_seconds", contact.statistics().seconds}};
    statistics.insert(statistics.end(), benchmark.attributes().begin(), benchmark.attributes().end());
    PetscCall(writer->Close(statistics));
    report.frames = writer->frames();
  }

  // 8. Summary on rank 0.
  PetscCall(PrintRunSummary(comm, scene, layout, integration, output, integrator.statistics(),
                            has_unknowns ? integrator.solver() : nullptr, contact, report));
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
    if (rank == 0) std::fprintf(stderr, "softbody: error: option -options_file: cannot open '%s'\n", path);
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
  const PetscErrorCode status = Run(PETSC_COMM_WORLD);
  PetscCall(PetscFinalize());
  MPI_Finalize();
  return status == PETSC_SUCCESS ? 0 : 1;
}
