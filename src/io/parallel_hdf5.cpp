#include "io/parallel_hdf5.hpp"

#include "common/even_share.hpp"

#include <algorithm>

namespace softbody {

RowSlab EvenSlab(hsize_t rows, int rank, int size) {
  const auto share = [&](int r) {
    return static_cast<hsize_t>(EvenShareBegin(static_cast<int64_t>(rows), size, r));
  };
  return {share(rank), share(rank + 1)};
}

hsize_t ChunkRows(hsize_t rows, hsize_t row_bytes) {
  const hsize_t fit = std::max<hsize_t>(1, kMaxChunkBytes / std::max<hsize_t>(1, row_bytes));
  return std::max<hsize_t>(1, std::min(rows, fit));
}

namespace {

// File access through MPI-IO on every rank of comm, or HDF5's default POSIX
// driver on a single rank (-1 on failure). MPI_COMM_SELF makes no MPI call, so the
// serial readers (ReadMeshH5) work where MPI is not initialised (the fuzzers).
hid_t MpioAccess(MPI_Comm comm) {
  const hid_t access = H5Pcreate(H5P_FILE_ACCESS);
  if (access < 0 || comm == MPI_COMM_SELF) return access;
  int size = 1;
  if (MPI_Comm_size(comm, &size) != MPI_SUCCESS) {
    H5Pclose(access);
    return -1;
  }
  if (size > 1 && H5Pset_fapl_mpio(access, comm, MPI_INFO_NULL) < 0) {
    H5Pclose(access);
    return -1;
  }
  return access;
}

// Not collective. Whether `object`'s file was opened with MPI-IO (a single
// rank's file was not: MpioAccess).
bool OpenedWithMpio(hid_t object) {
  const hid_t file = H5Iget_file_id(object);
  hbool_t atomic = false;
  herr_t status = -1;
  H5E_BEGIN_TRY {
    status = H5Fget_mpi_atomicity(file, &atomic);
  }
  H5E_END_TRY;
  if (file >= 0) H5Fclose(file);
  return status >= 0;
}

// Transfers for `dataset`: collective on a file opened with MPI-IO, HDF5's
// default on others (-1 on failure); the caller closes.
hid_t CollectiveTransfer(hid_t dataset) {
  const hid_t transfer = H5Pcreate(H5P_DATASET_XFER);
  if (transfer >= 0 && OpenedWithMpio(dataset) &&
      H5Pset_dxpl_mpio(transfer, H5FD_MPIO_COLLECTIVE) < 0) {
    H5Pclose(transfer);
    return -1;
  }
  return transfer;
}

}  // namespace

hid_t CreateParallelFile(MPI_Comm comm, const std::string &path) {
  const hid_t access = MpioAccess(comm);
  if (access < 0) return -1;
  const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, access);
  H5Pclose(access);
  return file;
}

hid_t OpenParallelFile(MPI_Comm comm, const std::string &path, bool writable) {
  const hid_t access = MpioAccess(comm);
  if (access < 0) return -1;
  const hid_t file = H5Fopen(path.c_str(), writable ? H5F_ACC_RDWR : H5F_ACC_RDONLY, access);
  H5Pclose(access);
  return file;
}

namespace {

// Bytes of one row of a dataset whose dims are `dims` from index `first_row_dim`
// on (the row's own columns follow it).
hsize_t RowBytes(hid_t type, const std::vector<hsize_t> &dims, size_t first_row_dim) {
  hsize_t bytes = H5Tget_size(type);
  for (size_t d = first_row_dim + 1; d < dims.size(); ++d) bytes *= dims[d];
  return bytes;
}

// A chunked, extendible (first dimension) dataset of `dims` with chunk `chunk`.
hid_t CreateChunked(hid_t location, const char *name, hid_t type, const std::vector<hsize_t> &dims,
                    const std::vector<hsize_t> &chunk) {
  std::vector<hsize_t> max_dims(dims);
  max_dims[0] = H5S_UNLIMITED;
  const hid_t space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), max_dims.data());
  const hid_t properties = H5Pcreate(H5P_DATASET_CREATE);
  hid_t set = -1;
  // Every value is written before it is read: no fill values to write first.
  if (space >= 0 && properties >= 0 &&
      H5Pset_chunk(properties, static_cast<int>(chunk.size()), chunk.data()) >= 0 &&
      H5Pset_fill_time(properties, H5D_FILL_TIME_NEVER) >= 0)
    set = H5Dcreate2(location, name, type, space, H5P_DEFAULT, properties, H5P_DEFAULT);
  if (properties >= 0) H5Pclose(properties);
  if (space >= 0) H5Sclose(space);
  return set;
}

}  // namespace

hid_t CreateRowDataset(hid_t location, const char *name, hid_t type,
                       const std::vector<hsize_t> &dims, bool extendible_rows) {
  if (extendible_rows) {
    std::vector<hsize_t> chunk(dims);
    chunk[0] = ChunkRows(dims[0], RowBytes(type, dims, 0));
    return CreateChunked(location, name, type, dims, chunk);
  }
  const hid_t space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr);
  if (space < 0) return -1;
  const hid_t set = H5Dcreate2(location, name, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  H5Sclose(space);
  return set;
}

