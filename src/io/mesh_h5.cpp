#include "io/mesh_h5.hpp"

#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <climits>
#include <cstdio>
#include <filesystem>
#include <vector>

#include "common/errors.hpp"
#include "common/even_share.hpp"
#include "fem/element.hpp"
#include "io/hdf5_io.hpp"
#include "io/parallel_hdf5.hpp"

namespace softbody {

namespace fs = std::filesystem;

namespace {

constexpr int kVertexColumns = 3;  // x y z
constexpr int kTetColumns = 4;     // four corners

// Rows the serial reader converts from int64 to TetMesh's int32 at a time: 2 MiB of
// int64 tets, so the conversion buffer stays small next to the mesh itself.
constexpr hsize_t kSerialReadRows = hsize_t(1) << 16;

// ------------------------------------------------------------- HDF5 helpers
// The file's HDF5 calls, kept here in a few small functions so that they can be
// replaced by shared parallel-HDF5 primitives. Each returns false or a negative
// id on failure and prints nothing (the HDF5 error stack is switched off).

// An HDF5 id closed by `close` when the holder goes out of scope.
class Handle {
 public:
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  Handle(const Handle &) = delete;
  Handle &operator=(const Handle &) = delete;
  ~Handle() {
    if (id_ >= 0) close_(id_);
  }
  operator hid_t() const { return id_; }
  bool ok() const { return id_ >= 0; }
  // Closes the id held, if any, and holds `id` instead.
  void reset(hid_t id) {
    if (id_ >= 0) close_(id_);
    id_ = id;
  }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

// Opens `path` read-only: with MPI-IO on `comm` (collective), or serially when
// comm has one rank (parallel_hdf5.hpp).
hid_t OpenMeshFile(const std::string &path, MPI_Comm comm) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // failures are reported by the callers
  return OpenParallelFile(comm, path, false);
}

// Reads rows [first, first + count) of a [rows][columns] dataset into `values` as
// `memory_type`; collective when the file was opened on several ranks (count may
// be 0 on some).
bool ReadRows(hid_t dataset, hid_t memory_type, int64_t first, int64_t count, void *values) {
  return ReadRows(dataset, memory_type,
                  RowSlab{static_cast<hsize_t>(first), static_cast<hsize_t>(first + count)},
                  values);
}

// Creates and writes a [rows][columns] dataset of `file_type` from `values` (of
// `memory_type`), chunked in blocks of `chunk_rows` whole rows.
bool WriteRows(hid_t file, const char *name, hid_t file_type, hid_t memory_type, hsize_t rows,
               hsize_t columns, hsize_t chunk_rows, const void *values) {
  const hsize_t dims[2] = {rows, columns}, chunk[2] = {std::min(chunk_rows, rows), columns};
  const Handle space(H5Screate_simple(2, dims, nullptr), H5Sclose);
  const Handle create(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
  if (!space.ok() || !create.ok() || H5Pset_chunk(create, 2, chunk) < 0) return false;
  const Handle dataset(H5Dcreate2(file, name, file_type, space, H5P_DEFAULT, create, H5P_DEFAULT),
                       H5Dclose);
  return dataset.ok() && H5Dwrite(dataset, memory_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values) >= 0;
}

// A string attribute of `object` (fixed or variable length); false when absent
// or not a string.
bool ReadStringAttribute(hid_t object, const char *name, std::string *value) {
  if (H5Aexists(object, name) <= 0) return false;
  const Handle attribute(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  const Handle type(H5Aget_type(attribute), H5Tclose);
  if (!type.ok() || H5Tget_class(type) != H5T_STRING) return false;
  const Handle space(H5Aget_space(attribute), H5Sclose);
  if (H5Sget_simple_extent_npoints(space) != 1) return false;
  if (H5Tis_variable_str(type) > 0) {
    char *text = nullptr;
    if (H5Aread(attribute, type, &text) < 0 || text == nullptr) return false;
    *value = text;
    H5free_memory(text);
    return true;
  }
  std::vector<char> text(H5Tget_size(type) + 1, '\0');
  if (H5Aread(attribute, type, text.data()) < 0) return false;
  *value = text.data();
  return true;
}

// Rows of a dataset that must be [rows][columns] of an 8-byte float (`integer`
// false) or signed integer; empty when it is, otherwise what it is not.
std::string CheckShape(hid_t dataset, const char *name, hsize_t columns, bool integer,
                       int64_t *rows) {
  const std::string expected = std::string("/") + name + " must be [n][" + std::to_string(columns) +
                               "] " + (integer ? "int64" : "float64");
  const Handle type(H5Dget_type(dataset), H5Tclose);
  const Handle space(H5Dget_space(dataset), H5Sclose);
  if (!type.ok() || !space.ok()) return "unreadable dataset /" + std::string(name);
  const bool type_ok = integer ? H5Tget_class(type) == H5T_INTEGER && H5Tget_size(type) == 8 &&
                                     H5Tget_sign(type) == H5T_SGN_2
                               : H5Tget_class(type) == H5T_FLOAT && H5Tget_size(type) == 8;
  if (!type_ok) return expected + " (wrong data type)";
  hsize_t dims[2] = {0, 0};
  if (H5Sget_simple_extent_ndims(space) != 2 || H5Sget_simple_extent_dims(space, dims, nullptr) < 0)
    return expected + " (not two-dimensional)";
  if (dims[1] != columns) return expected + " (has " + std::to_string(dims[1]) + " columns)";
  *rows = static_cast<int64_t>(dims[0]);
  return "";
}

// ------------------------------------------------------------ shared checks

// The open file's format attributes and its two datasets, checked; empty when
// the file is a readable softbody mesh, otherwise what is wrong.
struct MeshFile {
  Handle vertices{-1, H5Dclose};
  Handle tets{-1, H5Dclose};
  int64_t num_vertices = 0, num_tets = 0;
};

std::string OpenDataset(hid_t file, const char *name, Handle *dataset) {
  if (!LinkExists(file, name)) return "no dataset /" + std::string(name);
  dataset->reset(H5Dopen2(file, name, H5P_DEFAULT));
  return dataset->ok() ? "" : "unreadable dataset /" + std::string(name);
}

std::string CheckMeshFile(hid_t file, MeshFile *mesh) {
  std::string format;
  if (!ReadStringAttribute(file, "format", &format) || format != kMeshFormatName)
    return std::string("not a softbody mesh file (no root attribute format = \"") +
           kMeshFormatName + "\"; write one with softbody-convert)";
  int64_t version = 0;
  if (!GetAttribute(file, "version", &version))
    return "no root attribute version (the format version)";
  if (version != kMeshFormatVersion)
    return "format version " + std::to_string(version) + " is not supported (this softbody reads " +
           std::to_string(kMeshFormatVersion) + ")";
  for (auto [name, dataset] : {std::pair{"vertices", &mesh->vertices}, {"tets", &mesh->tets}}) {
    const std::string error = OpenDataset(file, name, dataset);
    if (!error.empty()) return error;
  }
  std::string error =
      CheckShape(mesh->vertices, "vertices", kVertexColumns, false, &mesh->num_vertices);
  if (error.empty()) error = CheckShape(mesh->tets, "tets", kTetColumns, true, &mesh->num_tets);
  if (!error.empty()) return error;
  if (mesh->num_vertices == 0) return "no vertices in the mesh";
  if (mesh->num_tets == 0) return "no tetrahedra in the mesh";
  return "";
}

// Empty when every index of `tets` (rows of global row first_row + r) is in
// [0, num_vertices), otherwise the first one that is not.
template <class Tets>
std::string CheckIndices(const Tets &tets, int64_t first_row, int64_t num_vertices) {
  for (Eigen::Index t = 0; t < tets.rows(); ++t)
    for (int a = 0; a < kTetColumns; ++a)
      if (tets(t, a) < 0 || tets(t, a) >= num_vertices)
        return "tetrahedron " + std::to_string(first_row + t + 1) + ": vertex index " +
               std::to_string(tets(t, a)) + " out of range 0.." + std::to_string(num_vertices - 1);
  return "";
}

// Empty when no tet of `mesh` is degenerate, otherwise the first that is.
std::string FirstDegenerateTet(const TetMesh &mesh) {
  for (int32_t t = 0; t < mesh.num_tets(); ++t) {
    TetPositions X;
    for (int a = 0; a < kTetColumns; ++a) X.row(a) = mesh.vertices.row(mesh.tets(t, a));
    if (IsDegenerateTet(X))
      return "tetrahedron " + std::to_string(t + 1) + " is degenerate (zero volume)";
  }
  return "";
}

// Collective. The message of the lowest rank that has one, on every rank (empty
// on all when no rank has one).
PetscErrorCode AgreeOnError(MPI_Comm comm, std::string *error) {
  PetscFunctionBeginUser;
  PetscMPIInt rank = 0;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  const int mine = error->empty() ? INT_MAX : rank;
  int first = INT_MAX;
  PetscCallMPI(MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, comm));
  if (first == INT_MAX) PetscFunctionReturn(PETSC_SUCCESS);
  int length = static_cast<int>(error->size());
  PetscCallMPI(MPI_Bcast(&length, 1, MPI_INT, first, comm));
  error->resize(static_cast<size_t>(length));
  PetscCallMPI(MPI_Bcast(error->data(), length, MPI_CHAR, first, comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Fails on every rank with "path: <error>" when any rank has an error.
#define SOFTBODY_AGREE_OR_FAIL(comm, path, error)                                                 \
  do {                                                                                            \
    PetscCall(AgreeOnError(comm, &(error)));                                                      \
    PetscCheck((error).empty(), comm, PETSC_ERR_USER_INPUT, "%s", Where(path, 0, error).c_str()); \
  } while (0)

// ------------------------------------------------------------------ writing

void CheckMeshForWriting(const std::string &path, const TetMesh &mesh) {
  if (mesh.num_vertices() == 0 || mesh.num_tets() == 0)
    throw InputError(Where(path, 0, "cannot write an empty mesh"));
  std::string error = CheckIndices(mesh.tets, 0, mesh.num_vertices());
  if (error.empty()) error = FirstDegenerateTet(mesh);
  if (!error.empty()) throw InputError(Where(path, 0, "cannot write: " + error));
}

// Rows per chunk of a dataset of `rows` rows of `row_bytes`: ChunkRows's (at most
// kMaxChunkBytes), capped by `cap` when > 0.
hsize_t MeshChunkRows(hsize_t rows, hsize_t row_bytes, hsize_t cap) {
  const hsize_t chunk = ChunkRows(rows, row_bytes);
  return cap > 0 ? std::min(chunk, cap) : chunk;
}

bool WriteMeshFile(const std::string &path, const TetMesh &mesh, const std::string &source,
                   size_t chunk_rows) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // failures are reported by the caller
  const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  if (file < 0) return false;
  const bool ok =
      WriteRows(file, "vertices", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, mesh.vertices.rows(),
                kVertexColumns,
                MeshChunkRows(mesh.vertices.rows(), kVertexColumns * sizeof(double), chunk_rows),
                mesh.vertices.data()) &&
      WriteRows(file, "tets", H5T_STD_I64LE, H5T_NATIVE_INT32, mesh.tets.rows(), kTetColumns,
                MeshChunkRows(mesh.tets.rows(), kTetColumns * sizeof(int64_t), chunk_rows),
                mesh.tets.data()) &&
      SetAttribute(file, "format", std::string(kMeshFormatName)) &&
      SetAttribute(file, "version", kMeshFormatVersion) && SetAttribute(file, "source", source);
  return H5Fclose(file) >= 0 && ok;
}

}  // namespace

void WriteMeshH5(const std::string &path, const TetMesh &mesh, const std::string &source,
                 size_t chunk_rows) {
  CheckMeshForWriting(path, mesh);
  // Written beside its final name (same file system, so the rename is atomic).
  const std::string partial = path + ".partial-" + std::to_string(getpid());
  if (!WriteMeshFile(partial, mesh, source, chunk_rows)) {
    std::remove(partial.c_str());
    throw InputError(Where(path, 0, "cannot write the mesh file (is its folder writable?)"));
  }
  std::error_code failed;
  fs::rename(partial, path, failed);
  if (failed) {
    std::remove(partial.c_str());
    throw InputError(Where(path, 0, "cannot write the mesh file: " + failed.message()));
  }
}

// ------------------------------------------------------------ serial reader

namespace {

void ReadTets(const std::string &path, const MeshFile &file, TetMesh *mesh) {
  mesh->tets.resize(file.num_tets, kTetColumns);
  Eigen::Matrix<int64_t, Eigen::Dynamic, 4, Eigen::RowMajor> block;
  for (int64_t first = 0; first < file.num_tets; first += kSerialReadRows) {
    const int64_t rows = std::min<int64_t>(kSerialReadRows, file.num_tets - first);
    block.resize(rows, kTetColumns);
    if (!ReadRows(file.tets, H5T_NATIVE_INT64, first, rows, block.data()))
      throw InputError(Where(path, 0, "cannot read /tets"));
    const std::string error = CheckIndices(block, first, file.num_vertices);
    if (!error.empty()) throw InputError(Where(path, 0, error));
    mesh->tets.middleRows(first, rows) = block.cast<int32_t>();
  }
}

}  // namespace

namespace {

// Opens (into *file) and checks a softbody mesh file on this rank alone (throws
// InputError).
void OpenCheckedMeshFile(const std::string &path, Handle *file, MeshFile *mesh_file) {
  if (!fs::exists(path)) throw InputError(Where(path, 0, "no such file"));
  file->reset(OpenMeshFile(path, PETSC_COMM_SELF));
  if (!file->ok()) throw InputError(Where(path, 0, "not an HDF5 file (or unreadable)"));
  const std::string error = CheckMeshFile(*file, mesh_file);
  if (!error.empty()) throw InputError(Where(path, 0, error));
  if (mesh_file->num_vertices > INT32_MAX || mesh_file->num_tets > INT32_MAX)
    throw InputError(Where(path, 0,
                           std::to_string(mesh_file->num_vertices) + " vertices and " +
                               std::to_string(mesh_file->num_tets) +
                               " tets: more than a scene holds (2^31 - 1 each)"));
}

}  // namespace

MeshCounts ReadMeshH5Counts(const std::string &path) {
  Handle file(-1, H5Fclose);
  MeshFile mesh_file;
  OpenCheckedMeshFile(path, &file, &mesh_file);
  return {mesh_file.num_vertices, mesh_file.num_tets};
}

TetMesh ReadMeshH5(const std::string &path) {
  Handle file(-1, H5Fclose);
  MeshFile mesh_file;
  OpenCheckedMeshFile(path, &file, &mesh_file);
  TetMesh mesh;
  mesh.vertices.resize(mesh_file.num_vertices, kVertexColumns);
  if (!ReadRows(mesh_file.vertices, H5T_NATIVE_DOUBLE, 0, mesh_file.num_vertices,
                mesh.vertices.data()))
    throw InputError(Where(path, 0, "cannot read /vertices"));
  ReadTets(path, mesh_file, &mesh);
  const std::string degenerate = FirstDegenerateTet(mesh);
  if (!degenerate.empty()) throw InputError(Where(path, 0, degenerate));
  return mesh;
}

// ---------------------------------------------------------- parallel reader

namespace {

// Collective (rank `rank` of `size`). Reads this rank's rows of both datasets;
// empty error when done.
std::string ReadSlabs(const MeshFile &file, int rank, int size, MeshSlabs *slabs) {
  slabs->num_vertices = file.num_vertices;
  slabs->num_tets = file.num_tets;
  slabs->first_vertex = EvenShareBegin(file.num_vertices, size, rank);
  slabs->first_tet = EvenShareBegin(file.num_tets, size, rank);
  const int64_t vertex_rows =
      EvenShareBegin(file.num_vertices, size, rank + 1) - slabs->first_vertex;
  const int64_t tet_rows = EvenShareBegin(file.num_tets, size, rank + 1) - slabs->first_tet;
  slabs->vertices.resize(vertex_rows, kVertexColumns);
  slabs->tets.resize(tet_rows, kTetColumns);
  // Both reads are collective: every rank makes both calls, whatever the first gave.
  const bool vertices_read = ReadRows(file.vertices, H5T_NATIVE_DOUBLE, slabs->first_vertex,
                                      vertex_rows, slabs->vertices.data());
  const bool tets_read =
      ReadRows(file.tets, H5T_NATIVE_INT64, slabs->first_tet, tet_rows, slabs->tets.data());
  if (!vertices_read) return "cannot read /vertices";
  if (!tets_read) return "cannot read /tets";
  return CheckIndices(slabs->tets, slabs->first_tet, file.num_vertices);
}

}  // namespace

PetscErrorCode ReadMeshSlabs(MPI_Comm comm, const std::string &path, MeshSlabs *slabs) {
  PetscFunctionBeginUser;
  std::string error = fs::exists(path) ? "" : "no such file";
  SOFTBODY_AGREE_OR_FAIL(comm, path, error);
  const Handle file(OpenMeshFile(path, comm), H5Fclose);
  if (!file.ok()) error = "not an HDF5 file (or unreadable)";
  SOFTBODY_AGREE_OR_FAIL(comm, path, error);
  MeshFile mesh_file;
  error = CheckMeshFile(file, &mesh_file);
  SOFTBODY_AGREE_OR_FAIL(comm, path, error);
  PetscMPIInt rank = 0, size = 1;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  error = ReadSlabs(mesh_file, rank, size, slabs);
  SOFTBODY_AGREE_OR_FAIL(comm, path, error);
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CheckTetVolumes(
    MPI_Comm comm, const std::string &path, int64_t first_tet,
    const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> &corners) {
  PetscFunctionBeginUser;
  std::string error;
  for (Eigen::Index t = 0; error.empty() && t < corners.rows() / kTetColumns; ++t) {
    const TetPositions X = corners.middleRows<kTetColumns>(kTetColumns * t);
    if (IsDegenerateTet(X))
      error = "tetrahedron " + std::to_string(first_tet + t + 1) + " is degenerate (zero volume)";
  }
  SOFTBODY_AGREE_OR_FAIL(comm, path, error);
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
