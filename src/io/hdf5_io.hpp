// Small HDF5 helpers shared by the result file and its checkpoints (output.cpp,
// checkpoint.cpp). Not collective: only the rank that holds the file calls them.
// Every function returns false (or a negative id) on failure and prints nothing:
// the callers turn failures into one user-facing message.
#pragma once

#include <hdf5.h>

#include <cstdint>
#include <string>
#include <vector>

namespace softbody {

// Extendible dataset of frames: dims [0, frame_dims...], chunks of one frame
// (1024 values for scalar series). Returns the open dataset (caller closes).
hid_t CreateSeries(hid_t location, const char *name, const std::vector<hsize_t> &frame_dims);

// Writes frame `frame` of a series created by CreateSeries (extending it to
// frame + 1 frames when needed).
bool WriteSeriesFrame(hid_t location, const char *name, hsize_t frame, const double *values);

// Reads frame `frame` of a series into values (frame_size doubles).
bool ReadSeriesFrame(hid_t location, const char *name, hsize_t frame, double *values);

// Number of frames of a series (-1 when it does not exist).
int64_t SeriesLength(hid_t location, const char *name);

// Shrinks (or grows) a series to `frames` frames.
bool ResizeSeries(hid_t location, const char *name, hsize_t frames);

// A fixed-size dataset written at once.
bool WriteArray(hid_t location, const char *name, hid_t type, const std::vector<hsize_t> &dims,
                const void *values);

// A two-dimensional dataset [rows][columns] whose row count may change between
// writes (chunked, unlimited rows): created at the first write, resized after.
bool WriteResizableArray(hid_t location, const char *name, hid_t type, hsize_t rows,
                         hsize_t columns, const void *values);

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