hid_t CreateFrameDataset(hid_t location, const char *name, const std::vector<hsize_t> &frame_dims) {
  std::vector<hsize_t> dims{0}, chunk{frame_dims.empty() ? kScalarFramesPerChunk : 1};
  dims.insert(dims.end(), frame_dims.begin(), frame_dims.end());
  chunk.insert(chunk.end(), frame_dims.begin(), frame_dims.end());
  if (!frame_dims.empty())
    chunk[1] = ChunkRows(frame_dims[0], RowBytes(H5T_NATIVE_DOUBLE, dims, 1));
  return CreateChunked(location, name, H5T_NATIVE_DOUBLE, dims, chunk);
}

std::vector<hsize_t> DatasetDims(hid_t dataset) {
  const hid_t space = H5Dget_space(dataset);
  if (space < 0) return {};
  const int rank = H5Sget_simple_extent_ndims(space);
  std::vector<hsize_t> dims(std::max(rank, 0));
  if (rank < 0 || H5Sget_simple_extent_dims(space, dims.data(), nullptr) < 0) dims.clear();
  H5Sclose(space);
  return dims;
}

bool ExtendRows(hid_t dataset, hsize_t rows) {
  std::vector<hsize_t> dims = DatasetDims(dataset);
  if (dims.empty()) return false;
  dims[0] = rows;
  return H5Dset_extent(dataset, dims.data()) >= 0;
}

namespace {

// Collective. Transfers rows `slab` of the dimension after `prefix` (the
// leading indices, e.g. the frame), all later dimensions whole.
bool TransferSlab(hid_t dataset, const std::vector<hsize_t> &prefix, hid_t memory_type,
                  RowSlab slab, void *values, bool write) {
  const std::vector<hsize_t> dims = DatasetDims(dataset);
  const size_t row_dim = prefix.size();
  if (dims.size() <= row_dim || slab.end > dims[row_dim] || slab.begin > slab.end) return false;
  std::vector<hsize_t> start(dims.size(), 0), count(dims);
  for (size_t d = 0; d < row_dim; ++d) {
    if (prefix[d] >= dims[d]) return false;
    start[d] = prefix[d];
    count[d] = 1;
  }
  start[row_dim] = slab.begin;
  count[row_dim] = slab.count();
  const hid_t file_space = H5Dget_space(dataset);
  std::vector<hsize_t> memory_dims(count.begin() + row_dim, count.end());
  memory_dims[0] = std::max<hsize_t>(memory_dims[0], 1);  // an empty slab selects none of one row
  const hid_t memory_space =
      H5Screate_simple(static_cast<int>(memory_dims.size()), memory_dims.data(), nullptr);
  const hid_t transfer = CollectiveTransfer(dataset);
  bool ok = file_space >= 0 && memory_space >= 0 && transfer >= 0;
  if (ok && slab.count() == 0) {
    ok = H5Sselect_none(file_space) >= 0 && H5Sselect_none(memory_space) >= 0;
  } else if (ok) {
    ok = H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start.data(), nullptr, count.data(),
                             nullptr) >= 0;
  }
  double unused = 0;  // HDF5 wants a buffer even when it transfers nothing
  void *buffer = values ? values : &unused;
  if (ok)
    ok = (write ? H5Dwrite(dataset, memory_type, memory_space, file_space, transfer, buffer)
                : H5Dread(dataset, memory_type, memory_space, file_space, transfer, buffer)) >= 0;
  if (transfer >= 0) H5Pclose(transfer);
  if (memory_space >= 0) H5Sclose(memory_space);
  if (file_space >= 0) H5Sclose(file_space);
  return ok;
}

}  // namespace

bool WriteRows(hid_t dataset, hid_t memory_type, RowSlab slab, const void *values) {
  return TransferSlab(dataset, {}, memory_type, slab, const_cast<void *>(values), true);
}

bool ReadRows(hid_t dataset, hid_t memory_type, RowSlab slab, void *values) {
  return TransferSlab(dataset, {}, memory_type, slab, values, false);
}

bool WriteFrameRows(hid_t dataset, hsize_t frame, hid_t memory_type, RowSlab slab,
                    const void *values) {
  const std::vector<hsize_t> dims = DatasetDims(dataset);
  if (dims.empty() || (frame >= dims[0] && !ExtendRows(dataset, frame + 1))) return false;
  return TransferSlab(dataset, {frame}, memory_type, slab, const_cast<void *>(values), true);
}

bool ReadFrameRows(hid_t dataset, hsize_t frame, hid_t memory_type, RowSlab slab, void *values) {
  return TransferSlab(dataset, {frame}, memory_type, slab, values, false);
}

bool WriteScalarFrame(hid_t dataset, hsize_t frame, double value, bool writer) {
  const std::vector<hsize_t> dims = DatasetDims(dataset);
  if (dims.size() != 1 || (frame >= dims[0] && !ExtendRows(dataset, frame + 1))) return false;
  const RowSlab slab = writer ? RowSlab{frame, frame + 1} : RowSlab{frame, frame};
  return WriteRows(dataset, H5T_NATIVE_DOUBLE, slab, &value);
}

bool ReadScalarFrame(hid_t dataset, hsize_t frame, double *value) {
  return ReadRows(dataset, H5T_NATIVE_DOUBLE, {frame, frame + 1}, value);
}

}  // namespace softbody
