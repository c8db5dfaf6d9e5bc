#include "app/report.hpp"

#include <algorithm>
#include <ctime>
#include <string>
#include <vector>

#include "app/run_control.hpp"
#include "common/held_bytes.hpp"
#include "common/number_format.hpp"

namespace softbody {

namespace {

// Bodies without unknowns, by why.
struct BodiesWithoutUnknowns {
  int fixed_bodies = 0, resting_bodies = 0;
  PetscInt fixed_vertices = 0, resting_vertices = 0;
  PetscInt stray_vertices = 0;  // in no tet
};

BodiesWithoutUnknowns CountBodiesWithoutUnknowns(const Scene &scene, const DofLayout &layout) {
  BodiesWithoutUnknowns b;
  for (const Body &body : scene.bodies)
    if (body.at_rest) {
      ++b.resting_bodies;
      b.resting_vertices += body.num_vertices();
    } else if (body.fixed) {
      ++b.fixed_bodies;
      b.fixed_vertices += body.num_vertices();
    }
  b.stray_vertices =
      scene.num_vertices() - b.fixed_vertices - b.resting_vertices - layout.num_free();
  return b;
}

// How the unknowns were split, for the "unknowns" line.
const char *PartitionNote(Partitioner partitioner) {
  switch (partitioner) {
    case Partitioner::kMetis:
      return ", METIS partition on rank 0";
    case Partitioner::kPtScotch:
      return ", PT-Scotch partition";
    default:
      return "";
  }
}

// How the meshes were read and held, for the "scene" line ("" on one rank, unless
// a mesh file was read in slabs).
std::string MeshHoldingNote(const Scene &scene, int ranks) {
  const int in_slabs = scene.meshes_read_in_slabs;
  const bool on_rank0 = in_slabs < static_cast<int>(scene.bodies.size());
  if (ranks == 1 && in_slabs == 0) return "";
  if (scene.meshes_held) return "; meshes whole on every rank";
  if (scene.meshes_released)
    return "; meshes whole on every rank until contact's set-up, then released";
  std::string read;
  if (in_slabs == 0)
    read = "meshes read on rank 0, then held in slabs";
  else if (!on_rank0)
    read =
        in_slabs == 1 ? "mesh read in slabs by every rank" : "meshes read in slabs by every rank";
  else
    read = std::to_string(in_slabs) + " of " + std::to_string(scene.bodies.size()) +
           " meshes read in slabs by every rank, the rest on rank 0, then held in slabs";
  return "; " + read;
}

// "  scene ..." and "  unknowns ..." lines.
PetscErrorCode PrintSceneAndUnknowns(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                                     const BodiesWithoutUnknowns &b) {
  PetscFunctionBeginUser;
  PetscInt min_dofs = PETSC_MAX_INT, max_dofs = 0;
  for (PetscMPIInt q = 0; q < layout.size; ++q) {
    const PetscInt dofs = 3 * (layout.vertex_start[q + 1] - layout.vertex_start[q]);
    min_dofs = std::min(min_dofs, dofs);
    max_dofs = std::max(max_dofs, dofs);
  }
  const size_t bodies = scene.bodies.size();
  const std::string held = MeshHoldingNote(scene, layout.size);
  PetscCall(PetscPrintf(comm, "  scene        %s: %zu %s (%d fixed), %d vertices, %lld tets%s\n",
                        scene.path.c_str(), bodies, bodies == 1 ? "body" : "bodies", b.fixed_bodies,
                        scene.num_vertices(), (long long)scene.num_tets(), held.c_str()));
  PetscCall(PetscPrintf(comm,
                        "  unknowns     %" PetscInt_FMT " DOFs on %d %s (%" PetscInt_FMT
                        " to %" PetscInt_FMT " per rank%s; %s vertex order)\n",
                        3 * layout.num_free(), layout.size, layout.size == 1 ? "rank" : "ranks",
                        min_dofs, max_dofs, PartitionNote(layout.partitioner),
                        kVertexOrderNames[static_cast<int>(layout.vertex_order)]));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// -integrator's name and what it is, e.g. "alpha (generalized-alpha, rho_inf 0.9)".
std::string SchemeDescription(const IntegratorOptions &o) {
  const char *const what[] = {"backward Euler", "BDF2", "Newmark, trapezoidal rule",
                              "generalized-alpha"};
  std::string text = std::string(kTimeSchemes[o.scheme]) + " (" + what[o.scheme];
  if (o.scheme == SCHEME_ALPHA) text += ", rho_inf " + FormatNumber(o.rho_inf);
  return text + ")";
}

// "  model ..." line: elasticity, damping, integrator, time step, gravity.
PetscErrorCode PrintModel(MPI_Comm comm, const IntegratorOptions &o, const SolverStatistics &solver,
                          const RunReport &r) {
  PetscFunctionBeginUser;
  PetscCall(PetscPrintf(comm,
                        "  model        %s elasticity, shear scale %s; damping a = %s 1/s, "
                        "b = %s s; integrator %s; dt = %s s, %" PetscInt_FMT " steps",
                        kElasticityModes[o.mode], FormatNumber(o.shear_scale).c_str(),
                        FormatNumber(o.alpha).c_str(), FormatNumber(o.beta).c_str(),
                        SchemeDescription(o).c_str(), FormatNumber(o.dt).c_str(), r.steps));
  if (!r.restarted_from.empty())
    PetscCall(PetscPrintf(comm, " (restarted at step %" PetscInt_FMT " from %s)", r.first_step,
                          r.restarted_from.c_str()));
  if (o.gravity.squaredNorm() > 0)
    PetscCall(PetscPrintf(comm, "; gravity (%s, %s, %s) m/s^2", FormatNumber(o.gravity[0]).c_str(),
                          FormatNumber(o.gravity[1]).c_str(), FormatNumber(o.gravity[2]).c_str()));
  if (solver.time_step_changes)
    PetscCall(PetscPrintf(comm, "; %" PetscInt_FMT " time step changes", solver.time_step_changes));
  if (o.adaptive)
    PetscCall(PetscPrintf(comm,
                          "; -dt_adapt, -tol %s: %" PetscInt_FMT
                          " substeps accepted, %" PetscInt_FMT " rejected, dt %s to %s s",
                          FormatNumber(o.tolerance).c_str(), solver.accepted_steps,
                          solver.rejected_steps, FormatNumber(solver.min_step).c_str(),
                          FormatNumber(solver.max_step).c_str()));
  PetscCall(PetscPrintf(comm, "\n"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. "  guard ..." line: what the collision guard did (the same on
// every rank), and the bytes the busiest rank sent for it (bytes: this rank's).
PetscErrorCode PrintGuard(MPI_Comm comm, const GuardStatistics *g, PetscInt64 bytes) {
  PetscFunctionBeginUser;
  if (!g) PetscFunctionReturn(PETSC_SUCCESS);
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &bytes, 1, MPIU_INT64, MPI_MAX, comm));
  PetscCall(PetscPrintf(
      comm,
      "  guard        %" PetscInt_FMT " passes with colliding surface pairs (%" PetscInt_FMT
      " pairs, %" PetscInt_FMT " rounds, at most %" PetscInt_FMT
      " in a step); zones moved %" PetscInt_FMT " vertices (%" PetscInt_FMT
      " frozen); %" PetscInt_FMT " pairs tested (self-contact candidates listed %" PetscInt_FMT
      " times, against fixed and resting bodies %" PetscInt_FMT " times, all ranks); %" PetscInt_FMT
      " pairs closer than the separation at a step's start (%" PetscInt_FMT
      " at the scene's start), not guarded; %" PetscInt_FMT " probes, %" PetscInt_FMT
      " of them repeating a clean one's positions (no detection); %.3f s",
      g->passes_guarded, g->collisions, g->rounds, g->max_rounds, g->zone_vertices,
      g->frozen_vertices, g->candidates, g->rebuilds, g->static_rebuilds, g->close_pairs,
      g->initial_close_pairs, g->probes, g->repeated, (double)g->seconds));
  if (bytes > 0)
    PetscCall(PetscPrintf(comm, "; halo and pairs: %.3g kB sent by the busiest rank in all",
                          bytes / 1e3));
  PetscCall(PetscPrintf(comm, "\n"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. The fixed tets' part of the "contact" line: the most a rank
// holds of them, how often they were fetched, and a warning if a query fell
// outside a rank's region.
PetscErrorCode PrintFixedTets(MPI_Comm comm, const ContactSolver &contact) {
  PetscFunctionBeginUser;
  const FixedTets &fixed = contact.fixed_tets();
  if (fixed.scene_count() == 0) PetscFunctionReturn(PETSC_SUCCESS);
  PetscInt counts[2] = {static_cast<PetscInt>(fixed.held().size()), contact.fixed_outside_region()};
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, counts, 2, MPIU_INT, MPI_MAX, comm));
  PetscCall(PetscPrintf(comm,
                        "; fixed tets held by a rank at most %" PetscInt_FMT
                        " of %lld (fetched %" PetscInt_FMT " times around its vertices)",
                        counts[0], static_cast<long long>(fixed.scene_count()), fixed.fetches()));
  if (counts[1] > 0)
    PetscCall(PetscPrintf(comm,
                          " (WARNING: %" PetscInt_FMT
                          " queries outside a rank's region of fixed tets: please report)",
                          counts[1]));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. "  contact ..." line, when the scene has collisions or constraints.
PetscErrorCode PrintContact(MPI_Comm comm, const ContactSolver &contact) {
  PetscFunctionBeginUser;
  if (!contact.active()) PetscFunctionReturn(PETSC_SUCCESS);
  const ContactStatistics &c = contact.statistics();
  PetscCall(PetscPrintf(comm, "  contact      %s; %" PetscInt_FMT " vertex collisions",
                        contact.Description().c_str(), c.collisions));
  if (c.feature_contacts)
    PetscCall(PetscPrintf(comm, ", %" PetscInt_FMT " sharp-edge contacts", c.feature_contacts));
  PetscInt grid_builds = contact.free_grid_builds();
  PetscCallMPI(MPIU_Allreduce(MPI_IN_PLACE, &grid_builds, 1, MPIU_INT, MPI_MAX, comm));
  PetscInt64 bytes = contact.exchange_bytes();
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &bytes, 1, MPIU_INT64, MPI_MAX, comm));
  if (contact.tracks_free_bodies())
    PetscCall(PetscPrintf(comm,
                          "; moving obstacles' grids built in %" PetscInt_FMT
                          " passes (only where bodies' boxes met)",
                          grid_builds));
  PetscCall(PrintFixedTets(comm, contact));
  if (c.exchanges)
    PetscCall(PetscPrintf(comm,
                          "; free state exchanged %" PetscInt_FMT
                          " times (halo and constrained vertices: %.3g kB sent by the busiest "
                          "rank in all)",
                          c.exchanges, bytes / 1e3));
  if (contact.num_constraints())
    PetscCall(PetscPrintf(comm,
                          "; constraint sweeps %" PetscInt_FMT " total, %" PetscInt_FMT
                          " max per step, worst relative violation %.1e",
                          c.constraint_sweeps, c.max_constraint_sweeps,
                          (double)c.max_constraint_violation));
  PetscCall(PetscPrintf(comm, "\n"));
  PetscCall(PrintGuard(comm, contact.guard_statistics(), contact.guard_bytes()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. "  whole scene ..." line, with contact: the largest rank's bytes
// of each structure contact keeps over the scene (the numbering and the free
// state's slot map are O(scene) on every rank; the obstacles' and the guard's
// lists hold the fixed bodies' surfaces whole, the fixed tets of the rank's
// share and region, and of the free bodies the rank's own part and its halo),
// and their sum per scene vertex.
PetscErrorCode PrintSceneBytes(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                               const ContactSolver &contact) {
  PetscFunctionBeginUser;
  if (!contact.active()) PetscFunctionReturn(PETSC_SUCCESS);
  const ContactSceneBytes c = contact.scene_bytes();
  const int64_t meshes = scene.MeshBytes();
  const int64_t numbering = HeldBytes(layout.petsc_of_natural);
  int64_t bytes[] = {meshes,
                     numbering,
                     c.free_state,
                     c.obstacles,
                     c.guard,
                     c.separation,
                     0,
                     scene.contact_setup_mesh_bytes};
  constexpr int kParts = 6;
  for (int k = 0; k < kParts; ++k) bytes[kParts] += bytes[k];
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, bytes, kParts + 2, MPI_INT64_T, MPI_MAX, comm));
  const double MB = 1e6;
  PetscCall(PetscPrintf(comm,
                        "  whole scene  held per rank, largest rank: meshes %.3g MB, numbering "
                        "%.3g MB; contact's free state %.3g MB, obstacles %.3g MB, guard %.3g MB, "
                        "overlap separation %.3g MB; %.3g MB in all, %.0f B per scene vertex; "
                        "meshes during contact's set-up %.3g MB\n",
                        bytes[0] / MB, bytes[1] / MB, bytes[2] / MB, bytes[3] / MB, bytes[4] / MB,
                        bytes[5] / MB, bytes[kParts] / MB,
                        double(bytes[kParts]) / std::max<int32_t>(1, scene.num_vertices()),
                        bytes[kParts + 1] / MB));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// "  left out ..." line: the work this run did not do, and why.
PetscErrorCode PrintLeftOut(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                            const IntegratorOptions &o, const OutputOptions &output,
                            const ContactSolver &contact, const BodiesWithoutUnknowns &b) {
  PetscFunctionBeginUser;
  PetscCall(
      PetscPrintf(comm, "  left out     D never formed (A = (1 + a dt) M + (b dt + dt^2) K)"));
  if (o.mode == MODE_COROTATIONAL)
    PetscCall(PetscPrintf(comm, "; K never formed (A refilled in place)"));
  else
    PetscCall(PetscPrintf(comm, "; reassembly (K and A assembled once)"));
  if (layout.size > 1)
    PetscCall(
        PetscPrintf(comm, "; matrix entries sent between ranks (each rank fills its own rows)"));
  if (b.fixed_bodies)
    PetscCall(PetscPrintf(comm, "; %d fixed bodies (%" PetscInt_FMT " vertices, no unknowns)",
                          b.fixed_bodies, b.fixed_vertices));
  if (b.resting_bodies)
    PetscCall(PetscPrintf(
        comm,
        "; %d bodies at rest (no velocity, gravity, deformation, contact or constraint: "
        "%" PetscInt_FMT " vertices, no unknowns)",
        b.resting_bodies, b.resting_vertices));
  if (b.stray_vertices)
    PetscCall(PetscPrintf(comm, "; %" PetscInt_FMT " vertices in no tet", b.stray_vertices));
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
  PetscFunctionReturn(PETSC_SUCCESS);
}

// What factorises or preconditions: the PC's type, its factor package, and
// whether the PC is "redundant" (naming the inner solver).
struct PreconditionerKind {
  PCType type = nullptr;
  MatSolverType factor_package = nullptr;  // null: not a factorisation
  PetscBool factored = PETSC_FALSE, redundant = PETSC_FALSE;
};

PetscErrorCode DescribePreconditioner(KSP ksp, PreconditionerKind *kind) {
  PetscFunctionBeginUser;
  PC pc;
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PCGetType(pc, &kind->type));
  // -pc_type redundant factorises on every rank: name the inner solver.
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCREDUNDANT, &kind->redundant));
  PC factor_pc = pc;
  if (kind->redundant) {
    KSP inner;
    PetscCall(PCRedundantGetKSP(pc, &inner));
    PetscCall(KSPGetPC(inner, &factor_pc));
    PetscCall(PCGetType(factor_pc, &kind->type));
  }
  PetscCall(
      PetscObjectTypeCompareAny((PetscObject)factor_pc, &kind->factored, PCCHOLESKY, PCLU, ""));
  if (kind->factored) PetscCall(PCFactorGetMatSolverType(factor_pc, &kind->factor_package));
  PetscBool supernodal;
  PetscCall(PetscObjectTypeCompare((PetscObject)factor_pc, "supernodal", &supernodal));
  if (supernodal) {
    kind->factored = PETSC_TRUE;
    kind->factor_package = "CHOLMOD";
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// "  solver ..." line (and "  corotational ..." after Newton iterations).
PetscErrorCode PrintSolver(MPI_Comm comm, KSP ksp, const IntegratorOptions &o,
                           const SolverStatistics &solver) {
  PetscFunctionBeginUser;
  if (!ksp) {
    PetscCall(PetscPrintf(comm, "  solver       none: the scene has no unknowns\n"));
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  KSPType ksp_type;
  PetscCall(KSPGetType(ksp, &ksp_type));
  PreconditionerKind pc;
  PetscCall(DescribePreconditioner(ksp, &pc));
  PetscCall(PetscPrintf(comm, "  solver       %s + %s%s%s%s", ksp_type, pc.type,
                        pc.factor_package ? " " : "", pc.factor_package ? pc.factor_package : "",
                        pc.redundant ? " (whole A on every rank)" : ""));
  const char *prepared = pc.factored ? "factorised" : "set up";
  if (o.mode == MODE_LINEAR)
    PetscCall(PetscPrintf(comm, ", %s once in %s s", prepared,
                          FormatNumber(solver.factor_seconds, 3).c_str()));
  else if (std::string(pc.type) == "warp")
    PetscCall(PetscPrintf(comm,
                          ", A refilled every step, preconditioned by the linear system's factor "
                          "(once per time step size) rotated per vertex"));
  else
    PetscCall(PetscPrintf(comm, ", A refilled and %s again every step", prepared));
  PetscCall(PetscPrintf(comm, "; %" PetscInt_FMT " solves", solver.solves));
  if (solver.solves)
    PetscCall(PetscPrintf(
        comm, ", iterations per step %s mean, %" PetscInt_FMT " min, %" PetscInt_FMT " max",
        FormatNumber((double)solver.total_iterations / solver.solves, 3).c_str(),
        solver.min_iterations, solver.max_iterations));
  if (solver.fallback_solves)
    PetscCall(PetscPrintf(comm,
                          "; %" PetscInt_FMT
                          " solves broke down and were repeated by the direct fallback "
                          "(SuperLU_dist LU)",
                          solver.fallback_solves));
  PetscCall(PetscPrintf(comm, "\n"));
  if (!solver.choice.empty())
    PetscCall(PetscPrintf(comm, "  choice       %s\n", solver.choice.c_str()));
  if (solver.newton_iterations > 0)
    PetscCall(PetscPrintf(comm,
                          "  corotational %" PetscInt_FMT
                          " linearised solves without contact, at most %" PetscInt_FMT
                          " in one step, %" PetscInt_FMT " line-search halvings, %" PetscInt_FMT
                          " steps stopped short of -newton_rtol (stalled, no energy gain)\n",
                          solver.newton_iterations, solver.max_newton_iterations, solver.backtracks,
                          solver.newton_stopped_short));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscLogDouble ProcessCpuSeconds() {
  timespec now{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &now);
  return now.tv_sec + 1e-9 * now.tv_nsec;
}

namespace {

// "  steps ...": the time loop's steps with and without contact, their mean
// wall and CPU time (rank 0's), solves and iterations, and the ratio of the
// means (issue 14: a contact step at most 3 times a free one).
PetscErrorCode PrintStepKinds(MPI_Comm comm, const RunReport &r) {
  PetscFunctionBeginUser;
  auto describe = [](const StepKindCost &k) {
    const double n = k.steps > 0 ? double(k.steps) : 1.0;
    return std::to_string(k.steps) + " (" + FormatNumber(1e3 * k.wall / n, 3) + " ms/step, CPU " +
           FormatNumber(1e3 * k.cpu / n, 3) + " ms; " + FormatNumber(k.solves / n, 3) +
           " solves and " + FormatNumber(k.iterations / n, 3) + " iterations per step)";
  };
  PetscCall(PetscPrintf(comm, "  steps        with contact %s, without %s",
                        describe(r.contact_steps).c_str(), describe(r.free_steps).c_str()));
  const StepKindCost &c = r.contact_steps, &f = r.free_steps;
  if (c.steps > 0 && f.steps > 0 && f.wall > 0 && f.cpu > 0)
    PetscCall(PetscPrintf(comm, "; contact over free: %s wall, %s CPU",
                          FormatNumber((c.wall / c.steps) / (f.wall / f.steps), 3).c_str(),
                          FormatNumber((c.cpu / c.steps) / (f.cpu / f.steps), 3).c_str()));
  PetscCall(PetscPrintf(comm, "\n"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// "  time ...", "  energy ..." and "  output ..." lines.
PetscErrorCode PrintTimesAndEnergy(MPI_Comm comm, const IntegratorOptions &o,
                                   const OutputOptions &output, const ContactSolver &contact,
                                   const RunReport &r) {
  PetscFunctionBeginUser;
  const PetscInt taken = r.steps - r.first_step;
  const double per_step = taken > 0 ? r.times.loop / taken : 0;
  PetscCall(PetscPrintf(comm, "  time         set-up %.3f s, time loop %.3f s (%s ms/step",
                        r.times.setup, r.times.loop, FormatNumber(1e3 * per_step, 3).c_str()));
  if (contact.active())
    PetscCall(PetscPrintf(comm, ", of which contact %.3f s", contact.statistics().seconds));
  PetscCall(PetscPrintf(comm, "), output %.3f s\n", r.times.output));
  if (contact.active()) PetscCall(PrintStepKinds(comm, r));
  PetscCall(PetscPrintf(comm, "  energy       at t = %s s: kinetic %.6e J, elastic %.6e J",
                        FormatNumber(r.final_time).c_str(), (double)r.energy.kinetic,
                        (double)r.energy.elastic));
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

}  // namespace

PetscErrorCode PrintRankMessages(MPI_Comm comm) {
  PetscFunctionBeginUser;
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  // As PetscLogView's "MPI Msg Count" and "MPI Msg Len" per rank.
  const double mine[2] = {
      0.5 * (petsc_send_ct + petsc_isend_ct + petsc_recv_ct + petsc_irecv_ct),
      0.5 * (petsc_send_len + petsc_isend_len + petsc_recv_len + petsc_irecv_len)};
  std::vector<double> all(rank == 0 ? 2 * size : 0);
  PetscCallMPI(MPI_Gather(mine, 2, MPI_DOUBLE, all.data(), 2, MPI_DOUBLE, 0, comm));
  for (PetscMPIInt r = 0; r < (rank == 0 ? size : 0); ++r)
    PetscCall(PetscPrintf(PETSC_COMM_SELF, "  messages     rank %d: %.0f messages, %.0f bytes\n", r,
                          all[2 * r], all[2 * r + 1]));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PrintRunSummary(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                               const IntegratorOptions &integration, const OutputOptions &output,
                               const SolverStatistics &solver, KSP ksp,
                               const ContactSolver &contact, const RunReport &report) {
  PetscFunctionBeginUser;
  const BodiesWithoutUnknowns bodies = CountBodiesWithoutUnknowns(scene, layout);
  PetscCall(PetscPrintf(comm, "softbody run summary\n"));
  PetscCall(PrintSceneAndUnknowns(comm, scene, layout, bodies));
  PetscCall(PrintModel(comm, integration, solver, report));
  PetscCall(PrintContact(comm, contact));
  PetscCall(PrintSceneBytes(comm, scene, layout, contact));
  PetscCall(PrintLeftOut(comm, scene, layout, integration, output, contact, bodies));
  PetscCall(PrintSolver(comm, ksp, integration, solver));
  PetscCall(PrintTimesAndEnergy(comm, integration, output, contact, report));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PrintInterruption(MPI_Comm comm, int signal, const IntegratorOptions &integration,
                                 const OutputOptions &output, const RunReport &r) {
  PetscFunctionBeginUser;
  PetscCall(PetscFPrintf(
      comm, PETSC_STDERR,
      "softbody: stopped by %s after step %" PetscInt_FMT " of %" PetscInt_FMT " (t = %s s)",
      SignalName(signal), r.steps, integration.steps, FormatNumber(r.final_time).c_str()));
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
