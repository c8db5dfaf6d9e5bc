// A softbody result file as the crossing checker reads it (format:
// io/output.hpp and docs/scenes-and-output.md): the surfaces, the bodies, the
// ground plane if the run had one, and one frame's positions at a time.
//
// Read with the serial HDF5 interface (any rank may open the file on its own);
// nothing of the solver's geometry is used. Errors throw InputError naming the
// file and what is missing.
#pragma once

#include <hdf5.h>

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace softbody {

struct ResultSurface {
  std::vector<std::array<int32_t, 3>> triangles;  // /mesh/boundary_triangles (natural vertices)
  std::vector<int32_t> triangle_body;             // body of each triangle (of its first vertex)
  std::vector<int32_t> vertex_body;               // /mesh/vertex_body [V]
  std::vector<int32_t> body_fixed;                // /mesh/body_fixed [bodies] (1: fixed)
  int32_t num_vertices() const { return static_cast<int32_t>(vertex_body.size()); }
  int32_t num_bodies() const { return static_cast<int32_t>(body_fixed.size()); }
  bool fixed(int32_t body) const { return body_fixed[body] != 0; }
};

class ResultFile {
 public:
  // Opens `path` read-only and reads its surface, times and ground; throws
  // InputError when the file is missing, not HDF5, or not a softbody result
  // (a dataset missing or of the wrong shape, an index out of range, a
  // triangle whose corners lie in different bodies).
  explicit ResultFile(const std::string &path);
  ResultFile(const ResultFile &) = delete;
  ResultFile &operator=(const ResultFile &) = delete;
  ~ResultFile();

  const std::string &path() const { return path_; }
  const ResultSurface &surface() const { return surface_; }
  // Frames on disk: /time and /positions both hold them.
  int64_t num_frames() const { return static_cast<int64_t>(times_.size()); }
  double time(int64_t frame) const { return times_[frame]; }
  // The root attribute "ground_y" (m) when the run had a ground plane.
  const std::optional<double> &ground_y() const { return ground_y_; }
  // Positions at `frame` of the vertices in `rows` (ranges [begin, end) of
  // vertices) into `positions` [V][3] flattened (m; resized to V rows, the
  // other rows left as they were). Throws InputError on a read error.
  using VertexRange = std::pair<int32_t, int32_t>;
  void ReadPositions(int64_t frame, const std::vector<VertexRange> &rows,
                     std::vector<double> *positions) const;
  // All vertices, and the vertices of the free bodies (fixed bodies never move), as ranges.
  std::vector<VertexRange> AllVertices() const { return {{0, surface_.num_vertices()}}; }
  std::vector<VertexRange> FreeVertices() const;

 private:
  void Load();

  std::string path_;
  hid_t file_ = -1;
  hid_t positions_ = -1;  // the /positions dataset, open
  ResultSurface surface_;
  std::vector<double> times_;
  std::optional<double> ground_y_;
};

}  // namespace softbody
