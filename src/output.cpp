#include "output.hpp"

#include <filesystem>
#include <fstream>

#include "options.hpp"

namespace softbody {

PetscErrorCode ProcessOutputOptions(MPI_Comm comm, OutputOptions *o) {
  PetscFunctionBeginUser;
  char path[PETSC_MAX_PATH_LEN] = "", dir[PETSC_MAX_PATH_LEN] = "";
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kInteger, "-output_every"}}));
  PetscOptionsBegin(comm, nullptr, "Output", nullptr);
  PetscCall(PetscOptionsString("-output", "HDF5 file of the frames (+ .xdmf beside it); none if unset",
                               nullptr, path, path, sizeof(path), nullptr));
  PetscCall(PetscOptionsInt("-output_every", "Write a frame every k steps", nullptr, o->every,
                            &o->every, nullptr));
  PetscCall(PetscOptionsString("-export_matrices",
                               "Folder for M.bin, K.bin, D.bin (PETSc binary, natural order)",
                               nullptr, dir, dir, sizeof(dir), nullptr));
  PetscOptionsEnd();
  o->path = path;
  o->matrix_dir = dir;
  PetscCheck(o->every >= 1, comm, PETSC_ERR_USER_INPUT,
             "option -output_every: must be >= 1 (got %" PetscInt_FMT ")", o->every);
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// Rank 0 reports success (true) or failure of an action; every rank then fails
// with the same user-facing message if it failed.
PetscErrorCode AgreeOnSuccess(MPI_Comm comm, bool ok, const std::string &message) {
  PetscFunctionBeginUser;
  int flag = ok ? 1 : 0;
  PetscCallMPI(MPI_Bcast(&flag, 1, MPI_INT, 0, comm));
  PetscCheck(flag, comm, PETSC_ERR_USER_INPUT, "%s", message.c_str());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Extendible dataset of frames: dims [0, frame_dims...], chunks of one frame
// (1024 values for scalar series).
hid_t CreateSeries(hid_t location, const char *name, const std::vector<hsize_t> &frame_dims) {
  std::vector<hsize_t> dims{0}, max_dims{H5S_UNLIMITED}, chunk{frame_dims.empty() ? 1024u : 1u};
  for (hsize_t d : frame_dims) {
    dims.push_back(d);
    max_dims.push_back(d);
    chunk.push_back(d);
  }
  const hid_t space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), max_dims.data());
  const hid_t properties = H5Pcreate(H5P_DATASET_CREATE);
  H5Pset_chunk(properties, static_cast<int>(chunk.size()), chunk.data());
  const hid_t set = H5Dcreate2(location, name, H5T_NATIVE_DOUBLE, space, H5P_DEFAULT, properties,
                               H5P_DEFAULT);
  H5Pclose(properties);
  H5Sclose(space);
  return set;
}

// Appends frame `frame` of a series created by CreateSeries.
bool AppendToSeries(hid_t file, const char *name, hsize_t frame, const double *values) {
  const hid_t set = H5Dopen2(file, name, H5P_DEFAULT);
  if (set < 0) return false;
  hid_t space = H5Dget_space(set);
  const int rank = H5Sget_simple_extent_ndims(space);
  std::vector<hsize_t> dims(rank), start(rank, 0);
  H5Sget_simple_extent_dims(space, dims.data(), nullptr);
  H5Sclose(space);
  dims[0] = frame + 1;
  bool ok = H5Dset_extent(set, dims.data()) >= 0;
  space = H5Dget_space(set);
  start[0] = frame;
  dims[0] = 1;
  ok = ok && H5Sselect_hyperslab(space, H5S_SELECT_SET, start.data(), nullptr, dims.data(), nullptr) >= 0;
  const hid_t memory = H5Screate_simple(rank, dims.data(), nullptr);
  ok = ok && H5Dwrite(set, H5T_NATIVE_DOUBLE, memory, space, H5P_DEFAULT, values) >= 0;
  H5Sclose(memory);
  H5Sclose(space);
  H5Dclose(set);
  return ok;
}

template <typename T>
bool WriteArray(hid_t location, const char *name, hid_t type, const std::vector<hsize_t> &dims,
                const T *values) {
  const hid_t space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr);
  const hid_t set = H5Dcreate2(location, name, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  const bool ok = set >= 0 && H5Dwrite(set, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values) >= 0;
  if (set >= 0) H5Dclose(set);
  H5Sclose(space);
  return ok;
}

