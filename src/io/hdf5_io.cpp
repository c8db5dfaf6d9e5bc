#include "io/hdf5_io.hpp"

namespace softbody {

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
