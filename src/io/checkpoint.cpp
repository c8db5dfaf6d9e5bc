#include "io/checkpoint.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "common/options.hpp"
#include "io/hdf5_io.hpp"
#include "io/parallel_hdf5.hpp"

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

// Collective: every rank fails with the message of the first rank whose `why`
// is not empty, if any.
PetscErrorCode AgreeOnFirstMessage(MPI_Comm comm, std::string why) {
  PetscFunctionBeginUser;
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscMPIInt first = why.empty() ? size : rank;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &first, 1, MPI_INT, MPI_MIN, comm));
  if (first == size) PetscFunctionReturn(PETSC_SUCCESS);
  int length = static_cast<int>(why.size());
  PetscCallMPI(MPI_Bcast(&length, 1, MPI_INT, first, comm));
  why.resize(length);
  PetscCallMPI(MPI_Bcast(why.data(), length, MPI_CHAR, first, comm));
  SETERRQ(comm, PETSC_ERR_USER_INPUT, "%s", why.c_str());
}

// Collective on a parallel file (not collective on a file one rank opened).
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

// Collective. Reads rows `slab` of dataset `name` (of `columns` values per row)
// into values; false when it is missing or the slab lies outside it.
template <typename T>
bool ReadSlab(hid_t file, const char *name, hid_t type, RowSlab slab, hsize_t columns,
              std::vector<T> *values) {
  if (!LinkExists(file, name)) return false;
  const hid_t set = H5Dopen2(file, name, H5P_DEFAULT);
  values->resize(columns * slab.count());
  const bool ok = set >= 0 && ReadRows(set, type, slab, values->data());
  if (set >= 0) H5Dclose(set);
  return ok;
}

// Collective. The first dimension of dataset `name` (-1: missing).
int64_t Rows(hid_t file, const char *name) {
  if (!LinkExists(file, name)) return -1;
  const hid_t set = H5Dopen2(file, name, H5P_DEFAULT);
  const std::vector<hsize_t> dims = set >= 0 ? DatasetDims(set) : std::vector<hsize_t>{};
  if (set >= 0) H5Dclose(set);
  return dims.empty() ? -1 : static_cast<int64_t>(dims[0]);
}

