// Small HDF5 helpers shared by the result file and its checkpoints (output.cpp,
// checkpoint.cpp): attributes, groups, whole small datasets. On a file opened by
// every rank with MPI-IO (parallel_hdf5.hpp) the writing ones (attributes,
// groups) are collective and need equal arguments on every rank; reading is
// independent (any rank may read). Every function returns false (or a negative
// id) on failure and prints nothing: the callers turn failures into one
// user-facing message.
#pragma once

#include <hdf5.h>

#include <cstdint>
#include <string>
#include <vector>

namespace softbody {

// Reads a whole dataset of `type` (any shape) into values, and its dims.
template <typename T>
bool ReadArray(hid_t location, const char *name, hid_t type, std::vector<T> *values,
               std::vector<hsize_t> *dims = nullptr);

// An attribute of an object (the file, a group), created or overwritten: a scalar,
// or a 1-D array of `count` doubles.
bool SetAttribute(hid_t object, const char *name, hid_t type, const void *value);
bool SetAttribute(hid_t object, const char *name, double value);
bool SetAttribute(hid_t object, const char *name, const double *values, hsize_t count);
bool SetAttribute(hid_t object, const char *name, int64_t value);
bool SetAttribute(hid_t object, const char *name, const std::string &value);
// Reads a scalar attribute (converted to the type asked for); false if absent.
bool GetAttribute(hid_t object, const char *name, double *value);
bool GetAttribute(hid_t object, const char *name, int64_t *value);

// True when `path` names a link (group or dataset) in the file.
bool LinkExists(hid_t location, const char *path);

// A group, opened if it exists, created otherwise (caller closes).
hid_t OpenOrCreateGroup(hid_t location, const char *name);

}  // namespace softbody
