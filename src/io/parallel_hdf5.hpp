// Parallel HDF5 (MPI-IO) primitives: files opened by every rank of a
// communicator, datasets created together, and each rank reading or writing its
// own slab of rows.
//
// A "row" is one index of a dataset's first dimension ([rows][columns...]);
// frame datasets are [frames][rows][columns...] and a frame's rows are addressed
// the same way. Rows are in natural order; rank r of P usually holds the even
// slab EvenSlab(rows, r, P). All transfers are collective hyperslab transfers
// (H5FD_MPIO_COLLECTIVE): every rank of the file's communicator calls them, a
// rank that owns no rows with an empty slab. Metadata calls (create, extend,
// attributes: hdf5_io.hpp) are collective too and need equal arguments on every
// rank. Memory types are HDF5 native types (H5T_NATIVE_DOUBLE, H5T_NATIVE_INT32,
// H5T_NATIVE_INT64, ...), converted to and from the dataset's file type.
//
// Nothing here prints: functions return false (or a negative id) on failure, on
// every rank when the failure is in metadata (which every rank sees alike); the
// callers agree on success (an MPI reduction) and report one line.
#pragma once

#include <hdf5.h>
#include <mpi.h>

#include <cstdint>
#include <string>
#include <vector>

namespace softbody {

// Rows [begin, end) of a dataset (begin == end: none).
struct RowSlab {
  hsize_t begin = 0, end = 0;
  hsize_t count() const { return end - begin; }
};

// Not collective. Rank `rank` of `size`'s even share of `rows` rows:
// [rows rank / size, rows (rank + 1) / size).
RowSlab EvenSlab(hsize_t rows, int rank, int size);

// Chunks are kept at most this large: several rows per chunk amortise the
// chunk index, and HDF5 refuses chunks of 4 GiB or more (one chunk per frame of
// a 2e8-vertex mesh would be 4.8 GB). 1 MiB is also HDF5's default chunk cache.
constexpr hsize_t kMaxChunkBytes = hsize_t{1} << 20;

// Frames per chunk of a series of scalars (time, energies): appending a frame
// rarely allocates, and a short run's file stays small.
constexpr hsize_t kScalarFramesPerChunk = 1024;

// Not collective. Rows per chunk for rows of `row_bytes` bytes: as many as fit
// in kMaxChunkBytes (at least 1), at most `rows` (at least 1).
hsize_t ChunkRows(hsize_t rows, hsize_t row_bytes);

// Collective. Creates (truncating) or opens `path` with the MPI-IO driver on
// every rank of comm; the caller closes it with H5Fclose (collective). On a
// single rank the file is opened with HDF5's default POSIX driver instead: the
// same file, and a flush that does not sync to disk (MPI-IO's flush calls
// MPI_File_sync, about 4 ms per flush here, measured in docs/long-runs.md).
hid_t CreateParallelFile(MPI_Comm comm, const std::string &path);
hid_t OpenParallelFile(MPI_Comm comm, const std::string &path, bool writable);

// Collective. A dataset [dims[0]][dims[1]...] of file type `type`. Fixed size
// (contiguous) unless `extendible_rows`: then its row count may change
// (ExtendRows) and it is chunked by ChunkRows rows. Caller closes (H5Dclose).
hid_t CreateRowDataset(hid_t location, const char *name, hid_t type,
                       const std::vector<hsize_t> &dims, bool extendible_rows);

// Collective. An extendible dataset of frames [0][frame_dims...] of doubles:
// chunks of one frame and ChunkRows rows of it ([1][rows][frame_dims[1]...]),
// or of kScalarFramesPerChunk frames for a series of scalars (frame_dims empty).
// Caller closes (H5Dclose).
hid_t CreateFrameDataset(hid_t location, const char *name, const std::vector<hsize_t> &frame_dims);

// Collective. The dataset's first dimension becomes `rows` (equal on every rank).
bool ExtendRows(hid_t dataset, hsize_t rows);

// Not collective. The dataset's current dimensions (empty on failure).
std::vector<hsize_t> DatasetDims(hid_t dataset);

// Collective. Writes / reads rows `slab` of `dataset` (all columns) from / into
// `values` (slab.count() x columns values of `memory_type`, row-major).
bool WriteRows(hid_t dataset, hid_t memory_type, RowSlab slab, const void *values);
bool ReadRows(hid_t dataset, hid_t memory_type, RowSlab slab, void *values);

// Collective. The same for rows `slab` of frame `frame` of a frame dataset
// ([frames][rows][columns...]). Writing first extends the dataset to frame + 1
// frames when it is shorter (equal `frame` on every rank).
bool WriteFrameRows(hid_t dataset, hsize_t frame, hid_t memory_type, RowSlab slab,
                    const void *values);
bool ReadFrameRows(hid_t dataset, hsize_t frame, hid_t memory_type, RowSlab slab, void *values);

// Collective. Scalar frame `frame` of a series of scalars ([frames]): the one
// rank with `writer` true (e.g. rank 0) writes `value`, after every rank has
// extended the series when needed; every rank reads it.
bool WriteScalarFrame(hid_t dataset, hsize_t frame, double value, bool writer);
bool ReadScalarFrame(hid_t dataset, hsize_t frame, double *value);

}  // namespace softbody
