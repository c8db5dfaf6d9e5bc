#include "io/output.hpp"

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <string_view>

#include "common/options.hpp"
#include "fem/share_boundary.hpp"
#include "io/hdf5_io.hpp"
#include "io/parallel_hdf5.hpp"

namespace softbody {

PetscErrorCode ProcessOutputOptions(MPI_Comm comm, OutputOptions *o) {
  PetscFunctionBeginUser;
  char path[PETSC_MAX_PATH_LEN] = "", dir[PETSC_MAX_PATH_LEN] = "";
  PetscCall(CheckOptionSyntax(
      comm, {{OptionSyntax::kInteger, "-output_every"}, {OptionSyntax::kInteger, "-flush_every"}}));
  PetscOptionsBegin(comm, nullptr, "Output", nullptr);
  PetscCall(PetscOptionsString("-output",
                               "HDF5 file of the frames (+ .xdmf beside it); none if unset",
                               nullptr, path, path, sizeof(path), nullptr));
  PetscCall(PetscOptionsInt("-output_every", "Write a frame every k steps", nullptr, o->every,
                            &o->every, nullptr));
  PetscCall(PetscOptionsInt("-flush_every",
                            "Flush the HDF5 file to disk and extend the .xdmf every k frames (a "
                            "killed run keeps every frame up to the last flush)",
                            nullptr, o->flush_every, &o->flush_every, nullptr));
  PetscCall(PetscOptionsString("-export_matrices",
                               "Folder for M.bin, K.bin, D.bin (PETSc binary, natural order)",
                               nullptr, dir, dir, sizeof(dir), nullptr));
  PetscOptionsEnd();
  o->path = path;
  o->matrix_dir = dir;
  PetscCheck(o->every >= 1, comm, PETSC_ERR_USER_INPUT,
             "option -output_every: must be >= 1 (got %" PetscInt_FMT ")", o->every);
  PetscCheck(o->flush_every >= 1, comm, PETSC_ERR_USER_INPUT,
             "option -flush_every: must be >= 1 (got %" PetscInt_FMT ")", o->flush_every);
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode AgreeOnSuccess(MPI_Comm comm, bool ok, const std::string &message) {
  PetscFunctionBeginUser;
  int flag = ok ? 1 : 0;
  PetscCallMPI(MPI_Bcast(&flag, 1, MPI_INT, 0, comm));
  PetscCheck(flag, comm, PETSC_ERR_USER_INPUT, "%s", message.c_str());
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode AgreeOnAllRanks(MPI_Comm comm, bool ok, const std::string &message) {
  PetscFunctionBeginUser;
  int flag = ok ? 1 : 0;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &flag, 1, MPI_INT, MPI_LAND, comm));
  PetscCheck(flag, comm, PETSC_ERR_USER_INPUT, "%s", message.c_str());
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

std::string XdmfPath(const std::string &h5_path) {
  return std::filesystem::path(h5_path).replace_extension(".xdmf").string();
}

// Why rank 0 could not create or overwrite `path` ("" if it could).
std::string WhyNotWritable(const std::string &path) {
  namespace fs = std::filesystem;
  if (path.empty()) return "empty file name";
  if (fs::path(path).extension() == ".xdmf")
    return "the result file must not end in .xdmf (that name is its .xdmf)";
  const fs::path folder =
      fs::path(path).has_parent_path() ? fs::path(path).parent_path() : fs::path(".");
  std::error_code error;
  if (!fs::exists(folder, error)) return "folder '" + folder.string() + "' does not exist";
  if (!fs::is_directory(folder, error)) return "'" + folder.string() + "' is not a folder";
  if (access(folder.c_str(), W_OK | X_OK) != 0)
    return "folder '" + folder.string() + "' is not writable";
  for (const std::string &file : {path, XdmfPath(path)}) {
    if (!fs::exists(file, error)) continue;
    if (fs::is_directory(file, error)) return "'" + file + "' is a folder";
    if (access(file.c_str(), W_OK) != 0) return "'" + file + "' is not writable";
  }
  return "";
}

}  // namespace

PetscErrorCode CheckOutputPath(MPI_Comm comm, const char *option, const std::string &path) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  const std::string why = rank == 0 ? WhyNotWritable(path) : "";
  PetscCall(
      AgreeOnSuccess(comm, why.empty(),
                     std::string("option ") + option + ": cannot create '" + path + "': " + why));
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// Calls visit(body, b, from, to) for each body b that meets the natural range
// `slab`, with [from, to) its part of the range counted from the body's first
// item; `first_of(b)` is body b's first natural index and `count_of(b)` its
// number of items (vertices or tets).
template <typename First, typename Count, typename Visit>
void ForEachBodyPart(const Scene &scene, RowSlab slab, First first_of, Count count_of,
                     Visit visit) {
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const hsize_t first = first_of(b), last = first + count_of(b);
    const hsize_t from = std::max(first, slab.begin), to = std::min(last, slab.end);
    if (from < to) visit(scene.bodies[b], b, from - first, to - first);
  }
}