// A scalar root attribute, created or overwritten.
template <typename T>
bool SetRootAttribute(hid_t file, const char *name, hid_t type, T value) {
  const hid_t space = H5Screate(H5S_SCALAR);
  const hid_t attribute = H5Aexists(file, name) > 0
                              ? H5Aopen(file, name, H5P_DEFAULT)
                              : H5Acreate2(file, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  const bool ok = attribute >= 0 && H5Awrite(attribute, type, &value) >= 0;
  if (attribute >= 0) H5Aclose(attribute);
  H5Sclose(space);
  return ok;
}

// Root attribute "complete": 0 while the run goes on, 1 once it has finished.
bool MarkComplete(hid_t file, int complete) {
  return SetRootAttribute(file, "complete", H5T_NATIVE_INT, complete);
}

// Rank 0: the static mesh datasets under /mesh.
bool WriteMesh(hid_t file, const Scene &scene) {
  const hid_t group = H5Gcreate2(file, "/mesh", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  std::vector<int32_t> tets, triangles, vertex_body, body_fixed;
  std::vector<double> rest;
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    body_fixed.push_back(body.fixed && !body.at_rest ? 1 : 0);
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
  const hsize_t V = vertex_body.size();
  bool ok = group >= 0;
  ok = ok && WriteArray(group, "tets", H5T_NATIVE_INT32, {tets.size() / 4, 4}, tets.data());
  ok = ok && WriteArray(group, "boundary_triangles", H5T_NATIVE_INT32, {triangles.size() / 3, 3},
                        triangles.data());
  ok = ok && WriteArray(group, "vertex_body", H5T_NATIVE_INT32, {V}, vertex_body.data());
  ok = ok && WriteArray(group, "rest_positions", H5T_NATIVE_DOUBLE, {V, 3}, rest.data());
  ok = ok && WriteArray(group, "body_fixed", H5T_NATIVE_INT32, {body_fixed.size()}, body_fixed.data());
  if (group >= 0) H5Gclose(group);
  return ok;
}

}  // namespace

ResultWriter::~ResultWriter() {
  if (file_ >= 0) H5Fclose(file_);
  VecScatterDestroy(&to_natural_);
  VecDestroy(&positions_);
  VecDestroy(&velocities_);
}

PetscErrorCode ResultWriter::Open(MPI_Comm comm, const std::string &path, const Scene &scene,
                                  const DofLayout &layout, Vec like) {
  PetscFunctionBeginUser;
  comm_ = comm;
  path_ = path;
  PetscCallMPI(MPI_Comm_rank(comm, &rank_));
  num_vertices_ = scene.num_vertices();
  num_tets_ = scene.num_tets();

  // Gather plan: rank 0 receives every free DOF at its natural all-vertex slot.
  const PetscInt n_free = rank_ == 0 ? layout.num_free() : 0;
  std::vector<PetscInt> from(3 * n_free), to(3 * n_free);
  for (PetscInt f = 0; f < n_free; ++f)
    for (int c = 0; c < 3; ++c) {
      from[3 * f + c] = 3 * layout.petsc_of_free[f] + c;
      to[3 * f + c] = 3 * layout.natural_of_free[f] + c;
    }
  const PetscInt natural_size = rank_ == 0 ? 3 * num_vertices_ : 0;
  PetscCall(VecCreateSeq(PETSC_COMM_SELF, natural_size, &positions_));
  PetscCall(VecDuplicate(positions_, &velocities_));
  IS is_from, is_to;
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, 3 * n_free, from.data(), PETSC_COPY_VALUES, &is_from));
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, 3 * n_free, to.data(), PETSC_COPY_VALUES, &is_to));
  PetscCall(VecScatterCreate(like, is_from, positions_, is_to, &to_natural_));
  PetscCall(ISDestroy(&is_from));
  PetscCall(ISDestroy(&is_to));

  // Vertices without unknowns keep their rest position and zero velocity.
  bool ok = true;
  if (rank_ == 0) {
    PetscScalar *x;
    PetscCall(VecGetArray(positions_, &x));
    for (const Body &body : scene.bodies)
      for (int32_t v = 0; v < body.mesh.num_vertices(); ++v)
        for (int c = 0; c < 3; ++c) x[3 * (body.first_vertex + v) + c] = body.mesh.vertices(v, c);
    PetscCall(VecRestoreArray(positions_, &x));
    PetscCall(VecZeroEntries(velocities_));

    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // we report failures ourselves
    file_ = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    ok = file_ >= 0;
    if (ok) {
      const hsize_t V = static_cast<hsize_t>(num_vertices_);
      const hid_t energy = H5Gcreate2(file_, "/energy", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
      for (hid_t set : {CreateSeries(file_, "/time", {}), CreateSeries(file_, "/positions", {V, 3}),
                        CreateSeries(file_, "/velocities", {V, 3}),
                        CreateSeries(energy, "kinetic", {}), CreateSeries(energy, "elastic", {}),
                        CreateSeries(energy, "gravitational", {})}) {
        ok = ok && set >= 0;
        if (set >= 0) H5Dclose(set);
      }
      if (energy >= 0) H5Gclose(energy);
      ok = ok && energy >= 0 && WriteMesh(file_, scene) && MarkComplete(file_, 0);
    }
  }
  PetscCall(AgreeOnSuccess(comm, ok, "option -output: cannot create HDF5 file '" + path + "'"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ResultWriter::Gather(Vec dofs, Vec natural) {
  PetscFunctionBeginUser;
  PetscCall(VecScatterBegin(to_natural_, dofs, natural, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(to_natural_, dofs, natural, INSERT_VALUES, SCATTER_FORWARD));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ResultWriter::WriteFrame(PetscReal time, Vec positions, Vec velocities,
                                        const EnergySample &energy) {
  PetscFunctionBeginUser;
  PetscCall(Gather(positions, positions_));
  PetscCall(Gather(velocities, velocities_));
  bool ok = true;
  if (rank_ == 0) {
    const hsize_t frame = times_.size();
    const PetscScalar *x, *v;
    PetscCall(VecGetArrayRead(positions_, &x));
    PetscCall(VecGetArrayRead(velocities_, &v));
    ok = AppendToSeries(file_, "/time", frame, &time) &&
         AppendToSeries(file_, "/positions", frame, x) &&
         AppendToSeries(file_, "/velocities", frame, v) &&
         AppendToSeries(file_, "/energy/kinetic", frame, &energy.kinetic) &&
         AppendToSeries(file_, "/energy/elastic", frame, &energy.elastic) &&
         AppendToSeries(file_, "/energy/gravitational", frame, &energy.gravitational) &&
         H5Fflush(file_, H5F_SCOPE_LOCAL) >= 0;
    PetscCall(VecRestoreArrayRead(positions_, &x));
    PetscCall(VecRestoreArrayRead(velocities_, &v));
  }
  PetscCall(AgreeOnSuccess(comm_, ok, "cannot write frame to '" + path_ + "'"));
  times_.push_back(time);
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ResultWriter::Close(const std::vector<std::pair<std::string, double>> &statistics) {
  PetscFunctionBeginUser;
  bool ok = true;
  if (rank_ == 0 && file_ >= 0) {
    for (const auto &[name, value] : statistics)
      ok = ok && SetRootAttribute(file_, name.c_str(), H5T_NATIVE_DOUBLE, value);
    ok = ok && MarkComplete(file_, 1) && H5Fclose(file_) >= 0;
    file_ = -1;
    // XDMF 3, as ParaView's default reader (Xdmf3ReaderS) takes it: a temporal
    // collection of grids sharing the tets; frame f of a [F][V][3] series is the
    // HDF subset "file:/set|start:stride:count:dims".
    const std::string h5 = std::filesystem::path(path_).filename().string();
    const std::string xdmf_path = std::filesystem::path(path_).replace_extension(".xdmf").string();
    const size_t F = times_.size();
    const std::string V = std::to_string(num_vertices_), T = std::to_string(num_tets_);
    std::ofstream xdmf(xdmf_path);
    xdmf << "<?xml version=\"1.0\" ?>\n<Xdmf Version=\"3.0\">\n<Domain>\n"
         << "<Grid Name=\"softbody\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
    auto slab = [&](const char *dataset, size_t frame) {
      return "<DataItem Dimensions=\"" + V + " 3\" NumberType=\"Float\" Precision=\"8\" "
             "Format=\"HDF\">" + h5 + ":" + dataset + "|" + std::to_string(frame) + " 0 0:1 1 1:1 " +
             V + " 3:" + std::to_string(F) + " " + V + " 3</DataItem>\n";
    };
    for (size_t f = 0; f < F; ++f) {
      char time[32];
      std::snprintf(time, sizeof(time), "%.17g", times_[f]);
      xdmf << "<Grid Name=\"frame " << f << "\" GridType=\"Uniform\">\n<Time Value=\"" << time
           << "\"/>\n<Topology TopologyType=\"Tetrahedron\" NumberOfElements=\"" << T << "\">\n"
           << "<DataItem Dimensions=\"" << T << " 4\" NumberType=\"Int\" Precision=\"4\" "
           << "Format=\"HDF\">" << h5 << ":/mesh/tets</DataItem>\n</Topology>\n"
           << "<Geometry GeometryType=\"XYZ\">\n" << slab("/positions", f) << "</Geometry>\n"
           << "<Attribute Name=\"velocity\" AttributeType=\"Vector\" Center=\"Node\">\n"
           << slab("/velocities", f) << "</Attribute>\n"
           << "<Attribute Name=\"body\" AttributeType=\"Scalar\" Center=\"Node\">\n"
           << "<DataItem Dimensions=\"" << V << "\" NumberType=\"Int\" Precision=\"4\" "
           << "Format=\"HDF\">" << h5 << ":/mesh/vertex_body</DataItem>\n</Attribute>\n</Grid>\n";
    }
    xdmf << "</Grid>\n</Domain>\n</Xdmf>\n";
    ok = ok && static_cast<bool>(xdmf);
  }
  PetscCall(AgreeOnSuccess(comm_, ok, "cannot finish '" + path_ + "' and its .xdmf"));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ExportMatrices(const std::string &dir, const DofLayout &layout,
                              const LocalElements &elements, PetscReal shear_scale,
                              Vec lumped_mass, PetscReal alpha, PetscReal beta) {
  PetscFunctionBeginUser;
  MPI_Comm comm = PetscObjectComm((PetscObject)lumped_mass);
  Mat stiffness;
  PetscCall(CreateStiffnessMatrix(comm, layout, elements, shear_scale, &stiffness));
  std::error_code error;
  if (layout.rank == 0) std::filesystem::create_directories(dir, error);
  PetscCall(AgreeOnSuccess(comm, !error, "option -export_matrices: cannot create folder '" + dir + "'"));

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
