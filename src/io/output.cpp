#include "io/output.hpp"

#include <unistd.h>

#include <filesystem>
#include <string_view>

#include "common/options.hpp"
#include "io/hdf5_io.hpp"

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

NaturalOrder::~NaturalOrder() {
  VecScatterDestroy(&scatter_);
  VecDestroy(&natural_template_);
}

PetscErrorCode NaturalOrder::Setup(const Scene &scene, const DofLayout &layout, Vec like) {
  PetscFunctionBeginUser;
  scene_ = &scene;
  // Rank 0 receives every free DOF at its natural all-vertex slot.
  const PetscInt n_free = layout.rank == 0 ? layout.num_free() : 0;
  std::vector<PetscInt> from(3 * n_free), to(3 * n_free);
  for (PetscInt f = 0; f < n_free; ++f)
    for (int c = 0; c < 3; ++c) {
      from[3 * f + c] = 3 * layout.petsc_of_free[f] + c;
      to[3 * f + c] = 3 * layout.natural_of_free[f] + c;
    }
  PetscCall(VecCreateSeq(PETSC_COMM_SELF, layout.rank == 0 ? 3 * scene.num_vertices() : 0,
                         &natural_template_));
  IS is_from, is_to;
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, 3 * n_free, from.data(), PETSC_COPY_VALUES, &is_from));
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, 3 * n_free, to.data(), PETSC_COPY_VALUES, &is_to));
  PetscCall(VecScatterCreate(like, is_from, natural_template_, is_to, &scatter_));
  PetscCall(ISDestroy(&is_from));
  PetscCall(ISDestroy(&is_to));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode NaturalOrder::CreateVector(bool rest, Vec *natural) const {
  PetscFunctionBeginUser;
  PetscCall(VecDuplicate(natural_template_, natural));
  PetscCall(VecZeroEntries(*natural));
  PetscInt n;
  PetscCall(VecGetLocalSize(*natural, &n));
  if (rest && n > 0) {
    PetscScalar *x;
    PetscCall(VecGetArray(*natural, &x));
    for (const Body &body : scene_->bodies)
      for (int32_t v = 0; v < body.mesh.num_vertices(); ++v)
        for (int c = 0; c < 3; ++c) x[3 * (body.first_vertex + v) + c] = body.mesh.vertices(v, c);
    PetscCall(VecRestoreArray(*natural, &x));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode NaturalOrder::Gather(Vec dofs, Vec natural) const {
  PetscFunctionBeginUser;
  PetscCall(VecScatterBegin(scatter_, dofs, natural, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(scatter_, dofs, natural, INSERT_VALUES, SCATTER_FORWARD));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode NaturalOrder::Scatter(Vec natural, Vec dofs) const {
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

// Root attribute "complete": 0 while the run goes on, 1 once it has finished.
bool MarkComplete(hid_t file, int complete) {
  return SetAttribute(file, "complete", H5T_NATIVE_INT, &complete);
}

// Rank 0: the static mesh datasets under /mesh.
bool WriteMesh(hid_t file, const Scene &scene) {
  const hid_t group = H5Gcreate2(file, "/mesh", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  std::vector<int32_t> tets, triangles, vertex_body, body_fixed;
  std::vector<double> rest, materials;
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    body_fixed.push_back(body.fixed && !body.at_rest ? 1 : 0);
    materials.insert(materials.end(),
                     {body.material.density, body.material.young, body.material.poisson});
    for (int32_t t = 0; t < body.mesh.num_tets(); ++t)
      for (int a = 0; a < 4; ++a) tets.push_back(body.first_vertex + body.mesh.tets(t, a));
    const auto boundary = BoundaryTriangles(body.mesh);
    for (Eigen::Index f = 0; f < boundary.rows(); ++f)
      for (int a = 0; a < 3; ++a) triangles.push_back(body.first_vertex + boundary(f, a));
    for (int32_t v = 0; v < body.mesh.num_vertices(); ++v) {
      vertex_body.push_back(static_cast<int32_t>(b));
      for (int c = 0; c < 3; ++c) rest.push_back(body.mesh.vertices(v, c));
    }
  }
  const hsize_t V = vertex_body.size(), B = body_fixed.size();
  bool ok = group >= 0;
  ok = ok && WriteArray(group, "tets", H5T_NATIVE_INT32, {tets.size() / 4, 4}, tets.data());
  ok = ok && WriteArray(group, "boundary_triangles", H5T_NATIVE_INT32, {triangles.size() / 3, 3},
                        triangles.data());
  ok = ok && WriteArray(group, "vertex_body", H5T_NATIVE_INT32, {V}, vertex_body.data());
  ok = ok && WriteArray(group, "rest_positions", H5T_NATIVE_DOUBLE, {V, 3}, rest.data());
  ok = ok && WriteArray(group, "body_fixed", H5T_NATIVE_INT32, {B}, body_fixed.data());
  ok = ok && WriteArray(group, "body_material", H5T_NATIVE_DOUBLE, {B, 3}, materials.data());
  ok = ok && SetAttribute(group, "scene", scene.path);
  if (group >= 0) H5Gclose(group);
  return ok;
}

}  // namespace

ResultWriter::~ResultWriter() {
  if (file_ >= 0) H5Fclose(file_);
  if (xdmf_) std::fclose(xdmf_);
  VecDestroy(&positions_);
  VecDestroy(&velocities_);
}

bool ResultWriter::CreateFile(const Scene &scene) {
  file_ = H5Fcreate(options_.path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  if (file_ < 0) return false;
  const hsize_t V = static_cast<hsize_t>(num_vertices_);
  const hid_t energy = H5Gcreate2(file_, "/energy", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  bool ok = energy >= 0;
  if (energy >= 0) H5Gclose(energy);
  for (const SeriesName &series : kSeries) {
    const hid_t set =
        CreateSeries(file_, series.name,
                     series.per_vertex ? std::vector<hsize_t>{V, 3} : std::vector<hsize_t>{});
    ok = ok && set >= 0;
    if (set >= 0) H5Dclose(set);
  }
  return ok && WriteMesh(file_, scene) && MarkComplete(file_, 0);
}

// Rank 0: reopens the continued file and cuts its series back to the kept frames.
bool ResultWriter::ContinueInPlace(const Continuation &continuation) {
  file_ = H5Fopen(options_.path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  if (file_ < 0) return false;
  for (const SeriesName &series : kSeries)
    if (SeriesLength(file_, series.name) < continuation.frames ||
        !ResizeSeries(file_, series.name, continuation.frames))
      return false;
  times_.resize(continuation.frames);
  for (PetscInt f = 0; f < continuation.frames; ++f)
    if (!ReadSeriesFrame(file_, "/time", f, &times_[f])) return false;
  return MarkComplete(file_, 0) && H5Fflush(file_, H5F_SCOPE_LOCAL) >= 0;
}

// Rank 0: copies the kept frames of the continued file into the new one, frame by frame.
bool ResultWriter::CopyFrames(const Continuation &continuation) {
  const hid_t source = H5Fopen(continuation.source.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (source < 0) return false;
  std::vector<double> frame(3 * static_cast<size_t>(num_vertices_));
  bool ok = true;
  times_.resize(continuation.frames);
  for (PetscInt f = 0; ok && f < continuation.frames; ++f)
    for (const SeriesName &series : kSeries) {
      ok = ok && ReadSeriesFrame(source, series.name, f, frame.data()) &&
           WriteSeriesFrame(file_, series.name, f, frame.data());
      if (std::string_view(series.name) == "/time") times_[f] = frame[0];
    }
  H5Fclose(source);
  return ok && H5Fflush(file_, H5F_SCOPE_LOCAL) >= 0;
}

PetscErrorCode ResultWriter::Open(MPI_Comm comm, const OutputOptions &options, const Scene &scene,
                                  const DofLayout &layout, Vec like,
                                  const Continuation *continuation) {
  PetscFunctionBeginUser;
  comm_ = comm;
  options_ = options;
  PetscCallMPI(MPI_Comm_rank(comm, &rank_));
  num_vertices_ = scene.num_vertices();
  num_tets_ = scene.num_tets();
  PetscCall(natural_.Setup(scene, layout, like));
  // Vertices without unknowns keep their rest position and zero velocity.
  PetscCall(natural_.CreateVector(true, &positions_));
  PetscCall(natural_.CreateVector(false, &velocities_));

  bool ok = true;
  std::string what = "cannot create HDF5 file";
  if (rank_ == 0) {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // we report failures ourselves
    std::error_code error;
    const bool in_place = continuation && std::filesystem::exists(options_.path, error) &&
                          std::filesystem::equivalent(options_.path, continuation->source, error);
    if (in_place) {
      what = "cannot continue HDF5 file";
      ok = ContinueInPlace(*continuation);
    } else {
      ok = CreateFile(scene);
      if (ok && continuation) {
        what = "cannot copy the first frames of '" + continuation->source + "' into";
        ok = CopyFrames(*continuation);
      }
    }
    if (ok) {
      xdmf_ = std::fopen(XdmfPath(options_.path).c_str(), "w");
      what = "cannot create '" + XdmfPath(options_.path) + "' beside";
      ok = xdmf_ && std::fputs(
                        "<?xml version=\"1.0\" ?>\n<Xdmf Version=\"3.0\">\n<Domain>\n<Grid "
                        "Name=\"softbody\" GridType=\"Collection\" CollectionType=\"Temporal\">\n",
                        xdmf_) >= 0;
      xdmf_tail_ = ok ? std::ftell(xdmf_) : 0;
      ok = ok && ExtendXdmf();
    }
  }
  PetscCall(AgreeOnSuccess(comm, ok, "option -output: " + what + " '" + options_.path + "'"));
  if (continuation) {  // every rank counts the kept frames
    PetscInt count = static_cast<PetscInt>(times_.size());
    PetscCallMPI(MPI_Bcast(&count, 1, MPIU_INT, 0, comm));
    times_.resize(count);
    PetscCallMPI(MPI_Bcast(times_.data(), static_cast<int>(count), MPI_DOUBLE, 0, comm));
    xdmf_frames_ = times_.size();  // listed by the .xdmf just written: every rank counts from here
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ResultWriter::WriteFrame(PetscReal time, Vec positions, Vec velocities,
                                        const EnergySample &energy) {
  PetscFunctionBeginUser;
  PetscCall(natural_.Gather(positions, positions_));
  PetscCall(natural_.Gather(velocities, velocities_));
  bool ok = true;
  if (rank_ == 0) {
    const hsize_t frame = times_.size();
    const PetscScalar *x, *v;
    PetscCall(VecGetArrayRead(positions_, &x));
    PetscCall(VecGetArrayRead(velocities_, &v));
    ok = WriteSeriesFrame(file_, "/time", frame, &time) &&
         WriteSeriesFrame(file_, "/positions", frame, x) &&
         WriteSeriesFrame(file_, "/velocities", frame, v) &&
         WriteSeriesFrame(file_, "/energy/kinetic", frame, &energy.kinetic) &&
         WriteSeriesFrame(file_, "/energy/elastic", frame, &energy.elastic) &&
         WriteSeriesFrame(file_, "/energy/gravitational", frame, &energy.gravitational);
    PetscCall(VecRestoreArrayRead(positions_, &x));
    PetscCall(VecRestoreArrayRead(velocities_, &v));
  }
  PetscCall(AgreeOnSuccess(comm_, ok, "cannot write frame to '" + options_.path + "'"));
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
  bool ok = true;
  if (rank_ == 0) ok = H5Fflush(file_, H5F_SCOPE_LOCAL) >= 0 && ExtendXdmf();
  PetscCall(AgreeOnSuccess(comm_, ok, "cannot flush '" + options_.path + "' and its .xdmf"));
  xdmf_frames_ = times_.size();
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ResultWriter::WriteWorld(const double gravity[3], const double *ground_y) {
  PetscFunctionBeginUser;
  bool ok = true;
  if (rank_ == 0) {
    ok = SetAttribute(file_, "gravity", gravity, 3);
    if (ground_y) ok = ok && SetAttribute(file_, "ground_y", *ground_y);
  }
  PetscCall(AgreeOnSuccess(comm_, ok, "cannot write to '" + options_.path + "'"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ResultWriter::Close(const std::vector<std::pair<std::string, double>> &statistics,
                                   int interrupted_by) {
  PetscFunctionBeginUser;
  bool ok = true;
  if (rank_ == 0 && file_ >= 0) {
    for (const auto &[name, value] : statistics)
      ok = ok && SetAttribute(file_, name.c_str(), value);
    ok = ok && SetAttribute(file_, "interrupted", H5T_NATIVE_INT, &interrupted_by) &&
         MarkComplete(file_, interrupted_by ? 0 : 1) && H5Fclose(file_) >= 0;
    file_ = -1;
    ok = ok && ExtendXdmf() && std::fclose(xdmf_) == 0;
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

  // Natural order of the free DOFs, with the PETSc layout's local sizes.
  std::vector<PetscInt> natural;
  for (PetscInt f = layout.local_begin(); f < layout.local_begin() + layout.local_count(); ++f)
    for (int c = 0; c < 3; ++c) natural.push_back(3 * layout.petsc_of_free[f] + c);
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