template <typename Visit>
void ForEachBodyVertices(const Scene &scene, RowSlab slab, Visit visit) {
  ForEachBodyPart(
      scene, slab, [&](size_t b) { return hsize_t(scene.bodies[b].first_vertex); },
      [&](size_t b) { return hsize_t(scene.bodies[b].num_vertices()); }, visit);
}

}  // namespace

std::vector<int32_t> SlabVertexBodies(const Scene &scene, RowSlab vertices) {
  std::vector<int32_t> bodies;
  bodies.reserve(vertices.count());
  ForEachBodyVertices(scene, vertices, [&](const Body &, size_t b, hsize_t from, hsize_t to) {
    bodies.insert(bodies.end(), to - from, static_cast<int32_t>(b));
  });
  return bodies;
}

std::vector<int32_t> ShareTetRows(const MeshShare &share) {
  std::vector<int32_t> rows;
  rows.reserve(4 * share.tets.size());
  for (const auto &tet : share.tets) rows.insert(rows.end(), tet.begin(), tet.end());
  return rows;
}

NaturalSlab::~NaturalSlab() {
  VecScatterDestroy(&scatter_);
  VecDestroy(&natural_template_);
}

PetscErrorCode NaturalSlab::Setup(const MeshShare &share, const DofLayout &layout, Vec like) {
  PetscFunctionBeginUser;
  num_vertices_ = static_cast<int32_t>(share.num_vertices);
  MPI_Comm comm = PetscObjectComm((PetscObject)like);
  slab_ = EvenSlab(static_cast<hsize_t>(num_vertices_), layout.rank, layout.size);
  PetscCheck(slab_.begin == static_cast<hsize_t>(share.first_vertex) &&
                 slab_.count() == static_cast<hsize_t>(share.slab_size()),
             PETSC_COMM_SELF, PETSC_ERR_PLIB, "the mesh share is not this rank's file slab");
  rest_.assign(share.rest.data(), share.rest.data() + share.rest.size());
  PetscCall(VecCreate(comm, &natural_template_));
  PetscCall(VecSetSizes(natural_template_, 3 * static_cast<PetscInt>(slab_.count()),
                        3 * static_cast<PetscInt>(num_vertices_)));
  PetscCall(VecSetBlockSize(natural_template_, 3));
  PetscCall(VecSetType(natural_template_, VECMPI));
  // Each rank sends its owned vertices (PETSc block local_begin + i) to their
  // natural blocks, wherever those live.
  const PetscInt owned = layout.local_count();
  std::vector<PetscInt> from(owned),
      to(layout.natural_of_owned.begin(), layout.natural_of_owned.end());
  for (PetscInt i = 0; i < owned; ++i) from[i] = layout.local_begin() + i;
  IS is_from, is_to;
  PetscCall(ISCreateBlock(PETSC_COMM_SELF, 3, owned, from.data(), PETSC_COPY_VALUES, &is_from));
  PetscCall(ISCreateBlock(PETSC_COMM_SELF, 3, owned, to.data(), PETSC_COPY_VALUES, &is_to));
  PetscCall(VecScatterCreate(like, is_from, natural_template_, is_to, &scatter_));
  PetscCall(ISDestroy(&is_from));
  PetscCall(ISDestroy(&is_to));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode NaturalSlab::CreateVector(bool rest, Vec *natural) const {
  PetscFunctionBeginUser;
  PetscCall(VecDuplicate(natural_template_, natural));
  PetscCall(VecZeroEntries(*natural));
  if (rest && slab_.count() > 0) {
    PetscScalar *x;
    PetscCall(VecGetArray(*natural, &x));
    std::copy(rest_.begin(), rest_.end(), x);
    PetscCall(VecRestoreArray(*natural, &x));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode NaturalSlab::Gather(Vec dofs, Vec natural) const {
  PetscFunctionBeginUser;
  PetscCall(VecScatterBegin(scatter_, dofs, natural, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(scatter_, dofs, natural, INSERT_VALUES, SCATTER_FORWARD));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode NaturalSlab::Scatter(Vec natural, Vec dofs) const {
  PetscFunctionBeginUser;
  PetscCall(VecScatterBegin(scatter_, natural, dofs, INSERT_VALUES, SCATTER_REVERSE));
  PetscCall(VecScatterEnd(scatter_, natural, dofs, INSERT_VALUES, SCATTER_REVERSE));
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// The series of a result file, with the size of one frame in doubles (per vertex).
struct SeriesName {
  const char *name;
  bool per_vertex;
};
constexpr SeriesName kSeries[] = {{"/time", false},           {"/positions", true},
                                  {"/velocities", true},      {"/energy/kinetic", false},
                                  {"/energy/elastic", false}, {"/energy/gravitational", false}};

// Collective. Root attribute "complete": 0 while the run goes on, 1 once it has finished.
bool MarkComplete(hid_t file, int complete) {
  return SetAttribute(file, "complete", H5T_NATIVE_INT, &complete);
}

// Collective. Creates the fixed dataset location/name [rows][columns] (columns 0:
// one-dimensional [rows]) and writes this rank's rows `slab` from `values`.
bool WriteSlabDataset(hid_t location, const char *name, hid_t type, hsize_t rows, hsize_t columns,
                      RowSlab slab, const void *values) {
  const hid_t set = CreateRowDataset(
      location, name, type,
      columns ? std::vector<hsize_t>{rows, columns} : std::vector<hsize_t>{rows}, false);
  const bool ok = set >= 0 && WriteRows(set, type, slab, values);
  if (set >= 0) H5Dclose(set);
  return ok;
}

// Collective. This rank's rows of /mesh/boundary_triangles (3 natural vertices
// per row, each body's rows as BoundaryTriangles orders them; ShareBoundaryTriangles).
PetscErrorCode BoundaryRows(MPI_Comm comm, const MeshShare &share, std::vector<int32_t> *rows) {
  PetscFunctionBeginUser;
  std::vector<std::array<PetscInt, 3>> triangles;
  PetscCall(ShareBoundaryTriangles(comm, share, &triangles));
  rows->clear();
  rows->reserve(3 * triangles.size());
  for (const auto &triangle : triangles)
    rows->insert(rows->end(), triangle.begin(), triangle.end());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Rows [begin, end) of /mesh/boundary_triangles that `local` rows
// computed on this rank fill (the ranks' rows follow each other in rank order),
// and the total number of rows.
PetscErrorCode RowsInRankOrder(MPI_Comm comm, hsize_t local, RowSlab *rows, hsize_t *total) {
  PetscFunctionBeginUser;
  uint64_t count = local, before = 0, all = 0;
  PetscCallMPI(MPI_Exscan(&count, &before, 1, MPI_UINT64_T, MPI_SUM, comm));
  PetscCallMPI(MPI_Allreduce(&count, &all, 1, MPI_UINT64_T, MPI_SUM, comm));
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (rank == 0) before = 0;  // MPI_Exscan leaves rank 0's result undefined
  *rows = {before, before + count};
  *total = all;
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

// Collective. The static mesh datasets under /mesh, every rank its slabs.
PetscErrorCode ResultWriter::WriteMesh(const Scene &scene, const MeshShare &share, bool *written) {
  PetscFunctionBeginUser;
  const RowSlab vertices = natural_.vertices();
  const RowSlab tets = EvenSlab(static_cast<hsize_t>(num_tets_), rank_, size_);
  PetscCheck(tets.begin == static_cast<hsize_t>(share.first_tet) &&
                 tets.count() == static_cast<hsize_t>(share.num_tets()) &&
                 vertices.begin == static_cast<hsize_t>(share.first_vertex) &&
                 vertices.count() == static_cast<hsize_t>(share.slab_size()),
             PETSC_COMM_SELF, PETSC_ERR_PLIB, "the mesh share is not this rank's file slab");
  const hsize_t V = static_cast<hsize_t>(num_vertices_), T = static_cast<hsize_t>(num_tets_);
  const hsize_t bodies = scene.bodies.size();
  std::vector<int32_t> triangles;
  PetscCall(BoundaryRows(comm_, share, &triangles));
  const hid_t group = H5Gcreate2(file_, "/mesh", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  hsize_t B = 0;
  RowSlab triangle_rows;
  PetscCall(RowsInRankOrder(comm_, triangles.size() / 3, &triangle_rows, &B));
  // The per-body tables are small: rank 0 writes them whole.
  const RowSlab body_rows{0, rank_ == 0 ? bodies : 0};
  std::vector<int32_t> body_fixed;
  std::vector<double> materials;
  for (const Body &body : scene.bodies) {
    body_fixed.push_back(body.fixed && !body.at_rest ? 1 : 0);
    materials.insert(materials.end(),
                     {body.material.density, body.material.young, body.material.poisson});
  }
  bool ok = group >= 0;
  ok = ok &&
       WriteSlabDataset(group, "tets", H5T_NATIVE_INT32, T, 4, tets, ShareTetRows(share).data());
  ok = ok && WriteSlabDataset(group, "boundary_triangles", H5T_NATIVE_INT32, B, 3, triangle_rows,
                              triangles.data());
  ok = ok && WriteSlabDataset(group, "vertex_body", H5T_NATIVE_INT32, V, 0, vertices,
                              SlabVertexBodies(scene, vertices).data());
  ok = ok && WriteSlabDataset(group, "rest_positions", H5T_NATIVE_DOUBLE, V, 3, vertices,
                              share.rest.data());
  ok = ok && WriteSlabDataset(group, "body_fixed", H5T_NATIVE_INT32, bodies, 0, body_rows,
                              body_fixed.data());
  ok = ok && WriteSlabDataset(group, "body_material", H5T_NATIVE_DOUBLE, bodies, 3, body_rows,
                              materials.data());
  ok = ok && SetAttribute(group, "scene", scene.path);
  if (group >= 0) H5Gclose(group);
  *written = ok;
  PetscFunctionReturn(PETSC_SUCCESS);
}

ResultWriter::~ResultWriter() {
  if (file_ >= 0) H5Fclose(file_);
  if (xdmf_) std::fclose(xdmf_);
  VecDestroy(&positions_);
  VecDestroy(&velocities_);
}

// Collective. A new file with the mesh and the empty series.
PetscErrorCode ResultWriter::CreateFile(const Scene &scene, const MeshShare &share, bool *created) {
  PetscFunctionBeginUser;
  file_ = CreateParallelFile(comm_, options_.path);
  *created = file_ >= 0;
  if (file_ < 0) PetscFunctionReturn(PETSC_SUCCESS);
  const hsize_t V = static_cast<hsize_t>(num_vertices_);
  const hid_t energy = H5Gcreate2(file_, "/energy", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  bool ok = energy >= 0;
  if (energy >= 0) H5Gclose(energy);
  for (const SeriesName &series : kSeries) {
    const hid_t set =
        CreateFrameDataset(file_, series.name,
                           series.per_vertex ? std::vector<hsize_t>{V, 3} : std::vector<hsize_t>{});
    ok = ok && set >= 0;
    if (set >= 0) H5Dclose(set);
  }
  bool mesh = false;
  PetscCall(WriteMesh(scene, share, &mesh));
  *created = ok && mesh && MarkComplete(file_, 0);
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// Collective. The number of frames of series `name` (-1: none).
int64_t SeriesLength(hid_t file, const char *name) {
  if (!LinkExists(file, name)) return -1;
  const hid_t set = H5Dopen2(file, name, H5P_DEFAULT);
  const std::vector<hsize_t> dims = set >= 0 ? DatasetDims(set) : std::vector<hsize_t>{};
  if (set >= 0) H5Dclose(set);
  return dims.empty() ? -1 : static_cast<int64_t>(dims[0]);
}

// Collective. Cuts series `name` to `frames` frames.
bool ResizeSeries(hid_t file, const char *name, hsize_t frames) {
  const hid_t set = H5Dopen2(file, name, H5P_DEFAULT);
  const bool ok = set >= 0 && ExtendRows(set, frames);
  if (set >= 0) H5Dclose(set);
  return ok;
}

// Collective. Every rank reads the first `frames` values of /time.
bool ReadTimes(hid_t file, PetscInt frames, std::vector<double> *times) {
  times->resize(frames);
  const hid_t set = H5Dopen2(file, "/time", H5P_DEFAULT);
  const bool ok = set >= 0 && ReadRows(set, H5T_NATIVE_DOUBLE, {0, hsize_t(frames)}, times->data());
  if (set >= 0) H5Dclose(set);
  return ok;
}

// Collective. Copies frame `frame` of series `series` from `source` to `target`,
// every rank the rows of its vertex slab (rank 0 the scalars).
bool CopyFrame(hid_t source, hid_t target, const SeriesName &series, hsize_t frame, RowSlab slab,
               bool first_rank, std::vector<double> *buffer) {
  const hid_t from = H5Dopen2(source, series.name, H5P_DEFAULT);
  const hid_t to = H5Dopen2(target, series.name, H5P_DEFAULT);
  bool ok = from >= 0 && to >= 0;
  if (ok && series.per_vertex) {
    buffer->resize(3 * slab.count());
    ok = ReadFrameRows(from, frame, H5T_NATIVE_DOUBLE, slab, buffer->data()) &&
         WriteFrameRows(to, frame, H5T_NATIVE_DOUBLE, slab, buffer->data());
  } else if (ok) {
    double value = 0;
    ok = ReadScalarFrame(from, frame, &value) && WriteScalarFrame(to, frame, value, first_rank);
  }
  if (from >= 0) H5Dclose(from);
  if (to >= 0) H5Dclose(to);
  return ok;
}

}  // namespace

// Collective. Reopens the continued file and cuts its series back to the kept frames.
bool ResultWriter::ContinueInPlace(const Continuation &continuation) {
  file_ = OpenParallelFile(comm_, options_.path, true);
  if (file_ < 0) return false;
  for (const SeriesName &series : kSeries)
    if (SeriesLength(file_, series.name) < continuation.frames ||
        !ResizeSeries(file_, series.name, continuation.frames))
      return false;
  return ReadTimes(file_, continuation.frames, &times_) && MarkComplete(file_, 0) &&
         H5Fflush(file_, H5F_SCOPE_LOCAL) >= 0;
}

// Collective. Copies the kept frames of the continued file into the new one,
// frame by frame, every rank its slab.
bool ResultWriter::CopyFrames(const Continuation &continuation) {
  const hid_t source = OpenParallelFile(comm_, continuation.source, false);
  if (source < 0) return false;
  std::vector<double> buffer;
  bool ok = ReadTimes(source, continuation.frames, &times_);
  for (PetscInt f = 0; ok && f < continuation.frames; ++f)
    for (const SeriesName &series : kSeries)
      ok = ok && CopyFrame(source, file_, series, f, natural_.vertices(), rank_ == 0, &buffer);
  H5Fclose(source);
  return ok && H5Fflush(file_, H5F_SCOPE_LOCAL) >= 0;
}

PetscErrorCode ResultWriter::Open(MPI_Comm comm, const OutputOptions &options, const Scene &scene,
                                  const DofLayout &layout, const MeshShare &share, Vec like,
                                  const Continuation *continuation) {
  PetscFunctionBeginUser;
  comm_ = comm;
  options_ = options;
  PetscCallMPI(MPI_Comm_rank(comm, &rank_));
  PetscCallMPI(MPI_Comm_size(comm, &size_));
  num_vertices_ = scene.num_vertices();
  num_tets_ = scene.num_tets();
  PetscCall(natural_.Setup(share, layout, like));
  // Vertices without unknowns keep their rest position and zero velocity.
  PetscCall(natural_.CreateVector(true, &positions_));
  PetscCall(natural_.CreateVector(false, &velocities_));

  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // we report failures ourselves
  int in_place = 0;
  if (rank_ == 0 && continuation) {
    std::error_code error;
    in_place = std::filesystem::exists(options_.path, error) &&
               std::filesystem::equivalent(options_.path, continuation->source, error);
  }
  PetscCallMPI(MPI_Bcast(&in_place, 1, MPI_INT, 0, comm));
  bool ok = true;
  std::string what = "cannot create HDF5 file";
  if (in_place) {
    what = "cannot continue HDF5 file";
    ok = ContinueInPlace(*continuation);
  } else {
    PetscCall(CreateFile(scene, share, &ok));
    if (ok && continuation) {
      what = "cannot copy the first frames of '" + continuation->source + "' into";
      ok = CopyFrames(*continuation);
    }
  }
  PetscCall(AgreeOnAllRanks(comm, ok, "option -output: " + what + " '" + options_.path + "'"));
  PetscCall(OpenXdmf());
  xdmf_frames_ = times_.size();  // listed by the .xdmf just written: every rank counts from here
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Rank 0 writes the .xdmf listing the frames already in the file.
PetscErrorCode ResultWriter::OpenXdmf() {
  PetscFunctionBeginUser;
  bool ok = true;
  if (rank_ == 0) {
    xdmf_ = std::fopen(XdmfPath(options_.path).c_str(), "w");
    ok = xdmf_ && std::fputs(
                      "<?xml version=\"1.0\" ?>\n<Xdmf Version=\"3.0\">\n<Domain>\n<Grid "
                      "Name=\"softbody\" GridType=\"Collection\" "
                      "CollectionType=\"Temporal\">\n",
                      xdmf_) >= 0;
    xdmf_tail_ = ok ? std::ftell(xdmf_) : 0;
    ok = ok && ExtendXdmf();
  }
  PetscCall(AgreeOnSuccess(comm_, ok,
                           "option -output: cannot create '" + XdmfPath(options_.path) +
                               "' beside '" + options_.path + "'"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ResultWriter::WriteFrame(PetscReal time, Vec positions, Vec velocities,
                                        const EnergySample &energy) {
  PetscFunctionBeginUser;
  PetscCall(natural_.Gather(positions, positions_));
  PetscCall(natural_.Gather(velocities, velocities_));
  const hsize_t frame = times_.size();
  const PetscScalar *x, *v;
  PetscCall(VecGetArrayRead(positions_, &x));
  PetscCall(VecGetArrayRead(velocities_, &v));
  const std::pair<const char *, const double *> rows[] = {{"/positions", x}, {"/velocities", v}};
  const std::pair<const char *, double> scalars[] = {
      {"/time", time},
      {"/energy/kinetic", energy.kinetic},
      {"/energy/elastic", energy.elastic},
      {"/energy/gravitational", energy.gravitational}};
  bool ok = true;
  for (const auto &[name, values] : rows) {
    const hid_t set = H5Dopen2(file_, name, H5P_DEFAULT);
    ok = ok && set >= 0 &&
         WriteFrameRows(set, frame, H5T_NATIVE_DOUBLE, natural_.vertices(), values);
    if (set >= 0) H5Dclose(set);
  }
  for (const auto &[name, value] : scalars) {
    const hid_t set = H5Dopen2(file_, name, H5P_DEFAULT);
    ok = ok && set >= 0 && WriteScalarFrame(set, frame, value, rank_ == 0);
    if (set >= 0) H5Dclose(set);
  }
  PetscCall(VecRestoreArrayRead(positions_, &x));
  PetscCall(VecRestoreArrayRead(velocities_, &v));
  PetscCall(AgreeOnAllRanks(comm_, ok, "cannot write frame to '" + options_.path + "'"));
  times_.push_back(time);
  if (static_cast<PetscInt>(times_.size() - xdmf_frames_) >= options_.flush_every)
    PetscCall(Flush());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// XDMF 3, as ParaView's default reader (Xdmf3ReaderS) takes it: a temporal
// collection of grids sharing the tets; frame f of a [F][V][3] series is the HDF
// subset "file:/set|start:stride:count:dims", dims giving the series' length
// when the entry was written (the reader selects the hyperslab from the actual
// dataset, which may have grown since: checked with ParaView 5.11). New entries
// overwrite the closing tags, which then follow them again.
bool ResultWriter::ExtendXdmf() {
  const std::string h5 = std::filesystem::path(options_.path).filename().string();
  const std::string V = std::to_string(num_vertices_), T = std::to_string(num_tets_);
  const std::string F = std::to_string(times_.size());
  auto slab = [&](const char *dataset, size_t frame) {
    return "<DataItem Dimensions=\"" + V +
           " 3\" NumberType=\"Float\" Precision=\"8\" "
           "Format=\"HDF\">" +
           h5 + ":" + dataset + "|" + std::to_string(frame) + " 0 0:1 1 1:1 " + V + " 3:" + F +
           " " + V + " 3</DataItem>\n";
  };
  std::string entries;
  for (size_t f = xdmf_frames_; f < times_.size(); ++f) {
    char time[32];
    std::snprintf(time, sizeof(time), "%.17g", times_[f]);
    entries +=
        "<Grid Name=\"frame " + std::to_string(f) + "\" GridType=\"Uniform\">\n<Time Value=\"" +
        time + "\"/>\n<Topology TopologyType=\"Tetrahedron\" NumberOfElements=\"" + T + "\">\n" +
        "<DataItem Dimensions=\"" + T + " 4\" NumberType=\"Int\" Precision=\"4\" Format=\"HDF\">" +
        h5 + ":/mesh/tets</DataItem>\n</Topology>\n<Geometry GeometryType=\"XYZ\">\n" +
        slab("/positions", f) +
        "</Geometry>\n<Attribute Name=\"velocity\" AttributeType=\"Vector\" Center=\"Node\">\n" +
        slab("/velocities", f) +
        "</Attribute>\n<Attribute Name=\"body\" AttributeType=\"Scalar\" Center=\"Node\">\n"
        "<DataItem Dimensions=\"" +
        V + "\" NumberType=\"Int\" Precision=\"4\" Format=\"HDF\">" + h5 +
        ":/mesh/vertex_body</DataItem>\n</Attribute>\n</Grid>\n";
  }
  bool ok = std::fseek(xdmf_, xdmf_tail_, SEEK_SET) == 0 && std::fputs(entries.c_str(), xdmf_) >= 0;
  xdmf_tail_ = std::ftell(xdmf_);
  ok = ok && xdmf_tail_ >= 0 && std::fputs("</Grid>\n</Domain>\n</Xdmf>\n", xdmf_) >= 0 &&
       std::fflush(xdmf_) == 0;
  if (ok) xdmf_frames_ = times_.size();
  return ok;
}

PetscErrorCode ResultWriter::Flush() {
  PetscFunctionBeginUser;
  // The frames reach the disk (collectively) before the .xdmf lists them.
  bool ok = H5Fflush(file_, H5F_SCOPE_LOCAL) >= 0;
  PetscCall(AgreeOnAllRanks(comm_, ok, "cannot flush '" + options_.path + "'"));
  if (rank_ == 0) ok = ExtendXdmf();
  PetscCall(AgreeOnSuccess(comm_, ok, "cannot flush '" + options_.path + "' and its .xdmf"));
  xdmf_frames_ = times_.size();
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ResultWriter::WriteWorld(const double gravity[3], const double *ground_y) {
  PetscFunctionBeginUser;
  bool ok = SetAttribute(file_, "gravity", gravity, 3);
  if (ground_y) ok = SetAttribute(file_, "ground_y", *ground_y) && ok;
  PetscCall(AgreeOnAllRanks(comm_, ok, "cannot write to '" + options_.path + "'"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ResultWriter::WriteTextAttribute(const char *name, const std::string &value) {
  PetscFunctionBeginUser;
  const bool ok = SetAttribute(file_, name, value);
  PetscCall(AgreeOnAllRanks(comm_, ok, "cannot write to '" + options_.path + "'"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ResultWriter::Close(const std::vector<std::pair<std::string, double>> &statistics,
                                   int interrupted_by) {
  PetscFunctionBeginUser;
  if (file_ < 0) PetscFunctionReturn(PETSC_SUCCESS);
  // Attributes are metadata: every rank writes rank 0's values (timings differ).
  std::vector<double> values;
  for (const auto &entry : statistics) values.push_back(entry.second);
  int counts[2] = {static_cast<int>(values.size()), -static_cast<int>(values.size())};
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, counts, 2, MPI_INT, MPI_MAX, comm_));
  PetscCheck(counts[0] == -counts[1], comm_, PETSC_ERR_PLIB,
             "the ranks hold different numbers of statistics for '%s'", options_.path.c_str());
  PetscCallMPI(MPI_Bcast(values.data(), static_cast<int>(values.size()), MPI_DOUBLE, 0, comm_));
  bool ok = true;
  for (size_t i = 0; i < statistics.size(); ++i)
    ok = SetAttribute(file_, statistics[i].first.c_str(), values[i]) && ok;
  ok = SetAttribute(file_, "interrupted", H5T_NATIVE_INT, &interrupted_by) && ok;
  ok = MarkComplete(file_, interrupted_by ? 0 : 1) && ok;
  ok = H5Fclose(file_) >= 0 && ok;
  file_ = -1;
  PetscCall(AgreeOnAllRanks(comm_, ok, "cannot finish '" + options_.path + "'"));
  if (rank_ == 0) {
    ok = ExtendXdmf() && std::fclose(xdmf_) == 0;
    xdmf_ = nullptr;
  }
  PetscCall(AgreeOnSuccess(comm_, ok, "cannot finish '" + options_.path + "' and its .xdmf"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ExportMatrices(const std::string &dir, const DofLayout &layout,
                              const LocalElements &elements, PetscReal shear_scale, Vec lumped_mass,
                              PetscReal alpha, PetscReal beta) {
  PetscFunctionBeginUser;
  MPI_Comm comm = PetscObjectComm((PetscObject)lumped_mass);
  Mat stiffness;
  PetscCall(CreateStiffnessMatrix(comm, layout, elements, shear_scale, &stiffness));
  std::error_code error;
  if (layout.rank == 0) std::filesystem::create_directories(dir, error);
  PetscCall(
      AgreeOnSuccess(comm, !error, "option -export_matrices: cannot create folder '" + dir + "'"));

  // Natural order of the free DOFs, with the PETSc layout's local sizes: the
  // PETSc vertex of each free vertex (in natural order) this rank's rows hold.
  std::vector<PetscInt> natural;
  PetscInt free = 0;
  for (const PetscInt petsc : layout.petsc_of_natural) {
    if (petsc < 0) continue;
    if (free >= layout.local_begin() && free < layout.local_begin() + layout.local_count())
      for (int c = 0; c < 3; ++c) natural.push_back(3 * petsc + c);
    ++free;
  }
  IS is;
  PetscCall(ISCreateGeneral(comm, static_cast<PetscInt>(natural.size()), natural.data(),
                            PETSC_COPY_VALUES, &is));
  Mat K, M, D;
  Vec mass;
  PetscCall(MatCreateSubMatrix(stiffness, is, is, MAT_INITIAL_MATRIX, &K));
  PetscCall(VecGetSubVector(lumped_mass, is, &mass));
  const PetscInt n = static_cast<PetscInt>(natural.size());
  PetscCall(MatCreateAIJ(comm, n, n, PETSC_DETERMINE, PETSC_DETERMINE, 1, nullptr, 0, nullptr, &M));
  PetscCall(MatDiagonalSet(M, mass, INSERT_VALUES));
  PetscCall(VecRestoreSubVector(lumped_mass, is, &mass));
  PetscCall(MatDuplicate(K, MAT_COPY_VALUES, &D));
  PetscCall(MatScale(D, beta));
  PetscCall(MatAXPY(D, alpha, M, SUBSET_NONZERO_PATTERN));

  const std::pair<const char *, Mat> files[] = {{"M.bin", M}, {"K.bin", K}, {"D.bin", D}};
  for (const auto &[name, matrix] : files) {
    PetscViewer viewer;
    PetscCall(PetscViewerCreate(comm, &viewer));
    PetscCall(PetscViewerSetType(viewer, PETSCVIEWERBINARY));
    PetscCall(PetscViewerFileSetMode(viewer, FILE_MODE_WRITE));
    PetscCall(PetscViewerBinarySetSkipInfo(viewer, PETSC_TRUE));
    PetscCall(PetscViewerFileSetName(viewer, (std::filesystem::path(dir) / name).c_str()));
    PetscCall(MatView(matrix, viewer));
    PetscCall(PetscViewerDestroy(&viewer));
  }
  PetscCall(MatDestroy(&stiffness));
  PetscCall(MatDestroy(&K));
  PetscCall(MatDestroy(&M));
  PetscCall(MatDestroy(&D));
  PetscCall(ISDestroy(&is));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
