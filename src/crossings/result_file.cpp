#include "crossings/result_file.hpp"

#include <unistd.h>

#include <algorithm>

#include "common/errors.hpp"
#include "io/hdf5_io.hpp"

namespace softbody {

namespace {

// A whole dataset that must exist with `columns` values per row (0: one-dimensional).
template <typename T>
std::vector<T> ReadTable(hid_t file, const std::string &path, const char *name, hid_t type,
                         hsize_t columns) {
  std::vector<T> values;
  std::vector<hsize_t> dims;
  if (!ReadArray(file, name, type, &values, &dims))
    throw InputError(path + ": not a softbody result file (no readable " + name + ")");
  const bool shape_ok = columns == 0 ? dims.size() == 1 : dims.size() == 2 && dims[1] == columns;
  if (!shape_ok) throw InputError(path + ": " + name + " has an unexpected shape");
  return values;
}

// Checks every index of a table against [0, bound).
void CheckIndices(const std::vector<int32_t> &indices, int32_t bound, const std::string &path,
                  const char *name) {
  for (const int32_t index : indices)
    if (index < 0 || index >= bound)
      throw InputError(path + ": " + name + " holds the index " + std::to_string(index) +
                       ", outside 0.." + std::to_string(bound - 1));
}

// Dimensions of a dataset (empty when it is missing).
std::vector<hsize_t> DatasetShape(hid_t file, const char *name) {
  if (!LinkExists(file, name)) return {};
  const hid_t set = H5Dopen2(file, name, H5P_DEFAULT);
  if (set < 0) return {};
  const hid_t space = H5Dget_space(set);
  std::vector<hsize_t> dims(space >= 0 ? std::max(H5Sget_simple_extent_ndims(space), 0) : 0);
  if (space >= 0) H5Sget_simple_extent_dims(space, dims.data(), nullptr);
  if (space >= 0) H5Sclose(space);
  H5Dclose(set);
  return dims;
}

}  // namespace

ResultFile::ResultFile(const std::string &path) : path_(path) {
  try {
    Load();
  } catch (...) {
    if (positions_ >= 0) H5Dclose(positions_);
    if (file_ >= 0) H5Fclose(file_);
    throw;
  }
}

void ResultFile::Load() {
  const std::string &path = path_;
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // failures become one InputError
  if (access(path.c_str(), R_OK) != 0) throw InputError(path + ": cannot read the file");
  if (H5Fis_hdf5(path.c_str()) <= 0) throw InputError(path + ": not an HDF5 file");
  file_ = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (file_ < 0) throw InputError(path + ": cannot open the HDF5 file");
  const std::vector<int32_t> rows =
      ReadTable<int32_t>(file_, path, "/mesh/boundary_triangles", H5T_NATIVE_INT32, 3);
  surface_.vertex_body = ReadTable<int32_t>(file_, path, "/mesh/vertex_body", H5T_NATIVE_INT32, 0);
  surface_.body_fixed = ReadTable<int32_t>(file_, path, "/mesh/body_fixed", H5T_NATIVE_INT32, 0);
  times_ = ReadTable<double>(file_, path, "/time", H5T_NATIVE_DOUBLE, 0);
  CheckIndices(rows, surface_.num_vertices(), path, "/mesh/boundary_triangles");
  CheckIndices(surface_.vertex_body, surface_.num_bodies(), path, "/mesh/vertex_body");
  for (size_t t = 0; t < rows.size() / 3; ++t) {
    const std::array<int32_t, 3> triangle = {rows[3 * t], rows[3 * t + 1], rows[3 * t + 2]};
    const int32_t body = surface_.vertex_body[triangle[0]];
    if (surface_.vertex_body[triangle[1]] != body || surface_.vertex_body[triangle[2]] != body)
      throw InputError(path + ": boundary triangle " + std::to_string(t) +
                       " has corners in different bodies");
    surface_.triangles.push_back(triangle);
    surface_.triangle_body.push_back(body);
  }
  const std::vector<hsize_t> shape = DatasetShape(file_, "/positions");
  if (shape.size() != 3 || shape[1] != static_cast<hsize_t>(surface_.num_vertices()) ||
      shape[2] != 3)
    throw InputError(path + ": not a softbody result file (no /positions [frames][" +
                     std::to_string(surface_.num_vertices()) + "][3])");
  times_.resize(std::min<size_t>(times_.size(), shape[0]));  // a file cut short mid-frame
  positions_ = H5Dopen2(file_, "/positions", H5P_DEFAULT);
  if (positions_ < 0) throw InputError(path + ": cannot open /positions");
  double ground = 0;
  if (GetAttribute(file_, "ground_y", &ground)) ground_y_ = ground;
}

ResultFile::~ResultFile() {
  if (positions_ >= 0) H5Dclose(positions_);
  if (file_ >= 0) H5Fclose(file_);
}

void ResultFile::ReadPositions(int64_t frame, const std::vector<VertexRange> &rows,
                               std::vector<double> *positions) const {
  positions->resize(3 * static_cast<size_t>(surface_.num_vertices()));
  const hid_t file_space = H5Dget_space(positions_);
  bool ok = file_space >= 0;
  for (const auto &[begin, end] : rows) {
    if (!ok || end <= begin) continue;
    const hsize_t start[3] = {static_cast<hsize_t>(frame), static_cast<hsize_t>(begin), 0};
    const hsize_t count[3] = {1, static_cast<hsize_t>(end - begin), 3};
    const hid_t memory_space = H5Screate_simple(3, count, nullptr);
    ok = memory_space >= 0 &&
         H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start, nullptr, count, nullptr) >= 0 &&
         H5Dread(positions_, H5T_NATIVE_DOUBLE, memory_space, file_space, H5P_DEFAULT,
                 positions->data() + 3 * static_cast<size_t>(begin)) >= 0;
    if (memory_space >= 0) H5Sclose(memory_space);
  }
  if (file_space >= 0) H5Sclose(file_space);
  if (!ok) throw InputError(path_ + ": cannot read /positions of frame " + std::to_string(frame));
}

std::vector<ResultFile::VertexRange> ResultFile::FreeVertices() const {
  std::vector<VertexRange> ranges;
  for (int32_t v = 0; v < surface_.num_vertices(); ++v) {
    if (surface_.fixed(surface_.vertex_body[v])) continue;
    if (!ranges.empty() && ranges.back().second == v)
      ++ranges.back().second;
    else
      ranges.push_back({v, v + 1});
  }
  return ranges;
}

}  // namespace softbody
