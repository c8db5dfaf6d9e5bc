// Checkpoints and restart.
//
// -checkpoint_every k stores, in the result file, everything the time loop
// carries from one step to the next, every k steps, at the last step and when a
// signal stops the run (run_control.hpp):
//   step, time (s), the number of frames in the file, positions and velocities
//   of every vertex (m, m/s; natural order; the velocities are also the
//   iterative solver's initial guess of the next step), which -deform events
//   have been applied, and the resting contacts (vertex, obstacle) that the
//   contact solver keeps constrained into the next step.
// Everything else a step depends on is rebuilt from the scene and the options:
// the time step from -dt/-dt_schedule at the checkpoint's time, the matrices
// (corotational mode refills A from the positions at every step), the
// preconditioner (set up afresh at every corotational step), the rest
// positions (never changed: -deform moves positions only).
//
// Layout: two slots, /checkpoint/0 and /checkpoint/1, written alternately, each
// with attributes valid, step, time, frames, ranks and datasets positions
// [V][3], velocities [V][3], deformations_applied [D][1], resting_contacts
// [n][2] (natural vertex, obstacle body; -1 the ground), resting_reactions
// [n][1] (their reactions, N s: the two-sided solve's starting multipliers;
// absent in older files, read as zero), and the time scheme's
// history (solvers/time_scheme.hpp): attribute integrator (its -integrator
// name), integrator_scalars [k][1] and its vectors [V][3] (bdf2:
// previous_positions, previous_velocities; alpha: accelerations). A slot is marked
// invalid and flushed before it is overwritten, and marked valid and flushed
// after, so a run killed while checkpointing still holds the other slot. Every
// rank writes the rows of its natural vertex slab (output.hpp's NaturalSlab);
// rank 0 the small tables.
//
// -restart FILE.h5 continues from the newest valid slot: -steps still counts
// from the original start. Every rank reads its own natural slab of the slot
// (and checks its slab of the file's mesh), so the file may come from a run on
// any number of ranks. The scene must be the one the file was written with
// (same bodies, vertices, tets, rest positions and materials) and -deform must
// list as many events; otherwise the run stops before set-up with one line. On
// the same number of ranks with the same options, the continued run equals the
// uninterrupted one bit for bit (the METIS partition and every reduction are
// the same); on another rank count, to round-off or the solver's tolerance.
#pragma once

#include <petscvec.h>

#include <array>
#include <string>
#include <vector>

#include "fem/partition.hpp"
#include "io/output.hpp"
#include "io/scene.hpp"
#include "solvers/time_scheme.hpp"

namespace softbody {

struct CheckpointOptions {
  PetscInt every = 0;        // -checkpoint_every k (0: no checkpoints)
  std::string restart_path;  // -restart FILE.h5 ("": start from the scene)
};

// Collective. Reads -checkpoint_every and -restart; checkpoints need -output or
// -restart (they are stored in the result file).
PetscErrorCode ProcessCheckpointOptions(MPI_Comm comm, const OutputOptions &output,
                                        CheckpointOptions *options);

// What the time loop carries from step to step besides positions and velocities.
struct LoopState {
  PetscInt step = 0;                          // steps taken since the original start
  PetscReal time = 0;                         // s
  PetscInt frames = 0;                        // frames in the result file up to this step
  std::vector<int32_t> deformations_applied;  // per -deform event, 0 or 1
  std::vector<std::array<int32_t, 2>> resting_contacts;  // (natural vertex, obstacle; -1 ground)
  std::vector<double> resting_reactions;  // per resting contact: its reaction (N s), or empty
};

// Collective. Fails early (before the scene is read) unless `path` is an HDF5
// file holding a valid checkpoint.
PetscErrorCode CheckRestartFile(MPI_Comm comm, const std::string &path);

// Collective. Reads the newest checkpoint of `path` (every rank its slab),
// checks it against the scene (and this rank's share of its meshes), the number of -deform events
// and -steps, and sets the PETSc-ordered positions x and velocities v. Every rank reads the whole
// LoopState. On failure, every rank fails with one message.
PetscErrorCode ReadCheckpoint(MPI_Comm comm, const std::string &path, const Scene &scene,
                              const MeshShare &share, const DofLayout &layout, size_t deformations,
                              PetscInt steps, Vec x, Vec v, LoopState *state);

// Collective. Writes `state` with x and v (PETSc order) and the time scheme's
// history (may be null) into the writer's file, in the slot not holding the
// newest checkpoint, and flushes the file. Only rank 0's state.resting_contacts
// and resting_reactions are used.
PetscErrorCode WriteCheckpoint(ResultWriter *writer, const LoopState &state, Vec x, Vec v,
                               const SchemeHistory *history = nullptr);

// Collective. Reads the time scheme's history from the newest checkpoint of
// `path` (after ReadCheckpoint checked it; `natural` is the result file's slab
// plan): history->vectors (PETSc order) are filled and history->scalars set when
// the slot holds the history of history->scheme (*found); otherwise nothing
// changes and *found is false (a checkpoint of another -integrator, or of a
// version without history).
PetscErrorCode ReadCheckpointHistory(MPI_Comm comm, const std::string &path,
                                     const NaturalSlab &natural, SchemeHistory *history,
                                     bool *found);

}  // namespace softbody
