// The parallel HDF5 primitives (src/io/parallel_hdf5.hpp) on one rank, against
// arithmetic and against what was written: even slabs cover the rows exactly
// once; chunks stay within kMaxChunkBytes; rows written slab by slab (empty
// slabs included, in any order) read back equal, whole and by slab; frame
// datasets grow frame by frame; int32 and int64 memory types convert. (One rank
// opens the file with HDF5's POSIX driver; the MPI-IO path at 2 and 3 ranks is
// tests/regression/test_parallel_output.py's.)
#include <gtest/gtest.h>
#include <petscsys.h>

#include <filesystem>
#include <numeric>
#include <vector>

#include "io/parallel_hdf5.hpp"

namespace softbody {
namespace {

class PetscEnvironment : public ::testing::Environment {
 public:
  void SetUp() override { PetscInitializeNoArguments(); }
  void TearDown() override { PetscFinalize(); }
};
const auto *const kPetsc = ::testing::AddGlobalTestEnvironment(new PetscEnvironment);

std::string TemporaryFile(const char *name) {
  return (std::filesystem::temp_directory_path() / name).string();
}

TEST(EvenSlab, CoversEveryRowOnceInRankOrder) {
  for (hsize_t rows : {hsize_t{0}, hsize_t{1}, hsize_t{7}, hsize_t{1000003}})
    for (int size : {1, 2, 3, 16, 1000}) {
      hsize_t next = 0;
      for (int rank = 0; rank < size; ++rank) {
        const RowSlab slab = EvenSlab(rows, rank, size);
        EXPECT_EQ(slab.begin, next);
        EXPECT_LE(slab.count(), rows / size + 1);
        next = slab.end;
      }
      EXPECT_EQ(next, rows);
    }
  // Far beyond 32 bits, without overflow of rows * rank.
  const hsize_t huge = hsize_t{1} << 62;
  EXPECT_EQ(EvenSlab(huge, 3, 4).begin, huge / 4 * 3);
  EXPECT_EQ(EvenSlab(huge, 3, 4).end, huge);
}

TEST(ChunkRows, BoundedBytesAtLeastOneRowAtMostAll) {
  EXPECT_EQ(ChunkRows(10, 24), 10u);
  EXPECT_EQ(ChunkRows(0, 24), 1u);
  EXPECT_EQ(ChunkRows(100000000, 24), kMaxChunkBytes / 24);
  EXPECT_LE(ChunkRows(100000000, 24) * 24, kMaxChunkBytes);
  EXPECT_EQ(ChunkRows(100, 4 * kMaxChunkBytes), 1u);
}

TEST(ParallelHdf5, RowsWrittenBySlabsReadBack) {
  const std::string path = TemporaryFile("softbody_test_parallel_hdf5.h5");
  const hsize_t rows = 50000;  // more than one chunk of [rows][3] doubles
  std::vector<double> values(3 * rows);
  std::iota(values.begin(), values.end(), 0.5);
  std::vector<int64_t> ids(rows);
  std::iota(ids.begin(), ids.end(), int64_t{1000});
  hid_t file = CreateParallelFile(PETSC_COMM_WORLD, path);
  ASSERT_GE(file, 0);
  const hid_t table = CreateRowDataset(file, "table", H5T_NATIVE_DOUBLE, {rows, 3}, true);
  const hid_t id_set = CreateRowDataset(file, "ids", H5T_NATIVE_INT64, {rows}, false);
  const hid_t frames = CreateFrameDataset(file, "frames", {rows, 3});
  ASSERT_TRUE(table >= 0 && id_set >= 0 && frames >= 0);
  // Slabs as three ranks would hold them, written last to first, with an empty one.
  for (int part = 3; part >= 0; --part) {
    const RowSlab slab = part == 3 ? RowSlab{rows, rows} : EvenSlab(rows, part, 3);
    EXPECT_TRUE(WriteRows(table, H5T_NATIVE_DOUBLE, slab, &values[3 * slab.begin]));
    EXPECT_TRUE(WriteRows(id_set, H5T_NATIVE_INT64, slab, ids.data() + slab.begin));
    for (hsize_t frame = 0; frame < 2; ++frame)
      EXPECT_TRUE(WriteFrameRows(frames, frame, H5T_NATIVE_DOUBLE, slab, &values[3 * slab.begin]));
  }
  EXPECT_EQ(DatasetDims(frames), (std::vector<hsize_t>{2, rows, 3}));
  EXPECT_FALSE(WriteRows(table, H5T_NATIVE_DOUBLE, {rows - 1, rows + 1}, values.data()));
  H5Dclose(table);
  H5Dclose(id_set);
  H5Dclose(frames);
  H5Fclose(file);

  file = OpenParallelFile(PETSC_COMM_WORLD, path, false);
  ASSERT_GE(file, 0);
  const hid_t read_table = H5Dopen2(file, "table", H5P_DEFAULT);
  const hid_t read_ids = H5Dopen2(file, "ids", H5P_DEFAULT);
  const hid_t read_frames = H5Dopen2(file, "frames", H5P_DEFAULT);
  std::vector<double> whole(3 * rows), frame(3 * rows);
  EXPECT_TRUE(ReadRows(read_table, H5T_NATIVE_DOUBLE, {0, rows}, whole.data()));
  EXPECT_EQ(whole, values);
  EXPECT_TRUE(ReadFrameRows(read_frames, 1, H5T_NATIVE_DOUBLE, {0, rows}, frame.data()));
  EXPECT_EQ(frame, values);
  std::vector<int64_t> wide(3);
  std::vector<int32_t> narrow(3);  // int64 on disk, int32 in memory
  EXPECT_TRUE(ReadRows(read_ids, H5T_NATIVE_INT64, {7, 10}, wide.data()));
  EXPECT_EQ(wide, std::vector<int64_t>(ids.begin() + 7, ids.begin() + 10));
  EXPECT_TRUE(ReadRows(read_ids, H5T_NATIVE_INT32, {7, 10}, narrow.data()));
  EXPECT_EQ(narrow, (std::vector<int32_t>{1007, 1008, 1009}));
  EXPECT_FALSE(ReadRows(read_ids, H5T_NATIVE_INT64, {rows, rows + 1}, wide.data()));
  EXPECT_TRUE(ReadRows(read_ids, H5T_NATIVE_INT64, {rows, rows}, nullptr));
  H5Dclose(read_table);
  H5Dclose(read_ids);
  H5Dclose(read_frames);
  H5Fclose(file);
  std::filesystem::remove(path);
}

TEST(ParallelHdf5, ScalarSeriesGrowsByFrames) {
  const std::string path = TemporaryFile("softbody_test_parallel_hdf5_series.h5");
  const hid_t file = CreateParallelFile(PETSC_COMM_WORLD, path);
  ASSERT_GE(file, 0);
  const hid_t series = CreateFrameDataset(file, "time", {});
  for (hsize_t f = 0; f < 5; ++f) EXPECT_TRUE(WriteScalarFrame(series, f, 0.25 * f, true));
  EXPECT_EQ(DatasetDims(series), std::vector<hsize_t>{5});
  double value = -1;
  EXPECT_TRUE(ReadScalarFrame(series, 3, &value));
  EXPECT_EQ(value, 0.75);
  EXPECT_TRUE(ExtendRows(series, 2));
  EXPECT_FALSE(ReadScalarFrame(series, 3, &value));
  H5Dclose(series);
  H5Fclose(file);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace softbody
