// What softbody-crossings reports: one line per frame with a crossing, a
// summary, and optionally a JSON file with every checked frame's counts.
//
// Summary figures (over the checked frames): frames with a crossing (any kind:
// a triangle pair or a vertex below the ground; or a non-finite position), the largest count of
// each kind and the frame where it first occurs, the first frame with a crossing, the first clean
// frame, and the frame from which every checked frame is clean
// ("clean from"; none when the last checked frame has a crossing).
//
// JSON (keys fixed; frames are frame indices of the file, -1 for none):
//   {"file", "ground_y" (null: not checked), "ground_tolerance", "every", "frames_checked",
//    "frames_with_crossings", "first_crossing_frame", "first_clean_frame",
//    "clean_from_frame", "seconds",
//    "kinds": {KIND: {"frames": frames with it, "max": largest count, "max_frame"}}
//             for KIND in free_free, free_fixed, self, below_ground,
//    "max_ground_depth" (m), "nonfinite_frames" (frames with a NaN or infinite position),
//    "frames": [{"frame", "time", "free_free", "free_fixed", "self", "below_ground",
//                "ground_depth", "degenerate", "nonfinite"}, ...]}
#pragma once

#include <petscsys.h>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "crossings/crossing_count.hpp"

namespace softbody {

struct CrossingsReport {
  std::string file;
  std::optional<GroundPlane> ground;   // the plane checked (none: no ground count)
  int64_t every = 1;                   // -every: frames 0, every, 2 every, ... checked
  std::vector<int64_t> frames;         // the checked frames' indices in the file
  std::vector<double> times;           // their times (s)
  std::vector<CrossingCounts> counts;  // their counts
  double seconds = 0;                  // wall time of the check
};

// Collective. Rank 0's `counts` becomes the sum over the ranks (each rank filled
// its own frames and left the others zero); the other ranks' are unchanged.
PetscErrorCode GatherCounts(MPI_Comm comm, std::vector<CrossingCounts> *counts);

// Collective. Fails (one line naming -json) unless `path` is empty or rank 0 can
// create it. Creates the file (empty) when it can.
PetscErrorCode CheckJsonPath(MPI_Comm comm, const std::string &path);

// Collective (rank 0 prints). The per-frame lines and the summary on stdout.
PetscErrorCode PrintReport(MPI_Comm comm, const CrossingsReport &report);

// Collective (rank 0 writes). Nothing when `path` is empty.
PetscErrorCode WriteJsonReport(MPI_Comm comm, const std::string &path,
                               const CrossingsReport &report);

}  // namespace softbody
