// The softbody HDF5 mesh file (io/mesh_h5.hpp): WriteMeshH5 then ReadMeshH5 (and
// ReadTetMesh of the .h5) give the source reader's mesh bit for bit for every
// source format; a failed write leaves no file; the serial reader rejects bad
// files with one line naming the file. The collective slab reader, at 1, 3 and 4
// ranks, gives each rank rows [N r / P, N (r + 1) / P) of the serial
// reader's mesh of the source .mesh, the slabs tile the mesh, ranks with no rows
// get empty slabs, and on bad input every rank fails with the same message.
// Runs on ranks: 1 3 4
#include <gtest/gtest.h>
#include <hdf5.h>
#include <petscsys.h>

#include <cstring>
#include <fstream>
#include <functional>

#include "input_checks.hpp"
#include "io/mesh_h5.hpp"
#include "io/mesh_io.hpp"
#include "petsc_environment.hpp"

using namespace softbody;
using namespace softbody::testing;

namespace {

void ExpectSameMesh(const TetMesh &ours, const TetMesh &reference) {
  ASSERT_EQ(ours.vertices.rows(), reference.vertices.rows());
  ASSERT_EQ(ours.tets.rows(), reference.tets.rows());
  EXPECT_EQ(std::memcmp(ours.vertices.data(), reference.vertices.data(),
                        sizeof(double) * reference.vertices.size()),
            0)
      << "vertices differ";
  EXPECT_TRUE(ours.tets == reference.tets) << "tets differ";
}

// ------------------------------------------------------------ serial tests

using MeshH5Test = TempFolderTest;

TEST_F(MeshH5Test, RoundTripOfEverySourceFormatIsBitForBit) {
  for (const char *source : {"meshes/cube.mesh", "meshes/cube-4.1.msh", "meshes/cube-2.2.msh",
                             "meshes/torus.off", "meshes/box_quads.off"}) {
    SCOPED_TRACE(source);
    const TetMesh reference = ReadTetMesh(source);
    const std::string path = (folder_ / "mesh.h5").string();
    WriteMeshH5(path, reference, source);
    ExpectSameMesh(ReadMeshH5(path), reference);
    ExpectSameMesh(ReadTetMesh(path), reference);  // the scene's dispatch by extension
  }
}

TEST_F(MeshH5Test, ManySmallChunksReadBack) {
  const TetMesh reference = ReadTetMesh("meshes/torus.off");
  const std::string path = (folder_ / "chunked.h5").string();
  WriteMeshH5(path, reference, "torus.off", 7);
  ExpectSameMesh(ReadMeshH5(path), reference);
}

TEST_F(MeshH5Test, DatasetsAreChunkedWithinTheBoundAndAttributesIdentifyTheFile) {
  const std::string path = (folder_ / "mesh.h5").string();
  WriteMeshH5(path, ReadTetMesh("meshes/torus.off"), "meshes/torus.off");
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  for (const char *name : {"vertices", "tets"}) {
    const hid_t dataset = H5Dopen2(file, name, H5P_DEFAULT);
    const hid_t create = H5Dget_create_plist(dataset);
    hsize_t chunk[2] = {0, 0};
    ASSERT_EQ(H5Pget_chunk(create, 2, chunk), 2) << name;
    EXPECT_LE(chunk[0] * chunk[1] * 8, kMeshChunkBytes) << name;
    H5Pclose(create);
    H5Dclose(dataset);
  }
  const hid_t version = H5Aopen(file, "version", H5P_DEFAULT);
  int64_t value = 0;
  H5Aread(version, H5T_NATIVE_INT64, &value);
  EXPECT_EQ(value, kMeshFormatVersion);
  H5Aclose(version);
  EXPECT_GT(H5Aexists(file, "source"), 0);
  H5Fclose(file);
}

TEST_F(MeshH5Test, FailedWriteLeavesNoFile) {
  const TetMesh mesh = ReadTetMesh("meshes/cube.mesh");
  const std::string path = (folder_ / "missing_folder" / "mesh.h5").string();
  EXPECT_CONTAINS(InputErrorOf([&] { WriteMeshH5(path, mesh, "cube.mesh"); }), path + ": ");
  EXPECT_FALSE(fs::exists(path));
  // A mesh the writer refuses (index out of range) leaves neither file nor partial file.
  TetMesh bad = mesh;
  bad.tets(5, 2) = 8;
  const std::string refused = (folder_ / "refused.h5").string();
  EXPECT_CONTAINS(InputErrorOf([&] { WriteMeshH5(refused, bad, "cube.mesh"); }),
                  refused + ": cannot write: tetrahedron 6: vertex index 8 out of range 0..7");
  EXPECT_TRUE(fs::is_empty(folder_));
}

// What a hand-made file holds: datasets of any type and shape, attributes.
struct RawMesh {
  hid_t vertex_type = H5T_IEEE_F64LE;
  std::vector<hsize_t> vertex_dims = {4, 3};
  hid_t tet_type = H5T_STD_I64LE;
  std::vector<hsize_t> tet_dims = {1, 4};
  std::vector<double> vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  std::vector<int64_t> tets = {0, 1, 2, 3};
  const char *format = kMeshFormatName;  // nullptr: no attribute
  int64_t version = kMeshFormatVersion;
  bool write_values = true;  // false: datasets left unwritten (chunked, fill value)
};

hid_t CreateRawDataset(hid_t file, const char *name, hid_t type, const std::vector<hsize_t> &dims) {
  std::vector<hsize_t> max_dims = dims;
  max_dims[0] = H5S_UNLIMITED;  // so that a dataset may have no rows
  const hid_t space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), max_dims.data());
  const hid_t create = H5Pcreate(H5P_DATASET_CREATE);
  std::vector<hsize_t> chunk(dims.size(), 1);
  chunk.back() = dims.back();
  H5Pset_chunk(create, static_cast<int>(chunk.size()), chunk.data());
  const hid_t dataset = H5Dcreate2(file, name, type, space, H5P_DEFAULT, create, H5P_DEFAULT);
  H5Pclose(create);
  H5Sclose(space);
  return dataset;
}

