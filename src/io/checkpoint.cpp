#include "io/checkpoint.hpp"

#include <cmath>
#include <cstdio>

#include "common/options.hpp"
#include "io/hdf5_io.hpp"

namespace softbody {

PetscErrorCode ProcessCheckpointOptions(MPI_Comm comm, const OutputOptions &output,
                                        CheckpointOptions *o) {
  PetscFunctionBeginUser;
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kInteger, "-checkpoint_every"}}));
  char path[PETSC_MAX_PATH_LEN] = "";
  PetscOptionsBegin(comm, nullptr, "Checkpoints and restart", nullptr);
  PetscCall(
      PetscOptionsInt("-checkpoint_every",
                      "Store a checkpoint in the result file every k steps, at the last step and "
                      "when a signal stops the run (0: none)",
                      nullptr, o->every, &o->every, nullptr));
  PetscCall(
      PetscOptionsString("-restart",
                         "Continue from the newest checkpoint of this result file (-steps counts "
                         "from the original start; without -output the file itself is continued)",
                         nullptr, path, path, sizeof(path), nullptr));
  PetscOptionsEnd();
  o->restart_path = path;
  PetscCheck(o->every >= 0, comm, PETSC_ERR_USER_INPUT,
             "option -checkpoint_every: must be >= 0 (got %" PetscInt_FMT ")", o->every);
  PetscCheck(o->every == 0 || !output.path.empty() || !o->restart_path.empty(), comm,
             PETSC_ERR_USER_INPUT,
             "option -checkpoint_every: needs -output (checkpoints are stored in the result file)");
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

constexpr const char *kSlots[] = {"/checkpoint/0", "/checkpoint/1"};

// Rank 0 collective: every rank fails with rank 0's message `why` unless it is empty.
PetscErrorCode AgreeOnMessage(MPI_Comm comm, std::string why) {
  PetscFunctionBeginUser;
  int length = static_cast<int>(why.size());
  PetscCallMPI(MPI_Bcast(&length, 1, MPI_INT, 0, comm));
  why.resize(length);
  PetscCallMPI(MPI_Bcast(why.data(), length, MPI_CHAR, 0, comm));
  PetscCheck(length == 0, comm, PETSC_ERR_USER_INPUT, "%s", why.c_str());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The newest valid slot of an open result file (-1: none) and its step.
int NewestSlot(hid_t file, int64_t *step) {
  int newest = -1;
  *step = -1;
  for (int s = 0; s < 2; ++s) {
    if (!LinkExists(file, kSlots[s])) continue;
    const hid_t slot = H5Gopen2(file, kSlots[s], H5P_DEFAULT);
    int64_t valid = 0, slot_step = -1;
    if (slot >= 0 && GetAttribute(slot, "valid", &valid) && valid == 1 &&
        GetAttribute(slot, "step", &slot_step) && slot_step > *step) {
      newest = s;
      *step = slot_step;
    }
    if (slot >= 0) H5Gclose(slot);
  }
  return newest;
}

hid_t OpenForReading(const std::string &path) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // we report failures ourselves
  return H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
}

std::string Quoted(const std::string &path) {
  return "'" + path + "'";
}

// Rank 0: why the result file does not match the scene ("" when it does).
std::string SceneMismatch(hid_t file, const Scene &scene) {
  std::vector<int32_t> vertex_body, tets, body_fixed;
  std::vector<double> rest, materials;
  std::vector<hsize_t> dims;
  if (!ReadArray(file, "/mesh/vertex_body", H5T_NATIVE_INT32, &vertex_body) ||
      !ReadArray(file, "/mesh/tets", H5T_NATIVE_INT32, &tets) ||
      !ReadArray(file, "/mesh/body_fixed", H5T_NATIVE_INT32, &body_fixed) ||
      !ReadArray(file, "/mesh/rest_positions", H5T_NATIVE_DOUBLE, &rest))
    return "it has no readable /mesh group";
  const size_t bodies = scene.bodies.size();
  if (body_fixed.size() != bodies)
    return "it has " + std::to_string(body_fixed.size()) +
           (body_fixed.size() == 1 ? " body" : " bodies") + ", the scene " + std::to_string(bodies);
  std::vector<int32_t> counts(bodies, 0);
  for (int32_t b : vertex_body)
    if (b >= 0 && static_cast<size_t>(b) < bodies) ++counts[b];
  for (size_t b = 0; b < bodies; ++b) {
    const Body &body = scene.bodies[b];
    if (counts[b] != body.mesh.num_vertices())
      return "body " + std::to_string(b) + " has " + std::to_string(counts[b]) +
             " vertices there, " + std::to_string(body.mesh.num_vertices()) + " in the scene";
    if (body_fixed[b] != (body.fixed ? 1 : 0))
      return "body " + std::to_string(b) + " is " + (body_fixed[b] ? "fixed" : "free") +
             " there, " + (body.fixed ? "fixed" : "free") + " in the scene";
  }
  std::vector<int32_t> scene_tets;
  for (const Body &body : scene.bodies)
    for (int32_t t = 0; t < body.mesh.num_tets(); ++t)
      for (int a = 0; a < 4; ++a) scene_tets.push_back(body.first_vertex + body.mesh.tets(t, a));
  if (tets != scene_tets) return "the tets differ";
  double largest = 0;
  for (const Body &body : scene.bodies)
    for (int32_t v = 0; v < body.mesh.num_vertices(); ++v)
      for (int c = 0; c < 3; ++c)
        largest = std::max(
            largest, std::abs(rest[3 * (body.first_vertex + v) + c] - body.mesh.vertices(v, c)));
  if (largest > 0) {
    char text[96];
    std::snprintf(text, sizeof(text), "the rest positions differ (by up to %.3g m)", largest);
    return text;
  }
  if (ReadArray(file, "/mesh/body_material", H5T_NATIVE_DOUBLE, &materials) &&
      materials.size() == 3 * bodies)
    for (size_t b = 0; b < bodies; ++b) {
      const Material &m = scene.bodies[b].material;
      if (materials[3 * b] != m.density || materials[3 * b + 1] != m.young ||
          materials[3 * b + 2] != m.poisson)
        return "body " + std::to_string(b) +
               "'s material (density, Young's modulus, Poisson ratio) differs";
    }
  return "";
}

