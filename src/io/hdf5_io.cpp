#include "io/hdf5_io.hpp"

namespace softbody {

namespace {

// Chunk of a time series of scalars (time, energies): this many frames, so that
// appending a frame rarely allocates and a short run's file stays small.
constexpr hsize_t kScalarSeriesChunk = 1024;
// Chunk rows of an extendible table (e.g. the resting contacts of a checkpoint).
constexpr hsize_t kChunkRows = 256;

}  // namespace

hid_t CreateSeries(hid_t location, const char *name, const std::vector<hsize_t> &frame_dims) {
  std::vector<hsize_t> dims{0}, max_dims{H5S_UNLIMITED},
      chunk{frame_dims.empty() ? kScalarSeriesChunk : 1};
  for (hsize_t d : frame_dims) {
    dims.push_back(d);
    max_dims.push_back(d);
    chunk.push_back(d);
  }
  const hid_t space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), max_dims.data());
  const hid_t properties = H5Pcreate(H5P_DATASET_CREATE);
  H5Pset_chunk(properties, static_cast<int>(chunk.size()), chunk.data());
  const hid_t set =
      H5Dcreate2(location, name, H5T_NATIVE_DOUBLE, space, H5P_DEFAULT, properties, H5P_DEFAULT);
  H5Pclose(properties);
  H5Sclose(space);
  return set;
}

namespace {

// Reads or writes frame `frame` of an open series; `extend` grows it first.
bool TransferFrame(hid_t set, hsize_t frame, double *values, bool write) {
  hid_t space = H5Dget_space(set);
  if (space < 0) return false;
  const int rank = H5Sget_simple_extent_ndims(space);
  std::vector<hsize_t> dims(rank), start(rank, 0);
  H5Sget_simple_extent_dims(space, dims.data(), nullptr);
  H5Sclose(space);
  bool ok = true;
  if (frame >= dims[0]) {
    if (!write) return false;
    dims[0] = frame + 1;
    ok = H5Dset_extent(set, dims.data()) >= 0;
  }
  space = H5Dget_space(set);
  start[0] = frame;
  dims[0] = 1;
  ok = ok &&
       H5Sselect_hyperslab(space, H5S_SELECT_SET, start.data(), nullptr, dims.data(), nullptr) >= 0;
  const hid_t memory = H5Screate_simple(rank, dims.data(), nullptr);
  ok = ok && (write ? H5Dwrite(set, H5T_NATIVE_DOUBLE, memory, space, H5P_DEFAULT, values)
                    : H5Dread(set, H5T_NATIVE_DOUBLE, memory, space, H5P_DEFAULT, values)) >= 0;
  H5Sclose(memory);
  H5Sclose(space);
  return ok;
}

}  // namespace

bool WriteSeriesFrame(hid_t location, const char *name, hsize_t frame, const double *values) {
  const hid_t set = H5Dopen2(location, name, H5P_DEFAULT);
  if (set < 0) return false;
  const bool ok = TransferFrame(set, frame, const_cast<double *>(values), true);
  H5Dclose(set);
  return ok;
}

bool ReadSeriesFrame(hid_t location, const char *name, hsize_t frame, double *values) {
  const hid_t set = H5Dopen2(location, name, H5P_DEFAULT);
  if (set < 0) return false;
  const bool ok = TransferFrame(set, frame, values, false);
  H5Dclose(set);
  return ok;
}

int64_t SeriesLength(hid_t location, const char *name) {
  if (!LinkExists(location, name)) return -1;
  const hid_t set = H5Dopen2(location, name, H5P_DEFAULT);
  if (set < 0) return -1;
  const hid_t space = H5Dget_space(set);
  int64_t length = -1;
  if (space >= 0 && H5Sget_simple_extent_ndims(space) >= 1) {
    std::vector<hsize_t> dims(H5Sget_simple_extent_ndims(space));
    H5Sget_simple_extent_dims(space, dims.data(), nullptr);
    length = static_cast<int64_t>(dims[0]);
  }
  if (space >= 0) H5Sclose(space);
  H5Dclose(set);
  return length;
}

bool ResizeSeries(hid_t location, const char *name, hsize_t frames) {
  const hid_t set = H5Dopen2(location, name, H5P_DEFAULT);
  if (set < 0) return false;
  const hid_t space = H5Dget_space(set);
  std::vector<hsize_t> dims(H5Sget_simple_extent_ndims(space));
  H5Sget_simple_extent_dims(space, dims.data(), nullptr);
  H5Sclose(space);
  dims[0] = frames;
  const bool ok = H5Dset_extent(set, dims.data()) >= 0;
  H5Dclose(set);
  return ok;
}

bool WriteArray(hid_t location, const char *name, hid_t type, const std::vector<hsize_t> &dims,
                const void *values) {
  const hid_t space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr);
  const hid_t set = H5Dcreate2(location, name, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  const bool ok = set >= 0 && H5Dwrite(set, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values) >= 0;
  if (set >= 0) H5Dclose(set);
  H5Sclose(space);
  return ok;
}

