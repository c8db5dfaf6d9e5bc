#include "app/report.hpp"

#include <algorithm>
#include <string>

#include "app/run_control.hpp"

namespace softbody {

PetscErrorCode PrintRunSummary(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                               const IntegratorOptions &o, const OutputOptions &output,
                               const SolverStatistics &solver, KSP ksp,
                               const ContactSolver &contact, const RunReport &r) {
  PetscFunctionBeginUser;
  int fixed_bodies = 0, resting_bodies = 0;
  PetscInt fixed_vertices = 0, resting_vertices = 0;
  for (const Body &body : scene.bodies)
    if (body.at_rest) {
      ++resting_bodies;
      resting_vertices += body.mesh.num_vertices();
    } else if (body.fixed) {
      ++fixed_bodies;
      fixed_vertices += body.mesh.num_vertices();
    }
  const PetscInt stray =
      scene.num_vertices() - fixed_vertices - resting_vertices - layout.num_free();
  PetscInt min_dofs = PETSC_MAX_INT, max_dofs = 0;
  for (PetscMPIInt q = 0; q < layout.size; ++q) {
    const PetscInt dofs = 3 * (layout.vertex_start[q + 1] - layout.vertex_start[q]);
    min_dofs = std::min(min_dofs, dofs);
    max_dofs = std::max(max_dofs, dofs);
  }

  PetscCall(PetscPrintf(comm, "softbody run summary\n"));
  PetscCall(PetscPrintf(comm, "  scene        %s: %zu bodies (%d fixed), %d vertices, %lld tets\n",
                        scene.path.c_str(), scene.bodies.size(), fixed_bodies, scene.num_vertices(),
                        (long long)scene.num_tets()));
  PetscCall(PetscPrintf(comm,
                        "  unknowns     %" PetscInt_FMT " DOFs on %d ranks (%" PetscInt_FMT
                        " to %" PetscInt_FMT " per rank, METIS partition)\n",
                        3 * layout.num_free(), layout.size, min_dofs, max_dofs));
  PetscCall(PetscPrintf(comm,
                        "  model        %s elasticity, shear scale %g; damping a = %g 1/s, "
                        "b = %g s; dt = %g s, %" PetscInt_FMT " steps",
                        kElasticityModes[o.mode], (double)o.shear_scale, (double)o.alpha,
                        (double)o.beta, (double)o.dt, r.steps));
  if (!r.restarted_from.empty())
    PetscCall(PetscPrintf(comm, " (restarted at step %" PetscInt_FMT " from %s)", r.first_step,
                          r.restarted_from.c_str()));
  if (o.gravity.squaredNorm() > 0)
    PetscCall(PetscPrintf(comm, "; gravity (%g, %g, %g) m/s^2", o.gravity[0], o.gravity[1],
                          o.gravity[2]));
  if (solver.time_step_changes)
    PetscCall(PetscPrintf(comm, "; %" PetscInt_FMT " time step changes", solver.time_step_changes));
  PetscCall(PetscPrintf(comm, "\n"));
  if (contact.active()) {
    const ContactStatistics &c = contact.statistics();
    PetscCall(PetscPrintf(comm, "  contact      %s; %" PetscInt_FMT " vertex collisions",
                          contact.Description().c_str(), c.collisions));
    if (c.feature_contacts)
      PetscCall(PetscPrintf(comm, ", %" PetscInt_FMT " sharp-edge contacts", c.feature_contacts));
    PetscInt grid_builds = contact.free_grid_builds();
    PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, &grid_builds, 1, MPIU_INT, MPI_MAX, comm));
    if (contact.tracks_free_bodies())
      PetscCall(PetscPrintf(comm,
                            "; moving obstacles' grids built in %" PetscInt_FMT
                            " passes (only where bodies' boxes met)"
                            ", free state gathered %" PetscInt_FMT " times",
                            grid_builds, c.gathers));
    if (contact.num_constraints())
      PetscCall(PetscPrintf(comm,
                            "; constraint sweeps %" PetscInt_FMT " total, %" PetscInt_FMT
                            " max per step, worst relative violation %.1e",
                            c.constraint_sweeps, c.max_constraint_sweeps,
                            (double)c.max_constraint_violation));
    PetscCall(PetscPrintf(comm, "\n"));
  }

  PetscCall(
      PetscPrintf(comm, "  left out     D never formed (A = (1 + a dt) M + (b dt + dt^2) K)"));
  if (o.mode == MODE_COROTATIONAL)
    PetscCall(PetscPrintf(comm, "; K never formed (A refilled in place)"));
  else
    PetscCall(PetscPrintf(comm, "; reassembly (K and A assembled once)"));
  if (layout.size > 1)
    PetscCall(
        PetscPrintf(comm, "; matrix entries sent between ranks (each rank fills its own rows)"));
  if (fixed_bodies)
    PetscCall(PetscPrintf(comm, "; %d fixed bodies (%" PetscInt_FMT " vertices, no unknowns)",
                          fixed_bodies, fixed_vertices));
  if (resting_bodies)
    PetscCall(PetscPrintf(
        comm,
        "; %d bodies at rest (no velocity, gravity, deformation, contact or constraint: "
        "%" PetscInt_FMT " vertices, no unknowns)",
        resting_bodies, resting_vertices));
  if (stray) PetscCall(PetscPrintf(comm, "; %" PetscInt_FMT " vertices in no tet", stray));
  if (scene.ignored_fixed_velocities)
    PetscCall(PetscPrintf(comm, "; %d initial velocities on fixed bodies",
                          scene.ignored_fixed_velocities));
  if (o.alpha == 0) PetscCall(PetscPrintf(comm, "; mass damping (a = 0)"));
  if (o.beta == 0) PetscCall(PetscPrintf(comm, "; stiffness damping (b = 0)"));
  if (o.gravity.squaredNorm() == 0) PetscCall(PetscPrintf(comm, "; external force (no gravity)"));
  if (!contact.active())
    PetscCall(PetscPrintf(comm, "; collision structures and constraint pass (nothing to collide)"));
  if (output.path.empty()) PetscCall(PetscPrintf(comm, "; output (no -output)"));
  PetscCall(PetscPrintf(comm, "\n"));

  if (ksp) {
    KSPType ksp_type;
    PCType pc_type;
    PC pc;
    PetscCall(KSPGetType(ksp, &ksp_type));
    PetscCall(KSPGetPC(ksp, &pc));
    PetscCall(PCGetType(pc, &pc_type));
    // -pc_type redundant factorises on every rank: name the inner solver.
    PetscBool redundant;
    PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCREDUNDANT, &redundant));
    PC factor_pc = pc;
    if (redundant) {
      KSP inner;
      PetscCall(PCRedundantGetKSP(pc, &inner));
      PetscCall(KSPGetPC(inner, &factor_pc));
      PetscCall(PCGetType(factor_pc, &pc_type));
    }
    MatSolverType factor_package = nullptr;
    PetscBool factored;
    PetscCall(PetscObjectTypeCompareAny((PetscObject)factor_pc, &factored, PCCHOLESKY, PCLU, ""));
    if (factored) PetscCall(PCFactorGetMatSolverType(factor_pc, &factor_package));
    PetscBool supernodal;
    PetscCall(PetscObjectTypeCompare((PetscObject)factor_pc, "supernodal", &supernodal));
    if (supernodal) {
      factored = PETSC_TRUE;
      factor_package = "CHOLMOD";
    }
    PetscCall(PetscPrintf(comm, "  solver       %s + %s%s%s%s", ksp_type, pc_type,
                          factor_package ? " " : "", factor_package ? factor_package : "",
                          redundant ? " (whole A on every rank)" : ""));
    if (o.mode == MODE_LINEAR)
      PetscCall(PetscPrintf(comm, ", %s once in %.3g s", factored ? "factorised" : "set up",
                            solver.factor_seconds));
    else if (std::string(pc_type) == "warp")
      PetscCall(PetscPrintf(comm,
                            ", A refilled every step, preconditioned by the linear system's factor "
                            "(once per time step size) rotated per vertex"));
    else
      PetscCall(PetscPrintf(comm, ", A refilled and %s again every step",
                            factored ? "factorised" : "set up"));
    PetscCall(PetscPrintf(comm, "; %" PetscInt_FMT " solves", solver.solves));
    if (solver.solves)
      PetscCall(PetscPrintf(
          comm, ", iterations per step %.3g mean, %" PetscInt_FMT " min, %" PetscInt_FMT " max",
          (double)solver.total_iterations / solver.solves, solver.min_iterations,
          solver.max_iterations));
    if (solver.fallback_solves)
      PetscCall(PetscPrintf(comm,
                            "; %" PetscInt_FMT
                            " solves broke down and were repeated by the direct fallback "
                            "(MUMPS Cholesky)",
                            solver.fallback_solves));
    PetscCall(PetscPrintf(comm, "\n"));
    if (solver.newton_iterations > 0)
      PetscCall(PetscPrintf(comm,
                            "  corotational %" PetscInt_FMT
                            " linearised solves without contact, at most %" PetscInt_FMT
                            " in one step, %" PetscInt_FMT " line-search halvings, %" PetscInt_FMT
                            " steps stopped short of -newton_rtol (stalled, no energy gain)\n",
                            solver.newton_iterations, solver.max_newton_iterations,
                            solver.backtracks, solver.newton_stopped_short));
  } else {
    PetscCall(PetscPrintf(comm, "  solver       none: the scene has no unknowns\n"));
  }
  const PetscInt taken = r.steps - r.first_step;
  const double per_step = taken > 0 ? r.times.loop / taken : 0;
  PetscCall(PetscPrintf(comm, "  time         set-up %.3f s, time loop %.3f s (%.3g ms/step",
                        r.times.setup, r.times.loop, 1e3 * per_step));
  if (contact.active())
    PetscCall(PetscPrintf(comm, ", of which contact %.3f s", contact.statistics().seconds));
  PetscCall(PetscPrintf(comm, "), output %.3f s\n", r.times.output));
  PetscCall(PetscPrintf(comm, "  energy       at t = %g s: kinetic %.6e J, elastic %.6e J",
                        (double)r.final_time, (double)r.energy.kinetic, (double)r.energy.elastic));
  if (o.gravity.squaredNorm() > 0)
    PetscCall(PetscPrintf(comm, ", gravitational %.6e J", (double)r.energy.gravitational));
  PetscCall(PetscPrintf(comm, "\n"));
  if (!output.path.empty()) {
    PetscCall(PetscPrintf(comm, "  output       %s (%" PetscInt_FMT " frames) and its .xdmf",
                          output.path.c_str(), r.frames));
    if (r.checkpoint_step >= 0)
      PetscCall(PetscPrintf(comm, "; checkpoint at step %" PetscInt_FMT, r.checkpoint_step));
    PetscCall(PetscPrintf(comm, "\n"));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PrintInterruption(MPI_Comm comm, int signal, const IntegratorOptions &integration,
                                 const OutputOptions &output, const RunReport &r) {
  PetscFunctionBeginUser;
  PetscCall(PetscFPrintf(comm, PETSC_STDERR,
                         "softbody: stopped by %s after step %" PetscInt_FMT " of %" PetscInt_FMT
                         " (t = %g s)",
                         SignalName(signal), r.steps, integration.steps, (double)r.final_time));
  if (!output.path.empty()) {
    PetscCall(PetscFPrintf(comm, PETSC_STDERR,
                           "; %s holds %" PetscInt_FMT " frames, marked incomplete",
                           output.path.c_str(), r.frames));
    if (r.checkpoint_step >= 0)
      PetscCall(PetscFPrintf(comm, PETSC_STDERR,
                             "; continue with -restart %s (checkpoint at step %" PetscInt_FMT ")",
                             output.path.c_str(), r.checkpoint_step));
  }
  PetscCall(PetscFPrintf(comm, PETSC_STDERR, "\n"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