// Rank 0: reads slot `slot` into state and the natural arrays; "" or why not.
std::string ReadSlot(hid_t file, int slot_index, int32_t num_vertices, LoopState *state,
                     std::vector<double> *positions, std::vector<double> *velocities) {
  const hid_t slot = H5Gopen2(file, kSlots[slot_index], H5P_DEFAULT);
  if (slot < 0) return "cannot open " + std::string(kSlots[slot_index]);
  int64_t step = 0, frames = 0;
  std::vector<int32_t> applied, resting;
  std::vector<hsize_t> x_dims, v_dims, resting_dims;
  bool ok = GetAttribute(slot, "step", &step) && GetAttribute(slot, "time", &state->time) &&
            GetAttribute(slot, "frames", &frames) &&
            ReadArray(slot, "positions", H5T_NATIVE_DOUBLE, positions, &x_dims) &&
            ReadArray(slot, "velocities", H5T_NATIVE_DOUBLE, velocities, &v_dims) &&
            ReadArray(slot, "deformations_applied", H5T_NATIVE_INT32, &applied) &&
            ReadArray(slot, "resting_contacts", H5T_NATIVE_INT32, &resting, &resting_dims);
  H5Gclose(slot);
  const size_t expected = 3 * static_cast<size_t>(num_vertices);
  if (!ok || positions->size() != expected || velocities->size() != expected ||
      (resting_dims.size() == 2 && resting_dims[1] != 2))
    return "its checkpoint " + std::string(kSlots[slot_index]) +
           " is incomplete or has the wrong size";
  state->step = static_cast<PetscInt>(step);
  state->frames = static_cast<PetscInt>(frames);
  state->deformations_applied = applied;
  state->resting_contacts.resize(resting.size() / 2);
  for (size_t i = 0; i < state->resting_contacts.size(); ++i)
    state->resting_contacts[i] = {resting[2 * i], resting[2 * i + 1]};
  return "";
}