bool WriteResizableArray(hid_t location, const char *name, hid_t type, hsize_t rows,
                         hsize_t columns, const void *values) {
  hsize_t dims[2] = {rows, columns};
  hid_t set;
  if (LinkExists(location, name)) {
    set = H5Dopen2(location, name, H5P_DEFAULT);
    if (set < 0 || H5Dset_extent(set, dims) < 0) {
      if (set >= 0) H5Dclose(set);
      return false;
    }
  } else {
    const hsize_t max_dims[2] = {H5S_UNLIMITED, columns}, chunk[2] = {kChunkRows, columns};
    const hid_t space = H5Screate_simple(2, dims, max_dims);
    const hid_t properties = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_chunk(properties, 2, chunk);
    set = H5Dcreate2(location, name, type, space, H5P_DEFAULT, properties, H5P_DEFAULT);
    H5Pclose(properties);
    H5Sclose(space);
    if (set < 0) return false;
  }
  const bool ok = rows == 0 || H5Dwrite(set, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values) >= 0;
  H5Dclose(set);
  return ok;
}

template <typename T>
bool ReadArray(hid_t location, const char *name, hid_t type, std::vector<T> *values,
               std::vector<hsize_t> *dims) {
  if (!LinkExists(location, name)) return false;
  const hid_t set = H5Dopen2(location, name, H5P_DEFAULT);
  if (set < 0) return false;
  const hid_t space = H5Dget_space(set);
  std::vector<hsize_t> shape(space >= 0 ? H5Sget_simple_extent_ndims(space) : 0);
  if (space >= 0) H5Sget_simple_extent_dims(space, shape.data(), nullptr);
  const hssize_t count = space >= 0 ? H5Sget_simple_extent_npoints(space) : -1;
  if (space >= 0) H5Sclose(space);
  bool ok = count >= 0;
  if (ok) {
    values->resize(static_cast<size_t>(count));
    ok = count == 0 || H5Dread(set, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values->data()) >= 0;
  }
  H5Dclose(set);
  if (dims) *dims = shape;
  return ok;
}

template bool ReadArray<double>(hid_t, const char *, hid_t, std::vector<double> *,
                                std::vector<hsize_t> *);
template bool ReadArray<int32_t>(hid_t, const char *, hid_t, std::vector<int32_t> *,
                                 std::vector<hsize_t> *);

bool SetAttribute(hid_t object, const char *name, hid_t type, const void *value) {
  if (H5Aexists(object, name) > 0) H5Adelete(object, name);  // the type may differ
  const hid_t space = H5Screate(H5S_SCALAR);
  const hid_t attribute = H5Acreate2(object, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  const bool ok = attribute >= 0 && H5Awrite(attribute, type, value) >= 0;
  if (attribute >= 0) H5Aclose(attribute);
  H5Sclose(space);
  return ok;
}

bool SetAttribute(hid_t object, const char *name, const double *values, hsize_t count) {
  if (H5Aexists(object, name) > 0) H5Adelete(object, name);
  const hid_t space = H5Screate_simple(1, &count, nullptr);
  const hid_t attribute =
      H5Acreate2(object, name, H5T_NATIVE_DOUBLE, space, H5P_DEFAULT, H5P_DEFAULT);
  const bool ok = attribute >= 0 && H5Awrite(attribute, H5T_NATIVE_DOUBLE, values) >= 0;
  if (attribute >= 0) H5Aclose(attribute);
  if (space >= 0) H5Sclose(space);
  return ok;
}

bool SetAttribute(hid_t object, const char *name, double value) {
  return SetAttribute(object, name, H5T_NATIVE_DOUBLE, &value);
}

bool SetAttribute(hid_t object, const char *name, int64_t value) {
  return SetAttribute(object, name, H5T_NATIVE_INT64, &value);
}

bool SetAttribute(hid_t object, const char *name, const std::string &value) {
  const hid_t type = H5Tcopy(H5T_C_S1);
  H5Tset_size(type, value.empty() ? 1 : value.size());
  const bool ok = SetAttribute(object, name, type, value.empty() ? "" : value.c_str());
  H5Tclose(type);
  return ok;
}

namespace {

bool ReadScalarAttribute(hid_t object, const char *name, hid_t type, void *value) {
  if (H5Aexists(object, name) <= 0) return false;
  const hid_t attribute = H5Aopen(object, name, H5P_DEFAULT);
  const bool ok = attribute >= 0 && H5Aread(attribute, type, value) >= 0;
  if (attribute >= 0) H5Aclose(attribute);
  return ok;
}

}  // namespace

bool GetAttribute(hid_t object, const char *name, double *value) {
  return ReadScalarAttribute(object, name, H5T_NATIVE_DOUBLE, value);
}

bool GetAttribute(hid_t object, const char *name, int64_t *value) {
  return ReadScalarAttribute(object, name, H5T_NATIVE_INT64, value);
}

bool LinkExists(hid_t location, const char *path) {
  // Every prefix must exist before H5Lexists may be asked about the next part.
  const std::string full(path);
  size_t from = full[0] == '/' ? 1 : 0;
  while (true) {
    const size_t slash = full.find('/', from);
    const std::string prefix = full.substr(0, slash);
    if (!prefix.empty() && prefix != "/" && H5Lexists(location, prefix.c_str(), H5P_DEFAULT) <= 0)
      return false;
    if (slash == std::string::npos) return true;
    from = slash + 1;
  }
}

hid_t OpenOrCreateGroup(hid_t location, const char *name) {
  if (LinkExists(location, name)) return H5Gopen2(location, name, H5P_DEFAULT);
  return H5Gcreate2(location, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
}

}  // namespace softbody