// Collective. Why the bodies' vertex counts and fixed flags of the result file
// differ from the scene's ("" when they do not): each rank counts its slab of
// /mesh/vertex_body, and the counts are summed.
PetscErrorCode BodyMismatch(MPI_Comm comm, hid_t file, const Scene &scene,
                            const std::vector<int32_t> &body_fixed, std::string *why) {
  PetscFunctionBeginUser;
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  const size_t bodies = scene.bodies.size();
  const RowSlab slab = EvenSlab(Rows(file, "/mesh/vertex_body"), rank, size);
  std::vector<int32_t> vertex_body;
  int read = ReadSlab(file, "/mesh/vertex_body", H5T_NATIVE_INT32, slab, 1, &vertex_body);
  std::vector<int64_t> counts(bodies, 0);
  for (int32_t b : vertex_body)
    if (b >= 0 && static_cast<size_t>(b) < bodies) ++counts[b];
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &read, 1, MPI_INT, MPI_LAND, comm));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, counts.data(), static_cast<int>(bodies), MPI_INT64_T,
                             MPI_SUM, comm));
  if (!read) *why = "it has no readable /mesh group";
  for (size_t b = 0; why->empty() && b < bodies; ++b) {
    const Body &body = scene.bodies[b];
    if (counts[b] != body.num_vertices())
      *why = "body " + std::to_string(b) + " has " + std::to_string(counts[b]) +
             " vertices there, " + std::to_string(body.num_vertices()) + " in the scene";
    else if (body_fixed[b] != (body.fixed ? 1 : 0))
      *why = "body " + std::to_string(b) + " is " + (body_fixed[b] ? "fixed" : "free") +
             " there, " + (body.fixed ? "fixed" : "free") + " in the scene";
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Why the tets and rest positions of the result file differ from
// the scene's ("" when they do not), each rank comparing its slabs with its share.
PetscErrorCode GeometryMismatch(MPI_Comm comm, hid_t file, const Scene &scene,
                                const MeshShare &share, std::string *why) {
  PetscFunctionBeginUser;
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  const RowSlab tets = EvenSlab(scene.num_tets(), rank, size);
  const RowSlab vertices = EvenSlab(scene.num_vertices(), rank, size);
  int differ = 0;
  if (Rows(file, "/mesh/tets") != scene.num_tets()) {
    differ = 1;  // every rank sees the same dims
  } else {
    std::vector<int32_t> file_tets;
    differ = !ReadSlab(file, "/mesh/tets", H5T_NATIVE_INT32, tets, 4, &file_tets) ||
             file_tets != ShareTetRows(share);
  }
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &differ, 1, MPI_INT, MPI_LOR, comm));
  if (differ) {
    *why = "the tets differ";
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  std::vector<double> rest;
  int read = ReadSlab(file, "/mesh/rest_positions", H5T_NATIVE_DOUBLE, vertices, 3, &rest);
  const double *scene_rest = share.rest.data();
  double largest = 0;
  for (size_t i = 0; read && i < rest.size(); ++i)
    largest = std::max(largest, std::abs(rest[i] - scene_rest[i]));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &read, 1, MPI_INT, MPI_LAND, comm));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &largest, 1, MPI_DOUBLE, MPI_MAX, comm));
  if (!read) {
    *why = "it has no readable /mesh group";
  } else if (largest > 0) {
    char text[96];
    std::snprintf(text, sizeof(text), "the rest positions differ (by up to %.3g m)", largest);
    *why = text;
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Why the result file does not match the scene ("" when it does).
PetscErrorCode SceneMismatch(MPI_Comm comm, hid_t file, const Scene &scene, const MeshShare &share,
                             std::string *why) {
  PetscFunctionBeginUser;
  std::vector<int32_t> body_fixed;
  std::vector<double> materials;
  const size_t bodies = scene.bodies.size();
  if (!ReadArray(file, "/mesh/body_fixed", H5T_NATIVE_INT32, &body_fixed) ||
      Rows(file, "/mesh/vertex_body") < 0 || Rows(file, "/mesh/tets") < 0 ||
      Rows(file, "/mesh/rest_positions") < 0) {
    *why = "it has no readable /mesh group";
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  if (body_fixed.size() != bodies) {
    *why = "it has " + std::to_string(body_fixed.size()) +
           (body_fixed.size() == 1 ? " body" : " bodies") + ", the scene " + std::to_string(bodies);
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  PetscCall(BodyMismatch(comm, file, scene, body_fixed, why));
  if (why->empty()) PetscCall(GeometryMismatch(comm, file, scene, share, why));
  if (why->empty() && ReadArray(file, "/mesh/body_material", H5T_NATIVE_DOUBLE, &materials) &&
      materials.size() == 3 * bodies)
    for (size_t b = 0; why->empty() && b < bodies; ++b) {
      const Material &m = scene.bodies[b].material;
      if (materials[3 * b] != m.density || materials[3 * b + 1] != m.young ||
          materials[3 * b + 2] != m.poisson)
        *why = "body " + std::to_string(b) +
               "'s material (density, Young's modulus, Poisson ratio) differs";
    }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Reads slot `slot_index` into state and this rank's slab of the
// natural positions and velocities (3 values per vertex); "" or why not.
std::string ReadSlot(hid_t file, int slot_index, int32_t num_vertices, RowSlab slab,
                     LoopState *state, double *positions, double *velocities) {
  const hid_t slot = H5Gopen2(file, kSlots[slot_index], H5P_DEFAULT);
  if (slot < 0) return "cannot open " + std::string(kSlots[slot_index]);
  int64_t step = 0, frames = 0;
  std::vector<int32_t> applied, resting;
  std::vector<double> reactions;
  std::vector<hsize_t> resting_dims;
  const std::vector<hsize_t> expected{static_cast<hsize_t>(num_vertices), 3};
  const auto read_state = [&](const char *name, double *values) {
    const hid_t set = LinkExists(slot, name) ? H5Dopen2(slot, name, H5P_DEFAULT) : -1;
    const bool ok =
        set >= 0 && DatasetDims(set) == expected && ReadRows(set, H5T_NATIVE_DOUBLE, slab, values);
    if (set >= 0) H5Dclose(set);
    return ok;
  };
  bool ok = GetAttribute(slot, "step", &step) && GetAttribute(slot, "time", &state->time) &&
            GetAttribute(slot, "frames", &frames) && read_state("positions", positions) &&
            read_state("velocities", velocities) &&
            ReadArray(slot, "deformations_applied", H5T_NATIVE_INT32, &applied) &&
            ReadArray(slot, "resting_contacts", H5T_NATIVE_INT32, &resting, &resting_dims);
  // Files from before the reactions were stored: none (zero).
  if (ok && LinkExists(slot, "resting_reactions"))
    ok = ReadArray(slot, "resting_reactions", H5T_NATIVE_DOUBLE, &reactions) &&
         reactions.size() == resting.size() / 2;
  H5Gclose(slot);
  if (!ok || (resting_dims.size() == 2 && resting_dims[1] != 2))
    return "its checkpoint " + std::string(kSlots[slot_index]) +
           " is incomplete or has the wrong size";
  state->step = static_cast<PetscInt>(step);
  state->frames = static_cast<PetscInt>(frames);
  state->deformations_applied = applied;
  state->resting_contacts.resize(resting.size() / 2);
  for (size_t i = 0; i < state->resting_contacts.size(); ++i)
    state->resting_contacts[i] = {resting[2 * i], resting[2 * i + 1]};
  state->resting_reactions = reactions;
  return "";
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

namespace {

// Collective. Reads the newest checkpoint of the open parallel `file` after
// checking it against the scene: the loop state and this rank's slabs of the
// natural vectors. "" or why not (equal on every rank).
PetscErrorCode ReadNewestCheckpoint(MPI_Comm comm, hid_t file, const std::string &path,
                                    const Scene &scene, const MeshShare &share, RowSlab slab,
                                    Vec natural_x, Vec natural_v, LoopState *state,
                                    std::string *why) {
  PetscFunctionBeginUser;
  int64_t step;
  const int slot = file < 0 ? -1 : NewestSlot(file, &step);
  if (slot < 0) {
    *why = "option -restart: " + Quoted(path) + " holds no readable checkpoint";
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  std::string mismatch;
  PetscCall(SceneMismatch(comm, file, scene, share, &mismatch));
  if (!mismatch.empty()) {
    *why = "option -restart: " + Quoted(path) + " does not match the scene: " + mismatch;
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  PetscScalar *nx, *nv;
  PetscCall(VecGetArray(natural_x, &nx));
  PetscCall(VecGetArray(natural_v, &nv));
  const std::string bad = ReadSlot(file, slot, scene.num_vertices(), slab, state, nx, nv);
  PetscCall(VecRestoreArray(natural_x, &nx));
  PetscCall(VecRestoreArray(natural_v, &nv));
  if (!bad.empty()) *why = "option -restart: " + Quoted(path) + ": " + bad;
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode ReadCheckpoint(MPI_Comm comm, const std::string &path, const Scene &scene,
                              const MeshShare &share, const DofLayout &layout, size_t deformations,
                              PetscInt steps, Vec x, Vec v, LoopState *state) {
  PetscFunctionBeginUser;
  NaturalSlab natural;
  PetscCall(natural.Setup(share, layout, x));
  Vec natural_x, natural_v;
  PetscCall(natural.CreateVector(false, &natural_x));
  PetscCall(natural.CreateVector(false, &natural_v));
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // we report failures ourselves
  const hid_t file = OpenParallelFile(comm, path, false);
  std::string why;
  PetscCall(ReadNewestCheckpoint(comm, file, path, scene, share, natural.vertices(), natural_x,
                                 natural_v, state, &why));
  if (file >= 0) H5Fclose(file);
  if (why.empty() && state->deformations_applied.size() != deformations)
    why = "option -restart: " + Quoted(path) + " was written with " +
          std::to_string(state->deformations_applied.size()) + " -deform events, this run has " +
          std::to_string(deformations);
  if (why.empty() && steps < state->step)
    why = "option -steps: " + std::to_string(steps) + " is before the checkpoint of " +
          Quoted(path) + " at step " + std::to_string(state->step);
  PetscCall(AgreeOnFirstMessage(comm, why));
  PetscCall(natural.Scatter(natural_x, x));
  PetscCall(natural.Scatter(natural_v, v));
  PetscCall(VecDestroy(&natural_x));
  PetscCall(VecDestroy(&natural_v));
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// Collective. Writes rows `slab` of the extendible table location/name
// [rows][columns] (created at the first write, resized after).
bool WriteTable(hid_t location, const char *name, hid_t type, hsize_t rows, hsize_t columns,
                RowSlab slab, const void *values) {
  const hid_t set = LinkExists(location, name)
                        ? H5Dopen2(location, name, H5P_DEFAULT)
                        : CreateRowDataset(location, name, type, {rows, columns}, true);
  const bool ok = set >= 0 && ExtendRows(set, rows) && WriteRows(set, type, slab, values);
  if (set >= 0) H5Dclose(set);
  return ok;
}

// Collective. Writes the slot's datasets: x and v (natural slabs), the
// deformations applied and rank 0's resting contacts with their reactions.
PetscErrorCode WriteSlotData(MPI_Comm comm, hid_t slot, const NaturalSlab &natural,
                             const LoopState &state, Vec natural_x, Vec natural_v, bool *ok) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  std::vector<int32_t> resting;
  for (const auto &contact : state.resting_contacts)
    resting.insert(resting.end(), contact.begin(), contact.end());
  hsize_t contacts = resting.size() / 2;
  PetscCallMPI(MPI_Bcast(&contacts, 1, MPI_UINT64_T, 0, comm));
  const hsize_t V = static_cast<hsize_t>(natural.num_vertices()),
                D = state.deformations_applied.size();
  const PetscScalar *nx, *nv;
  PetscCall(VecGetArrayRead(natural_x, &nx));
  PetscCall(VecGetArrayRead(natural_v, &nv));
  *ok = *ok && WriteTable(slot, "positions", H5T_NATIVE_DOUBLE, V, 3, natural.vertices(), nx) &&
        WriteTable(slot, "velocities", H5T_NATIVE_DOUBLE, V, 3, natural.vertices(), nv) &&
        WriteTable(slot, "deformations_applied", H5T_NATIVE_INT32, D, 1, {0, rank == 0 ? D : 0},
                   state.deformations_applied.data()) &&
        WriteTable(slot, "resting_contacts", H5T_NATIVE_INT32, contacts, 2,
                   {0, rank == 0 ? contacts : 0}, resting.data()) &&
        WriteTable(slot, "resting_reactions", H5T_NATIVE_DOUBLE, contacts, 1,
                   {0, rank == 0 ? contacts : 0}, state.resting_reactions.data());
  PetscCall(VecRestoreArrayRead(natural_x, &nx));
  PetscCall(VecRestoreArrayRead(natural_v, &nv));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Natural vectors of a scheme's history: positions show the fixed vertices'
// rest positions, the other vectors zeros there.
bool IsPositionVector(const std::string &name) {
  return name.find("positions") != std::string::npos;
}

// Collective. The time scheme's history into the slot: its name, its scalars
// (rank 0) and its vectors (natural slabs).
PetscErrorCode WriteSlotHistory(MPI_Comm comm, hid_t slot, const NaturalSlab &natural,
                                const SchemeHistory &history, bool *ok) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  const hsize_t V = static_cast<hsize_t>(natural.num_vertices()), S = history.scalars.size();
  *ok = *ok && SetAttribute(slot, "integrator", history.scheme) &&
        WriteTable(slot, "integrator_scalars", H5T_NATIVE_DOUBLE, S, 1, {0, rank == 0 ? S : 0},
                   history.scalars.data());
  for (const auto &[name, vector] : history.vectors) {
    Vec natural_vector;
    PetscCall(natural.CreateVector(IsPositionVector(name), &natural_vector));
    PetscCall(natural.Gather(vector, natural_vector));
    const PetscScalar *values;
    PetscCall(VecGetArrayRead(natural_vector, &values));
    *ok =
        *ok && WriteTable(slot, name.c_str(), H5T_NATIVE_DOUBLE, V, 3, natural.vertices(), values);
    PetscCall(VecRestoreArrayRead(natural_vector, &values));
    PetscCall(VecDestroy(&natural_vector));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode WriteCheckpoint(ResultWriter *writer, const LoopState &state, Vec x, Vec v,
                               const SchemeHistory *history) {
  PetscFunctionBeginUser;
  MPI_Comm comm = writer->comm();
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  const NaturalSlab &natural = writer->natural_slab();
  Vec natural_x, natural_v;
  PetscCall(natural.CreateVector(true, &natural_x));
  PetscCall(natural.CreateVector(false, &natural_v));
  PetscCall(natural.Gather(x, natural_x));
  PetscCall(natural.Gather(v, natural_v));
  const hid_t file = writer->file();
  int64_t newest_step;
  const int slot_index = NewestSlot(file, &newest_step) == 0 ? 1 : 0;
  const hid_t group = OpenOrCreateGroup(file, "/checkpoint");
  const hid_t slot = group < 0 ? -1 : OpenOrCreateGroup(file, kSlots[slot_index]);
  // Invalid on disk before its data change; valid again once they are complete.
  bool ok =
      slot >= 0 && SetAttribute(slot, "valid", int64_t{0}) && H5Fflush(file, H5F_SCOPE_LOCAL) >= 0;
  PetscCall(WriteSlotData(comm, slot, natural, state, natural_x, natural_v, &ok));
  if (history) PetscCall(WriteSlotHistory(comm, slot, natural, *history, &ok));
  ok = ok && SetAttribute(slot, "step", int64_t{state.step}) &&
       SetAttribute(slot, "time", double{state.time}) &&
       SetAttribute(slot, "frames", int64_t{state.frames}) &&
       SetAttribute(slot, "ranks", int64_t{size}) && SetAttribute(slot, "valid", int64_t{1});
  if (slot >= 0) H5Gclose(slot);
  if (group >= 0) H5Gclose(group);
  PetscCall(VecDestroy(&natural_x));
  PetscCall(VecDestroy(&natural_v));
  PetscCall(AgreeOnAllRanks(comm, ok, "cannot write a checkpoint to '" + writer->path() + "'"));
  PetscCall(writer->Flush());
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// A fixed-length string attribute ("" when missing).
std::string StringAttribute(hid_t object, const char *name) {
  if (H5Aexists(object, name) <= 0) return "";
  const hid_t attribute = H5Aopen(object, name, H5P_DEFAULT);
  const hid_t type = attribute >= 0 ? H5Aget_type(attribute) : -1;
  std::string value(type >= 0 ? H5Tget_size(type) : 0, '\0');
  const bool ok = type >= 0 && H5Tget_class(type) == H5T_STRING && !H5Tis_variable_str(type) &&
                  H5Aread(attribute, type, value.data()) >= 0;
  if (type >= 0) H5Tclose(type);
  if (attribute >= 0) H5Aclose(attribute);
  return ok ? value.substr(0, value.find('\0')) : "";
}

// Collective. Reads the history of history->scheme from the open slot into
// natural vectors (one per history vector) and scalars; false when the slot holds
// another scheme's history or none.
bool ReadSlotHistory(hid_t slot, RowSlab slab, int32_t num_vertices, SchemeHistory *history,
                     const std::vector<Vec> &natural, std::vector<double> *scalars) {
  if (StringAttribute(slot, "integrator") != history->scheme ||
      !ReadArray(slot, "integrator_scalars", H5T_NATIVE_DOUBLE, scalars))
    return false;
  const std::vector<hsize_t> expected{static_cast<hsize_t>(num_vertices), 3};
  bool ok = true;
  for (size_t i = 0; i < history->vectors.size(); ++i) {
    const char *name = history->vectors[i].first.c_str();
    const hid_t set = ok && LinkExists(slot, name) ? H5Dopen2(slot, name, H5P_DEFAULT) : -1;
    PetscScalar *values;
    ok = set >= 0 && DatasetDims(set) == expected && VecGetArray(natural[i], &values) == 0;
    if (ok) {
      ok = ReadRows(set, H5T_NATIVE_DOUBLE, slab, values);
      VecRestoreArray(natural[i], &values);
    }
    if (set >= 0) H5Dclose(set);
  }
  return ok;
}

}  // namespace

PetscErrorCode ReadCheckpointHistory(MPI_Comm comm, const std::string &path,
                                     const NaturalSlab &natural, SchemeHistory *history,
                                     bool *found) {
  PetscFunctionBeginUser;
  std::vector<Vec> natural_vectors(history->vectors.size());
  for (size_t i = 0; i < natural_vectors.size(); ++i)
    PetscCall(
        natural.CreateVector(IsPositionVector(history->vectors[i].first), &natural_vectors[i]));
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // a missing history is not an error
  const hid_t file = OpenParallelFile(comm, path, false);
  int64_t step;
  const int slot_index = file < 0 ? -1 : NewestSlot(file, &step);
  const hid_t slot = slot_index < 0 ? -1 : H5Gopen2(file, kSlots[slot_index], H5P_DEFAULT);
  std::vector<double> scalars;
  int ok = slot >= 0 && ReadSlotHistory(slot, natural.vertices(), natural.num_vertices(), history,
                                        natural_vectors, &scalars);
  if (slot >= 0) H5Gclose(slot);
  if (file >= 0) H5Fclose(file);
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &ok, 1, MPI_INT, MPI_MIN, comm));
  *found = ok != 0;
  if (*found) {
    history->scalars = scalars;
    for (size_t i = 0; i < natural_vectors.size(); ++i)
      PetscCall(natural.Scatter(natural_vectors[i], history->vectors[i].second));
  }
  for (Vec &vector : natural_vectors) PetscCall(VecDestroy(&vector));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