// Rank 0's LoopState to every rank.
PetscErrorCode BroadcastLoopState(MPI_Comm comm, LoopState *state) {
  PetscFunctionBeginUser;
  PetscInt counts[4] = {state->step, state->frames,
                        static_cast<PetscInt>(state->deformations_applied.size()),
                        static_cast<PetscInt>(state->resting_contacts.size())};
  PetscCallMPI(MPI_Bcast(counts, 4, MPIU_INT, 0, comm));
  PetscCallMPI(MPI_Bcast(&state->time, 1, MPIU_REAL, 0, comm));
  state->step = counts[0];
  state->frames = counts[1];
  state->deformations_applied.resize(counts[2]);
  state->resting_contacts.resize(counts[3]);
  PetscCallMPI(MPI_Bcast(state->deformations_applied.data(), static_cast<int>(counts[2]),
                         MPI_INT32_T, 0, comm));
  PetscCallMPI(MPI_Bcast(state->resting_contacts.data(), static_cast<int>(2 * counts[3]),
                         MPI_INT32_T, 0, comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode CheckRestartFile(MPI_Comm comm, const std::string &path) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  std::string why;
  if (rank == 0) {
    const hid_t file = OpenForReading(path);
    int64_t step;
    if (file < 0)
      why = "option -restart: cannot open " + Quoted(path) + " as an HDF5 file";
    else if (NewestSlot(file, &step) < 0)
      why = "option -restart: " + Quoted(path) +
            " holds no checkpoint (runs write them with -checkpoint_every k)";
    if (file >= 0) H5Fclose(file);
  }
  PetscCall(AgreeOnMessage(comm, why));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ReadCheckpoint(MPI_Comm comm, const std::string &path, const Scene &scene,
                              const DofLayout &layout, size_t deformations, PetscInt steps, Vec x,
                              Vec v, LoopState *state) {
  PetscFunctionBeginUser;
  NaturalOrder natural;
  PetscCall(natural.Setup(scene, layout, x));
  Vec natural_x, natural_v;
  PetscCall(natural.CreateVector(false, &natural_x));
  PetscCall(natural.CreateVector(false, &natural_v));
  std::string why;
  if (layout.rank == 0) {
    const hid_t file = OpenForReading(path);
    int64_t step;
    const int slot = file < 0 ? -1 : NewestSlot(file, &step);
    std::vector<double> positions, velocities;
    if (slot < 0) why = "option -restart: " + Quoted(path) + " holds no readable checkpoint";
    if (why.empty()) {
      const std::string mismatch = SceneMismatch(file, scene);
      if (!mismatch.empty())
        why = "option -restart: " + Quoted(path) + " does not match the scene: " + mismatch;
    }
    if (why.empty()) {
      const std::string bad =
          ReadSlot(file, slot, scene.num_vertices(), state, &positions, &velocities);
      if (!bad.empty()) why = "option -restart: " + Quoted(path) + ": " + bad;
    }
    if (file >= 0) H5Fclose(file);
    if (why.empty() && state->deformations_applied.size() != deformations)
      why = "option -restart: " + Quoted(path) + " was written with " +
            std::to_string(state->deformations_applied.size()) + " -deform events, this run has " +
            std::to_string(deformations);
    if (why.empty() && steps < state->step)
      why = "option -steps: " + std::to_string(steps) + " is before the checkpoint of " +
            Quoted(path) + " at step " + std::to_string(state->step);
    if (why.empty()) {
      PetscScalar *nx, *nv;
      PetscCall(VecGetArray(natural_x, &nx));
      PetscCall(VecGetArray(natural_v, &nv));
      std::copy(positions.begin(), positions.end(), nx);
      std::copy(velocities.begin(), velocities.end(), nv);
      PetscCall(VecRestoreArray(natural_x, &nx));
      PetscCall(VecRestoreArray(natural_v, &nv));
    }
  }
  PetscCall(AgreeOnMessage(comm, why));
  PetscCall(BroadcastLoopState(comm, state));
  PetscCall(natural.Scatter(natural_x, x));
  PetscCall(natural.Scatter(natural_v, v));
  PetscCall(VecDestroy(&natural_x));
  PetscCall(VecDestroy(&natural_v));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode WriteCheckpoint(ResultWriter *writer, const LoopState &state, Vec x, Vec v) {
  PetscFunctionBeginUser;
  MPI_Comm comm = writer->comm();
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  Vec natural_x, natural_v;
  PetscCall(writer->natural_order().CreateVector(true, &natural_x));
  PetscCall(writer->natural_order().CreateVector(false, &natural_v));
  PetscCall(writer->natural_order().Gather(x, natural_x));
  PetscCall(writer->natural_order().Gather(v, natural_v));
  bool ok = true;
  if (rank == 0) {
    const hid_t file = writer->file();
    int64_t newest_step;
    const int slot_index = NewestSlot(file, &newest_step) == 0 ? 1 : 0;
    const hid_t group = OpenOrCreateGroup(file, "/checkpoint");
    const hid_t slot = group < 0 ? -1 : OpenOrCreateGroup(file, kSlots[slot_index]);
    // Invalid on disk before its data change; valid again once they are complete.
    ok = slot >= 0 && SetAttribute(slot, "valid", int64_t{0}) &&
         H5Fflush(file, H5F_SCOPE_LOCAL) >= 0;
    const PetscScalar *nx, *nv;
    PetscCall(VecGetArrayRead(natural_x, &nx));
    PetscCall(VecGetArrayRead(natural_v, &nv));
    std::vector<int32_t> resting;
    for (const auto &contact : state.resting_contacts)
      resting.insert(resting.end(), contact.begin(), contact.end());
    const hsize_t V = static_cast<hsize_t>(writer->natural_order().num_vertices());
    ok = ok && WriteResizableArray(slot, "positions", H5T_NATIVE_DOUBLE, V, 3, nx) &&
         WriteResizableArray(slot, "velocities", H5T_NATIVE_DOUBLE, V, 3, nv) &&
         WriteResizableArray(slot, "deformations_applied", H5T_NATIVE_INT32,
                             state.deformations_applied.size(), 1,
                             state.deformations_applied.data()) &&
         WriteResizableArray(slot, "resting_contacts", H5T_NATIVE_INT32, resting.size() / 2, 2,
                             resting.data()) &&
         SetAttribute(slot, "step", int64_t{state.step}) &&
         SetAttribute(slot, "time", double{state.time}) &&
         SetAttribute(slot, "frames", int64_t{state.frames}) &&
         SetAttribute(slot, "ranks", int64_t{size}) && SetAttribute(slot, "valid", int64_t{1});
    PetscCall(VecRestoreArrayRead(natural_x, &nx));
    PetscCall(VecRestoreArrayRead(natural_v, &nv));
    if (slot >= 0) H5Gclose(slot);
    if (group >= 0) H5Gclose(group);
  }
  PetscCall(VecDestroy(&natural_x));
  PetscCall(VecDestroy(&natural_v));
  PetscCall(AgreeOnSuccess(comm, ok, "cannot write a checkpoint to '" + writer->path() + "'"));
  PetscCall(writer->Flush());
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
