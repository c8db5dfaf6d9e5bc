#include "crossings/crossings_report.hpp"

#include <algorithm>
#include <cstdio>

#include "common/number_format.hpp"
#include "io/output.hpp"

namespace softbody {

namespace {

// The kinds of crossing, in the order of the report.
constexpr int kKinds = 4;
constexpr const char *kKindKeys[kKinds] = {"free_free", "free_fixed", "self", "below_ground"};
constexpr const char *kKindNames[kKinds] = {"free-free", "free-fixed", "self", "below ground"};

int64_t KindCount(const CrossingCounts &counts, int kind) {
  const int64_t values[kKinds] = {counts.free_free, counts.free_fixed, counts.self,
                                  counts.below_ground};
  return values[kind];
}

struct KindSummary {
  int64_t frames = 0;      // checked frames with at least one
  int64_t max = 0;         // the largest count in a frame
  int64_t max_frame = -1;  // the first frame with that count
};

struct Summary {
  KindSummary kinds[kKinds];
  int64_t frames_with_crossings = 0;
  int64_t first_crossing = -1, first_clean = -1, clean_from = -1;
  double max_ground_depth = 0;                         // m
  int64_t nonfinite_frames = 0, first_nonfinite = -1;  // frames with non-finite positions
};

Summary Summarise(const CrossingsReport &report) {
  Summary summary;
  int64_t last_crossing = -1;  // index into report.frames
  for (size_t i = 0; i < report.frames.size(); ++i) {
    const CrossingCounts &counts = report.counts[i];
    const int64_t frame = report.frames[i];
    for (int k = 0; k < kKinds; ++k) {
      KindSummary &kind = summary.kinds[k];
      const int64_t value = KindCount(counts, k);
      if (value > 0) ++kind.frames;
      if (value > kind.max) kind.max = value, kind.max_frame = frame;
    }
    summary.max_ground_depth = std::max(summary.max_ground_depth, counts.ground_depth);
    if (counts.nonfinite > 0 && summary.nonfinite_frames++ == 0) summary.first_nonfinite = frame;
    if (counts.any()) {
      ++summary.frames_with_crossings;
      if (summary.first_crossing < 0) summary.first_crossing = frame;
      last_crossing = static_cast<int64_t>(i);
    } else if (summary.first_clean < 0) {
      summary.first_clean = frame;
    }
  }
  if (last_crossing + 1 < static_cast<int64_t>(report.frames.size()))
    summary.clean_from = report.frames[last_crossing + 1];
  return summary;
}

std::string FrameOrNone(int64_t frame) {
  return frame < 0 ? "none" : std::to_string(frame);
}

std::string FrameLine(int64_t frame, double time, const CrossingCounts &counts) {
  std::string line = "frame " + std::to_string(frame) + " (t = " + FormatNumber(time) + " s):";
  for (int k = 0; k < kKinds; ++k)
    line +=
        std::string(k ? ", " : " ") + kKindNames[k] + " " + std::to_string(KindCount(counts, k));
  if (counts.below_ground > 0) line += " (deepest " + FormatNumber(counts.ground_depth, 3) + " m)";
  if (counts.degenerate > 0) line += ", degenerate triangles " + std::to_string(counts.degenerate);
  if (counts.nonfinite > 0)
    line += ", triangles with non-finite corners (not checked) " + std::to_string(counts.nonfinite);
  return line + "\n";
}

std::string SummaryLine(const CrossingsReport &report, const Summary &summary) {
  std::string line =
      "softbody-crossings: " + report.file + ": " + std::to_string(report.frames.size()) +
      " frames checked, " + std::to_string(summary.frames_with_crossings) +
      " with crossings (first " + FrameOrNone(summary.first_crossing) + ", first clean " +
      FrameOrNone(summary.first_clean) + ", clean from " + FrameOrNone(summary.clean_from) + ")";
  for (int k = 0; k < kKinds; ++k) {
    const KindSummary &kind = summary.kinds[k];
    const bool ground = k == kKinds - 1;
    line += std::string("; ") + kKindNames[k];
    if (ground && !report.ground) {
      line += " not checked (no ground plane in the file; -ground H)";
      continue;
    }
    if (ground) {
      line += " (y < " + FormatNumber(report.ground->y) + " m";
      if (report.ground->tolerance > 0)
        line += " - " + FormatNumber(report.ground->tolerance) + " m";
      line += ")";
    }
    line += " " + std::to_string(kind.frames) + " frames";
    if (kind.frames > 0)
      line += ", max " + std::to_string(kind.max) + (ground ? " vertices" : " pairs") + " (frame " +
              std::to_string(kind.max_frame) + ")";
    if (ground && kind.frames > 0)
      line += ", deepest " + FormatNumber(summary.max_ground_depth, 3) + " m";
  }
  if (summary.nonfinite_frames > 0)
    line += "; non-finite positions in " + std::to_string(summary.nonfinite_frames) +
            " frames (first " + std::to_string(summary.first_nonfinite) + ")";
  return line + "; " + FormatNumber(report.seconds, 3) + " s\n";
}

std::string JsonString(const std::string &text) {
  std::string quoted = "\"";
  for (const char c : text) {
    if (c == '"' || c == '\\') quoted += '\\';
    if (static_cast<unsigned char>(c) < 0x20) continue;  // no control characters in file names
    quoted += c;
  }
  return quoted + "\"";
}

void WriteJsonFrames(std::FILE *out, const CrossingsReport &report) {
  std::fprintf(out, "  \"frames\": [");
  for (size_t i = 0; i < report.frames.size(); ++i) {
    const CrossingCounts &c = report.counts[i];
    std::fprintf(out,
                 "%s\n    {\"frame\": %lld, \"time\": %.17g, \"free_free\": %lld, "
                 "\"free_fixed\": %lld, \"self\": %lld, \"below_ground\": %lld, "
                 "\"ground_depth\": %.17g, \"degenerate\": %lld, \"nonfinite\": %lld}",
                 i ? "," : "", static_cast<long long>(report.frames[i]), report.times[i],
                 static_cast<long long>(c.free_free), static_cast<long long>(c.free_fixed),
                 static_cast<long long>(c.self), static_cast<long long>(c.below_ground),
                 c.ground_depth, static_cast<long long>(c.degenerate),
                 static_cast<long long>(c.nonfinite));
  }
  std::fprintf(out, "\n  ]\n}\n");
}

bool WriteJson(const std::string &path, const CrossingsReport &report, const Summary &summary) {
  std::FILE *out = std::fopen(path.c_str(), "w");
  if (!out) return false;
  const std::string ground = report.ground ? FormatNumber(report.ground->y, 17) : "null";
  const double tolerance = report.ground ? report.ground->tolerance : 0;
  std::fprintf(out,
               "{\n  \"file\": %s,\n  \"ground_y\": %s,\n  \"ground_tolerance\": %.17g,\n"
               "  \"every\": %lld,\n"
               "  \"frames_checked\": %zu,\n  \"frames_with_crossings\": %lld,\n"
               "  \"first_crossing_frame\": %lld,\n  \"first_clean_frame\": %lld,\n"
               "  \"clean_from_frame\": %lld,\n  \"seconds\": %.6g,\n  \"kinds\": {",
               JsonString(report.file).c_str(), ground.c_str(), tolerance,
               static_cast<long long>(report.every), report.frames.size(),
               static_cast<long long>(summary.frames_with_crossings),
               static_cast<long long>(summary.first_crossing),
               static_cast<long long>(summary.first_clean),
               static_cast<long long>(summary.clean_from), report.seconds);
  for (int k = 0; k < kKinds; ++k)
    std::fprintf(out, "%s\n    \"%s\": {\"frames\": %lld, \"max\": %lld, \"max_frame\": %lld}",
                 k ? "," : "", kKindKeys[k], static_cast<long long>(summary.kinds[k].frames),
                 static_cast<long long>(summary.kinds[k].max),
                 static_cast<long long>(summary.kinds[k].max_frame));
  std::fprintf(out, "\n  },\n  \"max_ground_depth\": %.17g,\n  \"nonfinite_frames\": %lld,\n",
               summary.max_ground_depth, static_cast<long long>(summary.nonfinite_frames));
  WriteJsonFrames(out, report);
  return std::fclose(out) == 0;
}

}  // namespace

PetscErrorCode GatherCounts(MPI_Comm comm, std::vector<CrossingCounts> *counts) {
  PetscFunctionBeginUser;
  PetscMPIInt rank = 0;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  constexpr int kSums = 6;  // the integer fields of CrossingCounts
  const size_t n = counts->size();
  std::vector<int64_t> sums(kSums * n);
  std::vector<double> depths(n);
  for (size_t i = 0; i < n; ++i) {
    const CrossingCounts &c = (*counts)[i];
    const int64_t fields[kSums] = {c.free_free,    c.free_fixed, c.self,
                                   c.below_ground, c.degenerate, c.nonfinite};
    std::copy(fields, fields + kSums, sums.begin() + kSums * i);
    depths[i] = c.ground_depth;
  }
  PetscCallMPI(MPI_Reduce(rank == 0 ? MPI_IN_PLACE : sums.data(), sums.data(),
                          static_cast<int>(sums.size()), MPI_INT64_T, MPI_SUM, 0, comm));
  PetscCallMPI(MPI_Reduce(rank == 0 ? MPI_IN_PLACE : depths.data(), depths.data(),
                          static_cast<int>(depths.size()), MPI_DOUBLE, MPI_MAX, 0, comm));
  if (rank != 0) PetscFunctionReturn(PETSC_SUCCESS);
  for (size_t i = 0; i < n; ++i) {
    const int64_t *s = &sums[kSums * i];
    (*counts)[i] = {s[0], s[1], s[2], s[3], depths[i], s[4], s[5]};
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CheckJsonPath(MPI_Comm comm, const std::string &path) {
  PetscFunctionBeginUser;
  if (path.empty()) PetscFunctionReturn(PETSC_SUCCESS);
  PetscMPIInt rank = 0;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  bool ok = true;
  if (rank == 0) {
    std::FILE *out = std::fopen(path.c_str(), "w");
    ok = out != nullptr;
    if (out) std::fclose(out);
  }
  PetscCall(AgreeOnSuccess(comm, ok, "option -json: cannot create " + path));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PrintReport(MPI_Comm comm, const CrossingsReport &report) {
  PetscFunctionBeginUser;
  for (size_t i = 0; i < report.frames.size(); ++i)
    if (report.counts[i].any())
      PetscCall(PetscPrintf(
          comm, "%s", FrameLine(report.frames[i], report.times[i], report.counts[i]).c_str()));
  PetscCall(PetscPrintf(comm, "%s", SummaryLine(report, Summarise(report)).c_str()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode WriteJsonReport(MPI_Comm comm, const std::string &path,
                               const CrossingsReport &report) {
  PetscFunctionBeginUser;
  if (path.empty()) PetscFunctionReturn(PETSC_SUCCESS);
  PetscMPIInt rank = 0;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  const bool ok = rank != 0 || WriteJson(path, report, Summarise(report));
  PetscCall(AgreeOnSuccess(comm, ok, "option -json: cannot write " + path));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
