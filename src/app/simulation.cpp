#include "app/simulation.hpp"

#include "common/unused_options.hpp"
#include "solvers/solver.hpp"

namespace softbody {

PetscErrorCode ProcessRunOptions(MPI_Comm comm, RunOptions *o) {
  PetscFunctionBeginUser;
  PetscCall(ProcessSceneOptions(comm, &o->scene));
  PetscCall(ProcessPartitionOptions(comm, &o->partition));
  PetscCall(ProcessIntegratorOptions(comm, &o->integration));
  PetscCall(ProcessContactOptions(comm, &o->contact));
  PetscCall(ProcessDeformationOptions(comm, &o->deformations));
  PetscCall(ProcessOutputOptions(comm, &o->output));
  PetscCall(ProcessCheckpointOptions(comm, o->output, &o->checkpoints));
  PetscCall(ProcessRunControlOptions(comm, &o->control));
  PetscCall(ProcessBenchmarkOptions(comm, &o->bench));
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// Collective. Lists the solver's options under -help (there is no scene to set up).
PetscErrorCode PrintSolverHelp(MPI_Comm comm) {
  PetscFunctionBeginUser;
  KSP ksp;
  PetscCall(ApplyPresetDefaults(kDirectPreset));
  PetscCall(KSPCreate(comm, &ksp));
  PetscCall(KSPSetFromOptions(ksp));
  PetscCall(KSPDestroy(&ksp));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Sets up (under -help) a KSP with the solver's options prefix and
// the given KSP and PC types, so that their options are documented.
PetscErrorCode DescribeKsp(MPI_Comm comm, const char *prefix, KSPType ksp_type, PCType pc_type) {
  PetscFunctionBeginUser;
  KSP ksp;
  PC pc;
  PetscCall(KSPCreate(comm, &ksp));
  PetscCall(KSPSetOptionsPrefix(ksp, prefix));
  PetscCall(KSPSetType(ksp, ksp_type));
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PCSetType(pc, pc_type));
  PetscCall(KSPSetFromOptions(ksp));
  PetscCall(KSPDestroy(&ksp));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Describers of the options of `solver`: its own KSP and PC types,
// and a Krylov method, since a direct solve (preonly) reads no tolerances.
std::vector<Describer> SolverDescribers(KSP solver) {
  const char *prefix = nullptr;
  KSPType ksp_type = nullptr;
  PCType pc_type = nullptr;
  PC pc;
  const MPI_Comm comm = PetscObjectComm((PetscObject)solver);
  if (KSPGetOptionsPrefix(solver, &prefix) || KSPGetType(solver, &ksp_type) ||
      KSPGetPC(solver, &pc) || PCGetType(pc, &pc_type))
    return {};
  return {[=] { return DescribeKsp(comm, prefix, ksp_type, pc_type); },
          [=] { return DescribeKsp(comm, prefix, KSPCG, PCJACOBI); }};
}

// The run's statistics, stored as root attributes of the result file.
std::vector<std::pair<std::string, double>> FileStatistics(const RunReport &report,
                                                           const DofLayout &layout,
                                                           const SolverStatistics &solver,
                                                           const ContactSolver &contact) {
  return {{"setup_seconds", report.times.setup},
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
          {"accepted_steps", double(solver.accepted_steps)},
          {"rejected_steps", double(solver.rejected_steps)},
          {"min_dt", solver.accepted_steps ? solver.min_step : 0.0},
          {"max_dt", solver.max_step},
          {"system_fills", double(solver.assemblies)},
          {"contact_seconds", contact.statistics().seconds}};
}

}  // namespace

Simulation::~Simulation() {
  VecDestroy(&initial_positions_);
}

PetscErrorCode Simulation::Run(int *exit_code) {
  PetscFunctionBeginUser;
  PetscCall(UnreadOptions(&given_options_));
  PetscCall(RegisterLogStages());
  setup_timer_.emplace(Stages().setup, &report_.times.setup);
  PetscCall(ProcessRunOptions(comm_, &options_));
  PetscBool help;
  PetscCall(PetscOptionsHasHelp(nullptr, &help));
  if (help) {
    setup_timer_.reset();
    PetscCall(PrintSolverHelp(comm_));
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  PetscCall(SetUp());
  PetscCall(TimeLoop());
  PetscCall(CloseOutput());
  PetscCall(PrintSummary(exit_code));
  PetscCall(WarnUnusedOptions());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Everything up to frame 0; the set-up timer stops before frame 0 is written.
PetscErrorCode Simulation::SetUp() {
  PetscFunctionBeginUser;
  PetscCall(CheckFiles());
  PetscCall(ReadScene());
  PetscCall(DistributeMesh());
  PetscCall(CreateInitialState());
  PetscCall(OpenOutput());
  PetscCall(SetUpContact());
  share_ = MeshShare();  // set-up only: the state and the result file hold what they need
  PetscCall(SetUpSolvers());
  PetscCall(StartTimeLoop());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Fails early: the output can be written, the restart file has a checkpoint. A
// restart without -output continues the restart file itself.
PetscErrorCode Simulation::CheckFiles() {
  PetscFunctionBeginUser;
  OutputOptions &output = options_.output;
  if (restart() && output.path.empty()) output.path = options_.checkpoints.restart_path;
  if (!output.path.empty()) PetscCall(CheckOutputPath(comm_, "-output", output.path));
  if (restart()) PetscCall(CheckRestartFile(comm_, options_.checkpoints.restart_path));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Rank 0 reads and validates the scene and its meshes; every rank the -deform
// events. Each rank gets its shares of the meshes (mesh_share.hpp): .h5 meshes
// are read in slabs by every rank, never whole, and contact builds its
// structures from the shares; -scene_replicate sends every mesh whole to every
// rank. Bodies that nothing can set in motion add no unknowns (partition.hpp);
// not on a restart (its bodies move as the checkpoint says) or when
// -export_matrices asks for the matrices of every free body.
PetscErrorCode Simulation::ReadScene() {
  PetscFunctionBeginUser;
  const ContactOptions &contact = options_.contact;
  PetscCall(LoadScene(comm_, options_.scene, true, &scene_));
  PetscCall(ParseDeformations(comm_, options_.deformations, scene_, &deformations_));
  holding_ = options_.scene.replicate ? MeshHolding::kWhole : MeshHolding::kSlabs;
  PetscCall(DistributeScene(comm_, options_.scene.meshing, holding_, &scene_, &share_));
  if (!restart() && options_.output.matrix_dir.empty()) {
    MotionSources sources{options_.integration.gravity.squaredNorm() > 0, bool(contact.ground),
                          !contact.constraints_path.empty() || contact.edge_bounds,
                          std::vector<bool>(scene_.bodies.size(), false)};
    for (const Deformation &d : deformations_) sources.deformed[d.body] = true;
    int marked;
    PetscCall(MarkBodiesAtRest(comm_, sources, &scene_, &share_, &marked));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The numbering of the free vertices and the tets this rank assembles
// (partition.hpp, migration.hpp).
PetscErrorCode Simulation::DistributeMesh() {
  PetscFunctionBeginUser;
  PetscCall(BuildDofLayout(comm_, options_.partition, &share_, &layout_));
  // Contact (when it may run) and -export_matrices still read the replicated numbering.
  if (holding_ == MeshHolding::kWhole || ContactMayRun(options_.contact, scene_.bodies.size()) ||
      !options_.output.matrix_dir.empty())
    PetscCall(ReplicateNumbering(comm_, share_, &layout_));
  PetscCall(MigrateTets(comm_, share_, layout_, &tets_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// This rank's elements, the lumped mass and the initial state; a restart
// replaces the state by its checkpoint's (checked against the scene) and keeps
// the original initial positions to prime the solver.
PetscErrorCode Simulation::CreateInitialState() {
  PetscFunctionBeginUser;
  elements_ = CollectLocalElements(scene_, layout_, tets_);
  PetscCall(CreateState(comm_, share_, layout_, elements_, &state_));
  if (restart()) {
    PetscCall(VecDuplicate(state_.positions, &initial_positions_));
    PetscCall(VecCopy(state_.positions, initial_positions_));
    PetscCall(ReadCheckpoint(comm_, options_.checkpoints.restart_path, scene_, share_, layout_,
                             deformations_.size(), options_.integration.steps, state_.positions,
                             state_.velocities, &start_));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The output file, before the costly set-up: new, or continuing the restart
// file's frames up to its checkpoint.
PetscErrorCode Simulation::OpenOutput() {
  PetscFunctionBeginUser;
  if (options_.output.path.empty()) PetscFunctionReturn(PETSC_SUCCESS);
  writer_ = &file_;
  const Continuation continuation{options_.checkpoints.restart_path, start_.frames};
  PetscCall(writer_->Open(comm_, options_.output, scene_, layout_, share_, state_.positions,
                          restart() ? &continuation : nullptr));
  const Eigen::Vector3d &gravity = options_.integration.gravity;
  const double ground_y = options_.contact.ground_y;
  PetscCall(writer_->WriteWorld(gravity.data(), options_.contact.ground ? &ground_y : nullptr));
  PetscCall(writer_->WriteTextAttribute("integrator", kTimeSchemes[options_.integration.scheme]));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collision structures and constraints, only as far as the scene needs them,
// built from the shares and the fixed bodies' meshes; none of these is kept
// after it, so the solver's set-up runs without them.
PetscErrorCode Simulation::SetUpContact() {
  PetscFunctionBeginUser;
  options_.contact.gravity = options_.integration.gravity.norm();
  PetscCall(contact_.Setup(comm_, scene_, share_, layout_, state_.lumped_mass, options_.contact));
  if (scene_.meshes_held) scene_.ReleaseMeshes();
  PetscFunctionReturn(PETSC_SUCCESS);
}

// A = (1 + a dt) M + (b dt + dt^2) K and its solver (linear: factorised once).
PetscErrorCode Simulation::SetUpSolvers() {
  PetscFunctionBeginUser;
  IntegratorOptions &integration = options_.integration;
  dt_first_ = TimeStepAt(integration, 0.0);
  integration.dt = TimeStepAt(integration, start_.time);
  if (has_unknowns()) {
    PetscCall(integrator_.Setup(comm_, scene_, layout_, std::move(tets_), elements_,
                                state_.rest_positions, state_.lumped_mass, integration));
    PetscCall(integrator_.SetBodies(OwnedVertexBodies(scene_, layout_),
                                    static_cast<int>(scene_.bodies.size())));
  }
  if (!options_.output.matrix_dir.empty() && has_unknowns())
    PetscCall(ExportMatrices(options_.output.matrix_dir, layout_, elements_,
                             integration.shear_scale, state_.lumped_mass, integration.alpha,
                             integration.beta));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// A fresh start applies the deformations due at t = 0 and writes frame 0; a
// restart takes over the checkpoint's loop state.
PetscErrorCode Simulation::StartTimeLoop() {
  PetscFunctionBeginUser;
  if (restart()) {
    PetscCall(Resume());
    PetscCall(VecDestroy(&initial_positions_));
  } else {
    PetscCall(ApplyDeformations(0.0, options_.integration.dt));
  }
  if (has_unknowns())
    PetscCall(integrator_.Energies(state_.positions, state_.velocities, &report_.energy));
  setup_timer_.reset();
  if (writer_ && !restart()) {
    TimedStage timer(Stages().output, &report_.times.output);
    PetscCall(writer_->WriteFrame(0.0, state_.positions, state_.velocities, report_.energy));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// What a restart takes over from its checkpoint besides x and v: the loop state,
// and the solver state of the original run (primed with that run's first step:
// its initial positions, deformed as due at t = 0).
PetscErrorCode Simulation::Resume() {
  PetscFunctionBeginUser;
  std::vector<Deformation> at_start = deformations_;
  bool changed;
  PetscCall(ApplyDueDeformations(scene_, layout_, 0.0, 0.5 * dt_first_, state_.lumped_mass,
                                 initial_positions_, &at_start, &changed));
  if (has_unknowns()) {
    PetscCall(integrator_.PrimeSolver(initial_positions_, dt_first_));
    SchemeHistory history;  // the time scheme's previous velocities or accelerations
    bool found = false;
    PetscCall(integrator_.GetHistory(&history));
    if (writer_)  // a restart always writes (into the restart file by default)
      PetscCall(ReadCheckpointHistory(comm_, options_.checkpoints.restart_path,
                                      writer_->natural_slab(), &history, &found));
    PetscCall(integrator_.SetHistory(history.scalars, found));
  }
  for (size_t i = 0; i < deformations_.size(); ++i)
    deformations_[i].applied = start_.deformations_applied[i] != 0;
  contact_.RestoreRestingContacts(start_.resting_contacts, start_.resting_reactions);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Prescribed deformations due at `time` (s), applied to the state at that time.
PetscErrorCode Simulation::ApplyDeformations(PetscReal time, PetscReal dt) {
  PetscFunctionBeginUser;
  if (deformations_.empty()) PetscFunctionReturn(PETSC_SUCCESS);
  bool changed;
  PetscCall(ApplyDueDeformations(scene_, layout_, time, 0.5 * dt, state_.lumped_mass,
                                 state_.positions, &deformations_, &changed));
  if (changed) integrator_.PositionsChanged();
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Steps start + 1 .. -steps; after SIGINT/SIGTERM the ranks stop together after
// the step, with its frame.
PetscErrorCode Simulation::TimeLoop() {
  PetscFunctionBeginUser;
  const IntegratorOptions &integration = options_.integration;
  benchmark_.emplace(options_.bench);
  PetscCall(progress_.Start(comm_, options_.control, start_.step, integration.steps));
  report_.first_step = report_.steps = start_.step;
  time_ = report_.final_time = start_.time;
  PetscCall(AgreeOnStop(comm_, &stop_signal_));
  for (PetscInt step = start_.step + 1; step <= integration.steps && !stop_signal_; ++step) {
    const PetscLogDouble loop_before = report_.times.loop;
    const SolverStatistics solver_before = integrator_.statistics();
    const PetscLogDouble cpu_before = ProcessCpuSeconds();
    PetscCall(Step());
    PetscCall(AgreeOnStop(comm_, &stop_signal_));
    PetscCall(RecordStep(step, loop_before));
    const PetscLogDouble cpu_after = ProcessCpuSeconds();
    StepKindCost &kind = has_unknowns() && integrator_.last_step_had_contact()
                             ? report_.contact_steps
                             : report_.free_steps;
    ++kind.steps;
    kind.wall += report_.times.loop - loop_before;
    kind.cpu += cpu_after - cpu_before;
    kind.solves += integrator_.statistics().solves - solver_before.solves;
    kind.iterations += integrator_.statistics().total_iterations - solver_before.total_iterations;
  }
  progress_.Finish();
  if (has_unknowns()) PetscCall(benchmark_->Finish(comm_, scene_, &integrator_, state_.positions));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// One time step: the solve (collisions and constraints inside it), then the
// deformations due by the new time, so that the frame at that time shows them.
PetscErrorCode Simulation::Step() {
  PetscFunctionBeginUser;
  TimedStage timer(Stages().step, &report_.times.loop);
  const PetscReal dt = TimeStepAt(options_.integration, time_);
  if (has_unknowns() && dt != integrator_.time_step()) PetscCall(integrator_.SetTimeStep(dt));
  if (has_unknowns()) PetscCall(integrator_.Step(state_.positions, state_.velocities, &contact_));
  time_ += dt;
  PetscCall(ApplyDeformations(time_, dt));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// After step `step`: its energies when a frame or the end needs them, the
// benchmark's record, the frame, the checkpoint and the progress line.
PetscErrorCode Simulation::RecordStep(PetscInt step, PetscLogDouble loop_before) {
  PetscFunctionBeginUser;
  const bool last = step == options_.integration.steps || stop_signal_;
  const bool frame = writer_ && (step % options_.output.every == 0 || stop_signal_);
  if (has_unknowns() && (frame || last)) {
    // The corotational element pass behind the energies is reused by the next step.
    TimedStage timer(Stages().step, &report_.times.loop);
    PetscCall(integrator_.Energies(state_.positions, state_.velocities, &report_.energy));
  }
  benchmark_->RecordStep(report_.times.loop - loop_before, integrator_.statistics());
  report_.steps = step;
  report_.final_time = time_;
  if (frame) {
    TimedStage timer(Stages().output, &report_.times.output);
    PetscCall(writer_->WriteFrame(time_, state_.positions, state_.velocities, report_.energy));
  }
  const PetscInt every = options_.checkpoints.every;
  if (every > 0 && (step % every == 0 || last)) {
    TimedStage timer(Stages().output, &report_.times.output);
    PetscCall(Checkpoint(step));
    report_.checkpoint_step = step;
  }
  progress_.Update(step, time_, integrator_.statistics().last_iterations);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Stores the loop state after `step` as a checkpoint in the result file.
PetscErrorCode Simulation::Checkpoint(PetscInt step) {
  PetscFunctionBeginUser;
  LoopState loop;
  loop.step = step;
  loop.time = time_;
  loop.frames = writer_->frames();
  for (const Deformation &d : deformations_) loop.deformations_applied.push_back(d.applied ? 1 : 0);
  PetscCall(contact_.GatherRestingContacts(&loop.resting_contacts, &loop.resting_reactions));
  SchemeHistory history;
  if (has_unknowns()) PetscCall(integrator_.GetHistory(&history));
  PetscCall(WriteCheckpoint(writer_, loop, state_.positions, state_.velocities,
                            has_unknowns() ? &history : nullptr));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Closes the result file with the run's statistics (and the benchmark's).
PetscErrorCode Simulation::CloseOutput() {
  PetscFunctionBeginUser;
  if (!writer_) PetscFunctionReturn(PETSC_SUCCESS);
  std::vector<std::pair<std::string, double>> statistics =
      FileStatistics(report_, layout_, integrator_.statistics(), contact_);
  statistics.insert(statistics.end(), benchmark_->attributes().begin(),
                    benchmark_->attributes().end());
  PetscCall(writer_->Close(statistics, stop_signal_));
  report_.frames = writer_->frames();
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The summary on rank 0 (not with -quiet); an interrupted run says so and exits
// with 128 + the signal.
PetscErrorCode Simulation::PrintSummary(int *exit_code) {
  PetscFunctionBeginUser;
  report_.restarted_from = options_.checkpoints.restart_path;
  if (!options_.control.quiet)
    PetscCall(PrintRunSummary(comm_, scene_, layout_, options_.integration, options_.output,
                              integrator_.statistics(),
                              has_unknowns() ? integrator_.solver() : nullptr, contact_, report_));
  if (options_.control.rank_messages) PetscCall(PrintRankMessages(comm_));
  if (stop_signal_) {
    PetscCall(
        PrintInterruption(comm_, stop_signal_, options_.integration, options_.output, report_));
    *exit_code = 128 + stop_signal_;
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Options the user gave that nothing read (unused_options.hpp); also with
// -quiet, as a warning is not a summary.
PetscErrorCode Simulation::WarnUnusedOptions() {
  PetscFunctionBeginUser;
  const MPI_Comm comm = comm_;
  std::vector<Describer> describers{[comm] {
    RunOptions defaults;  // every option softbody reads, into throwaway structs
    return ProcessRunOptions(comm, &defaults);
  }};
  if (has_unknowns()) {
    const std::vector<Describer> solver = SolverDescribers(integrator_.solver());
    describers.insert(describers.end(), solver.begin(), solver.end());
  }
  PetscCall(softbody::WarnUnusedOptions(comm_, given_options_, describers));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
