// softbody: implicit finite-element simulation of soft bodies on PETSc + MPI.
//
// Sample runs
//   mpirun -n 2 softbody -scene scenes/default-scene.txt -output results/default.h5
//   mpirun -n 2 softbody -scene S.txt -steps 200 -dt 0.01 -ksp_type cg -pc_type gamg -log_view
//   mpirun -n 2 softbody -scene S.txt -options_file config/cg-jacobi.opts -ksp_monitor
//   mpirun -n 2 softbody -scene S.txt -mode corotational -ksp_converged_reason
//
// Equations (linear and corotational): see integrator.hpp. Data flow: scene -> free DOFs (METIS partition)
// -> element kernels on each rank's elements -> COO assembly -> KSP -> time loop
// -> HDF5 frames in natural vertex order.
#include <petscksp.h>

#include "assembly.hpp"
#include "deformation.hpp"
#include "errors.hpp"
#include "integrator.hpp"
#include "output.hpp"
#include "partition.hpp"
#include "report.hpp"
#include "scene.hpp"
#include "solver.hpp"

static const char help[] =
    "softbody: implicit finite-element soft-body simulation (PETSc + MPI).\n"
    "Usage: mpirun -n 2 softbody -scene SCENE.txt [-output OUT.h5] [options] [PETSc options]\n"
    "Solver presets: -options_file config/direct.opts (default), config/cg-gamg.opts, ...\n";

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

// Energies of the current state (the corotational element pass this needs is
// reused by the next step, so it counts as step work).
PetscErrorCode ComputeEnergies(ImplicitEuler &integrator, bool has_unknowns, const State &state,
                               RunReport *report) {
  PetscFunctionBeginUser;
  if (has_unknowns)
    PetscCall(integrator.Energies(state.positions, state.velocities, &report->kinetic, &report->elastic));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Prescribed deformations due at `time` (s), before the step that starts then.
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

PetscErrorCode WriteFrame(ResultWriter *writer, const State &state, PetscReal time,
                          PetscLogStage stage, RunReport *report) {
  PetscFunctionBeginUser;
  PetscLogDouble start, end;
  PetscCall(PetscLogStagePush(stage));
  PetscCall(PetscTime(&start));
  PetscCall(writer->WriteFrame(time, state.positions, state.velocities, report->kinetic,
                               report->elastic));
  PetscCall(PetscTime(&end));
  PetscCall(PetscLogStagePop());
  report->times.output += end - start;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode Run(MPI_Comm comm) {
  PetscFunctionBeginUser;
  PetscLogStage setup_stage, step_stage, output_stage;
  PetscCall(PetscLogStageRegister("Set-up", &setup_stage));
  PetscCall(PetscLogStageRegister("Time steps", &step_stage));
  PetscCall(PetscLogStageRegister("Output", &output_stage));
  PetscLogDouble start, end;
  RunReport report_init;
  PetscCall(PetscTime(&start));
  PetscCall(PetscLogStagePush(setup_stage));

  // 1. Options of every module; -help lists them and stops.
  std::string scene_path;
  IntegratorOptions integration;
  OutputOptions output;
  PetscCall(ProcessSceneOptions(comm, &scene_path));
  PetscCall(ProcessIntegratorOptions(comm, &integration));
  PetscCall(ProcessOutputOptions(comm, &output));
  std::string deform_text;
  PetscCall(ProcessDeformationOptions(comm, &deform_text));
  PetscBool help;
  PetscCall(PetscOptionsHasHelp(nullptr, &help));
  if (help) {
    PetscCall(PrintSolverHelp(comm));
    PetscCall(PetscLogStagePop());
    PetscFunctionReturn(PETSC_SUCCESS);
  }

  // 2. Every rank reads and validates the scene and its meshes.
  Scene scene;
  PetscCall(LoadScene(comm, scene_path, &scene));

  std::vector<Deformation> deformations;
  PetscCall(ParseDeformations(comm, deform_text, scene, &deformations));

  // 3. Free vertices, METIS partition, contiguous block per rank.
  DofLayout layout;
  PetscCall(BuildDofLayout(comm, scene, &layout));
  const bool has_unknowns = layout.num_free() > 0;

  // 4. This rank's elements, the lumped mass and the initial state.
  const LocalElements elements = CollectLocalElements(scene, layout);
  State state;
  PetscCall(CreateState(comm, scene, layout, elements, &state));

  // 5. A = (1 + a dt) M + (b dt + dt^2) K and its solver (linear: factorised once).
  ImplicitEuler integrator;
  if (has_unknowns)
    PetscCall(integrator.Setup(comm, layout, elements, state.rest_positions, state.lumped_mass,
                               integration));
  if (!output.matrix_dir.empty() && has_unknowns)
    PetscCall(ExportMatrices(output.matrix_dir, layout, elements, integration.shear_scale,
                             state.lumped_mass, integration.alpha, integration.beta));

  // 6. Deformations due at t = 0, the output file with the mesh and frame 0.
  PetscCall(ApplyDeformations(scene, layout, 0.0, integration.dt, state, &integrator, &deformations));
  ResultWriter file;
  ResultWriter *writer = output.path.empty() ? nullptr : &file;
  if (writer) PetscCall(writer->Open(comm, output.path, scene, layout, state.positions));
  PetscCall(ComputeEnergies(integrator, has_unknowns, state, &report_init));
  PetscCall(PetscLogStagePop());
  PetscCall(PetscTime(&end));
  RunReport report = report_init;
  report.times.setup = end - start;
  if (writer) PetscCall(WriteFrame(writer, state, 0.0, output_stage, &report));

  // 7. Time loop: one solve per step, a frame every -output_every steps.
  for (PetscInt step = 1; step <= integration.steps; ++step) {
    const bool frame = writer && step % output.every == 0;
    PetscCall(PetscLogStagePush(step_stage));
    PetscCall(PetscTime(&start));
    PetscCall(ApplyDeformations(scene, layout, (step - 1) * integration.dt, integration.dt, state,
                                &integrator, &deformations));
    if (has_unknowns) PetscCall(integrator.Step(state.positions, state.velocities));
    if (frame || step == integration.steps)
      PetscCall(ComputeEnergies(integrator, has_unknowns, state, &report));
    PetscCall(PetscTime(&end));
    PetscCall(PetscLogStagePop());
    report.times.loop += end - start;
    report.steps = step;
    report.final_time = step * integration.dt;
    if (frame) PetscCall(WriteFrame(writer, state, report.final_time, output_stage, &report));
  }
  if (writer) {
    PetscCall(writer->Close());
    report.frames = writer->frames();
  }

  // 8. Summary on rank 0.
  PetscCall(PrintRunSummary(comm, scene, layout, integration, output, integrator.statistics(),
                            has_unknowns ? integrator.solver() : nullptr, report));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

int main(int argc, char **argv) {
  PetscCall(PetscInitialize(&argc, &argv, nullptr, help));
  PetscCall(InstallErrorHandler());
  const PetscErrorCode status = Run(PETSC_COMM_WORLD);
  PetscCall(PetscFinalize());
  return status == PETSC_SUCCESS ? 0 : 1;
}