void WriteRawMesh(const std::string &path, const RawMesh &raw) {
  const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  const hid_t vertices = CreateRawDataset(file, "vertices", raw.vertex_type, raw.vertex_dims);
  const hid_t tets = CreateRawDataset(file, "tets", raw.tet_type, raw.tet_dims);
  if (raw.write_values) {
    H5Dwrite(vertices, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, raw.vertices.data());
    H5Dwrite(tets, H5T_NATIVE_INT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, raw.tets.data());
  }
  H5Dclose(vertices);
  H5Dclose(tets);
  const hid_t scalar = H5Screate(H5S_SCALAR);
  if (raw.format) {
    const hid_t string = H5Tcopy(H5T_C_S1);
    H5Tset_size(string, std::strlen(raw.format));
    const hid_t format = H5Acreate2(file, "format", string, scalar, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(format, string, raw.format);
    H5Aclose(format);
    H5Tclose(string);
  }
  const hid_t version =
      H5Acreate2(file, "version", H5T_STD_I64LE, scalar, H5P_DEFAULT, H5P_DEFAULT);
  H5Awrite(version, H5T_NATIVE_INT64, &raw.version);
  H5Aclose(version);
  H5Sclose(scalar);
  H5Fclose(file);
}

// The bad files both readers must reject, each with the words its error must hold.
std::vector<std::pair<RawMesh, std::string>> BadFiles() {
  std::vector<std::pair<RawMesh, std::string>> bad(9);
  bad[0].first.format = nullptr;
  bad[0].second = "not a softbody mesh file";
  bad[1].first.format = "another-format";
  bad[1].second = "not a softbody mesh file";
  bad[2].first.version = 2;
  bad[2].second = "format version 2 is not supported";
  bad[3].first.vertex_type = H5T_IEEE_F32LE;
  bad[3].second = "/vertices must be [n][3] float64 (wrong data type)";
  bad[4].first.tet_type = H5T_STD_I32LE;
  bad[4].second = "/tets must be [n][4] int64 (wrong data type)";
  bad[5].first.vertex_dims = {6, 2};
  bad[5].second = "/vertices must be [n][3] float64 (has 2 columns)";
  bad[6].first.tet_dims = {4};
  bad[6].second = "/tets must be [n][4] int64 (not two-dimensional)";
  bad[7].first.tets = {0, 1, 2, 4};
  bad[7].second = "tetrahedron 1: vertex index 4 out of range 0..3";
  bad[8].first.tet_dims = {0, 4};
  bad[8].first.write_values = false;
  bad[8].second = "no tetrahedra in the mesh";
  return bad;
}

TEST_F(MeshH5Test, SerialReaderRejectsBadFilesInOneLineNamingTheFile) {
  const std::string path = (folder_ / "bad.h5").string();
  for (const auto &[raw, message] : BadFiles()) {
    SCOPED_TRACE(message);
    WriteRawMesh(path, raw);
    EXPECT_CONTAINS(InputErrorOf([&] { ReadMeshH5(path); }), path + ": " + message);
  }
  RawMesh degenerate;
  degenerate.vertices[11] = 0;  // the fourth corner in the plane of the other three
  WriteRawMesh(path, degenerate);
  EXPECT_CONTAINS(InputErrorOf([&] { ReadMeshH5(path); }), path + ": tetrahedron 1 is degenerate");
  const std::string text = Write("text.h5", "not HDF5\n");
  EXPECT_CONTAINS(InputErrorOf([&] { ReadMeshH5(text); }), text + ": not an HDF5 file");
  const std::string missing = (folder_ / "missing.h5").string();
  EXPECT_CONTAINS(InputErrorOf([&] { ReadMeshH5(missing); }), missing + ": no such file");
}

TEST_F(MeshH5Test, SerialReaderRefusesCountsBeyond32Bits) {
  RawMesh huge;  // 2^31 tets that take no disk space: chunks never written
  huge.tet_dims = {hsize_t(1) << 31, 4};
  huge.write_values = false;
  const std::string path = (folder_ / "huge.h5").string();
  WriteRawMesh(path, huge);
  EXPECT_CONTAINS(InputErrorOf([&] { ReadMeshH5(path); }),
                  path + ": 4 vertices and 2147483648 tets: more than a scene holds");
}

// ------------------------------------------------------ collective tests

// A folder shared by the ranks of PETSC_COMM_WORLD (rank 0 names, makes and
// removes it), holding the files rank 0 writes.
class SlabTest : public ::testing::Test {
 protected:
  void SetUp() override {
    MPI_Comm_rank(PETSC_COMM_WORLD, &rank_);
    MPI_Comm_size(PETSC_COMM_WORLD, &size_);
    char name[PETSC_MAX_PATH_LEN] = "";
    if (rank_ == 0) {
      std::snprintf(name, sizeof(name), "%s/softbody_test_slabs_%d_%u",
                    fs::temp_directory_path().c_str(), static_cast<int>(getpid()),
                    std::random_device()());
      fs::create_directories(name);
    }
    MPI_Bcast(name, sizeof(name), MPI_CHAR, 0, PETSC_COMM_WORLD);
    folder_ = name;
  }
  void TearDown() override {
    MPI_Barrier(PETSC_COMM_WORLD);
    if (rank_ == 0) fs::remove_all(folder_);
  }
  // Collective. `write` run by rank 0 on folder/name; returns the path.
  std::string WrittenByRankZero(const std::string &name,
                                const std::function<void(const std::string &)> &write) const {
    const std::string path = (folder_ / name).string();
    if (rank_ == 0) write(path);
    MPI_Barrier(PETSC_COMM_WORLD);
    return path;
  }
  // Collective. The message of the error ReadMeshSlabs gives on this rank ("" when none).
  std::string SlabErrorOf(const std::string &path) const {
    PetscCallAbort(PETSC_COMM_WORLD, PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
    MeshSlabs slabs;
    const PetscErrorCode code = ReadMeshSlabs(PETSC_COMM_WORLD, path, &slabs);
    PetscCallAbort(PETSC_COMM_WORLD, PetscPopErrorHandler());
    if (code == 0) return "";
    EXPECT_EQ(code, PETSC_ERR_USER_INPUT);
    char *message = nullptr;
    PetscErrorMessage(code, nullptr, &message);
    return message ? message : "(no message)";
  }

  fs::path folder_;
  int rank_ = 0, size_ = 1;
};

int64_t BlockStart(int64_t n, int rank, int size) {
  return n * rank / size;
}

// This rank's slabs hold rows [N r / P, N (r + 1) / P) of the reference, and the
// row counts of all ranks sum to the whole mesh.
void ExpectSlabsOf(const MeshSlabs &slabs, const TetMesh &reference, int rank, int size) {
  const int64_t V = reference.vertices.rows(), T = reference.tets.rows();
  // The collective part first: a failed check below must not leave a rank behind.
  int64_t rows[2] = {slabs.vertices.rows(), slabs.tets.rows()}, total[2] = {0, 0};
  MPI_Allreduce(rows, total, 2, MPI_INT64_T, MPI_SUM, PETSC_COMM_WORLD);
  EXPECT_EQ(total[0], V);
  EXPECT_EQ(total[1], T);
  EXPECT_EQ(slabs.num_vertices, V);
  EXPECT_EQ(slabs.num_tets, T);
  EXPECT_EQ(slabs.first_vertex, BlockStart(V, rank, size));
  EXPECT_EQ(slabs.first_tet, BlockStart(T, rank, size));
  const int64_t vertex_rows = BlockStart(V, rank + 1, size) - BlockStart(V, rank, size);
  const int64_t tet_rows = BlockStart(T, rank + 1, size) - BlockStart(T, rank, size);
  EXPECT_EQ(slabs.vertices.rows(), vertex_rows);
  EXPECT_EQ(slabs.tets.rows(), tet_rows);
  if (slabs.vertices.rows() == vertex_rows)
    EXPECT_TRUE(slabs.vertices ==
                reference.vertices.middleRows(BlockStart(V, rank, size), vertex_rows))
        << "vertex slab of rank " << rank;
  if (slabs.tets.rows() == tet_rows)
    EXPECT_TRUE(slabs.tets ==
                reference.tets.middleRows(BlockStart(T, rank, size), tet_rows).cast<int64_t>())
        << "tet slab of rank " << rank;
}

// A structured box of n^3 cells, 6 tets each, as MEDIT text.
void WriteBoxMedit(const std::string &path, int n) {
  std::ofstream out(path);
  out << "MeshVersionFormatted 2\nDimension 3\nVertices\n" << (n + 1) * (n + 1) * (n + 1) << "\n";
  const auto index = [n](int i, int j, int k) { return 1 + i + (n + 1) * (j + (n + 1) * k); };
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) out << 0.1 * i << " " << 0.2 * j << " " << 0.3 * k << " 0\n";
  out << "Tetrahedra\n" << 6 * n * n * n << "\n";
  const int paths[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (const auto &path_of : paths) {
          int corner[3] = {i, j, k};
          out << index(i, j, k);
          for (int s = 0; s < 3; ++s) {
            ++corner[path_of[s]];
            out << " " << index(corner[0], corner[1], corner[2]);
          }
          out << " 0\n";
        }
  out << "End\n";
}

TEST_F(SlabTest, SlabsAreTheSerialReadersRowsOfTheSourceMesh) {
  const std::string source = WrittenByRankZero("box.mesh", [](const std::string &path) {
    WriteBoxMedit(path, 5);  // 216 vertices, 750 tets
  });
  const TetMesh reference = ReadMedit(source);
  for (size_t chunk_rows : {size_t(0), size_t(7)}) {  // one chunk per dataset; many
    SCOPED_TRACE(chunk_rows);
    const std::string path = WrittenByRankZero("box.h5", [&](const std::string &path) {
      WriteMeshH5(path, ReadMedit(source), source, chunk_rows);
    });
    MeshSlabs slabs;
    ASSERT_EQ(ReadMeshSlabs(PETSC_COMM_WORLD, path, &slabs), 0);
    ExpectSlabsOf(slabs, reference, rank_, size_);
  }
}

TEST_F(SlabTest, RanksWithoutRowsGetEmptySlabs) {
  const TetMesh reference = ReadMedit("bad_input/tet.mesh");  // 4 vertices, 1 tet
  const std::string path = WrittenByRankZero(
      "tet.h5", [&](const std::string &path) { WriteMeshH5(path, reference, "tet.mesh"); });
  MeshSlabs slabs;
  ASSERT_EQ(ReadMeshSlabs(PETSC_COMM_WORLD, path, &slabs), 0);
  ExpectSlabsOf(slabs, reference, rank_, size_);
  EXPECT_EQ(slabs.tets.rows(), rank_ == size_ - 1 ? 1 : 0);
}

TEST_F(SlabTest, BadFilesFailOnEveryRankWithOneLineNamingTheFile) {
  for (const auto &[raw, message] : BadFiles()) {
    SCOPED_TRACE(message);
    const std::string path =
        WrittenByRankZero("bad.h5", [&](const std::string &path) { WriteRawMesh(path, raw); });
    EXPECT_CONTAINS(SlabErrorOf(path), path + ": " + message);
  }
  // An index out of range in the last tet of a larger mesh: only the last rank
  // reads it, every rank reports it.
  RawMesh last_bad;
  last_bad.tet_dims = {5, 4};
  last_bad.tets = {0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, -1};
  const std::string bad_index =
      WrittenByRankZero("last.h5", [&](const std::string &path) { WriteRawMesh(path, last_bad); });
  EXPECT_CONTAINS(SlabErrorOf(bad_index),
                  bad_index + ": tetrahedron 5: vertex index -1 out of range 0..3");
  const std::string text = WrittenByRankZero(
      "text.h5", [](const std::string &path) { std::ofstream(path) << "not HDF5\n"; });
  EXPECT_CONTAINS(SlabErrorOf(text), text + ": not an HDF5 file");
  const std::string missing = (folder_ / "missing.h5").string();
  EXPECT_CONTAINS(SlabErrorOf(missing), missing + ": no such file");
}

TEST_F(SlabTest, DegenerateTetOfTheLastRankFailsEveryRank) {
  // Each rank's corners: one regular tet per rank, the last rank's flattened.
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> corners(4, 3);
  corners << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  EXPECT_EQ(CheckTetVolumes(PETSC_COMM_WORLD, "box.h5", rank_, corners), 0);
  if (rank_ == size_ - 1) corners(3, 2) = 0;
  PetscCallAbort(PETSC_COMM_WORLD, PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
  const PetscErrorCode code = CheckTetVolumes(PETSC_COMM_WORLD, "box.h5", rank_, corners);
  PetscCallAbort(PETSC_COMM_WORLD, PetscPopErrorHandler());
  ASSERT_EQ(code, PETSC_ERR_USER_INPUT);
  char *message = nullptr;
  PetscErrorMessage(code, nullptr, &message);
  EXPECT_CONTAINS(std::string(message ? message : ""),
                  "box.h5: tetrahedron " + std::to_string(size_) + " is degenerate");
}

}  // namespace
