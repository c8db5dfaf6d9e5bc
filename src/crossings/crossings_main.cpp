// softbody-crossings: counts, in every frame of a softbody result file, the
// surface triangles that intersect, with CGAL's exact predicates and none of the
// solver's geometry (what counts: crossings/crossing_count.hpp).
//
// Sample runs
//   softbody-crossings results/stairway.h5
//   softbody-crossings results/bunny.h5 -ground 0 -json bunny-crossings.json
//   mpirun -n 2 softbody-crossings results/big.h5 -every 5
//
// Steps: 1. read the options and the file name; 2. every rank opens the file and
// counts its share of the frames (frame k of the checked ones on rank k mod P);
// 3. rank 0 gathers the counts, prints one line per frame with a crossing and a
// summary, and writes the JSON file. Bad input (a missing file, a file that is
// not a result) is one line naming the file and a non-zero exit on every rank.
#include <petscsys.h>

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/errors.hpp"
#include "common/options.hpp"
#include "common/unused_options.hpp"
#include "crossings/crossing_count.hpp"
#include "crossings/crossings_report.hpp"
#include "crossings/result_file.hpp"
#include "io/output.hpp"

static const char help[] =
    "softbody-crossings: counts intersecting surface triangles in every frame of a softbody\n"
    "result file with exact predicates (CGAL): pairs between two free bodies, between a free\n"
    "and a fixed body, within one free body (triangles sharing no vertex), and free surface\n"
    "vertices below the ground plane. Closed triangles: touching counts as crossing.\n"
    "Usage: softbody-crossings RESULT.h5 [-ground H] [-ground_tolerance D] [-every K] [-json "
    "FILE]\n"
    "Prints one line per frame with a crossing and a summary (docs/contact-crossings.md).\n";

using namespace softbody;

namespace {

struct CrossingsOptions {
  std::string result;    // RESULT.h5
  PetscReal ground = 0;  // -ground H (m): overrides the file's ground_y
  PetscBool ground_set = PETSC_FALSE;
  PetscReal ground_tolerance = 0;  // -ground_tolerance D (m): only y < y0 - D counts
  PetscInt every = 1;              // -every K: frames 0, K, 2K, ...
  std::string json;                // -json FILE ("": none)
};

// Collective. The options (file name aside).
PetscErrorCode ProcessCrossingsOptions(MPI_Comm comm, CrossingsOptions *o) {
  PetscFunctionBeginUser;
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kReal, "-ground"},
                                     {OptionSyntax::kReal, "-ground_tolerance"},
                                     {OptionSyntax::kInteger, "-every"}}));
  char json[PETSC_MAX_PATH_LEN] = "";
  PetscOptionsBegin(comm, nullptr, "softbody-crossings", nullptr);
  PetscCall(PetscOptionsReal("-ground",
                             "Ground plane height y0 (m): count free surface vertices with y < y0 "
                             "(default: the file's ground_y, none without it)",
                             nullptr, o->ground, &o->ground, &o->ground_set));
  PetscCall(PetscOptionsReal("-ground_tolerance",
                             "Count only vertices deeper than this below the ground (m; 0: any "
                             "vertex with y < y0, exactly)",
                             nullptr, o->ground_tolerance, &o->ground_tolerance, nullptr));
  PetscCall(PetscOptionsInt("-every", "Check frames 0, K, 2K, ... only", nullptr, o->every,
                            &o->every, nullptr));
  PetscCall(PetscOptionsString("-json",
                               "Write the counts of every checked frame and the summary "
                               "to this JSON file",
                               nullptr, json, json, sizeof(json), nullptr));
  PetscOptionsEnd();
  PetscCheck(o->ground_tolerance >= 0, comm, PETSC_ERR_USER_INPUT,
             "option -ground_tolerance: must not be negative (got %g)",
             static_cast<double>(o->ground_tolerance));
  PetscCheck(o->every >= 1, comm, PETSC_ERR_USER_INPUT,
             "option -every: must be at least 1 (got %d)", static_cast<int>(o->every));
  o->json = json;
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. The result file's name, first on the command line; with -help
// and no name, `*help_only` is set instead.
PetscErrorCode ProcessFileName(MPI_Comm comm, int argc, char **argv, CrossingsOptions *options,
                               bool *help_only) {
  PetscFunctionBeginUser;
  PetscBool help = PETSC_FALSE;
  PetscCall(PetscOptionsHasHelp(nullptr, &help));
  const bool named = argc > 1 && argv[1][0] != '-';
  *help_only = help && !named;
  if (*help_only) PetscFunctionReturn(PETSC_SUCCESS);
  PetscCheck(named && (argc == 2 || argv[2][0] == '-'), comm, PETSC_ERR_USER_INPUT,
             "usage: softbody-crossings RESULT.h5 [options] (-help lists them)");
  options->result = argv[1];
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Not collective. Throws InputError unless the fixed bodies' vertices are where
// they were in frame 0 (`first`) at `frame`: the checker reads them from frame 0 only.
void CheckFixedBodiesStill(const ResultFile &file, const std::vector<double> &first,
                           int64_t frame) {
  std::vector<double> last;
  file.ReadPositions(frame, file.AllVertices(), &last);
  const ResultSurface &surface = file.surface();
  for (int32_t v = 0; v < surface.num_vertices(); ++v) {
    const int32_t body = surface.vertex_body[v];
    if (!surface.fixed(body)) continue;
    for (int c = 0; c < 3; ++c)
      if (last[3 * v + c] != first[3 * v + c])
        throw InputError(file.path() + ": fixed body " + std::to_string(body) + " moves (vertex " +
                         std::to_string(v) + " between frames 0 and " + std::to_string(frame) +
                         "), but fixed bodies are read from frame 0 only");
  }
}

// Collective. Counts this rank's share of the checked frames; rank 0 receives
// every frame's counts (the others' `counts` are left partial). The fixed
// bodies are read from frame 0 only, the free ones from every checked frame.
PetscErrorCode CountFrames(MPI_Comm comm, const ResultFile &file,
                           const std::optional<GroundPlane> &ground,
                           const std::vector<int64_t> &frames,
                           std::vector<CrossingCounts> *counts) {
  PetscFunctionBeginUser;
  PetscMPIInt rank = 0, size = 1;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  counts->assign(frames.size(), CrossingCounts());
  std::vector<double> positions;
  std::unique_ptr<CrossingCounter> counter;
  std::string error;
  try {
    if (frames.empty()) throw InputError(file.path() + ": the file holds no frame");
    file.ReadPositions(0, file.AllVertices(), &positions);
    if (rank == 0 && frames.size() > 1) CheckFixedBodiesStill(file, positions, frames.back());
    counter = std::make_unique<CrossingCounter>(file.surface(), positions);
    const std::vector<ResultFile::VertexRange> moving = file.FreeVertices();
    for (size_t i = rank; i < frames.size(); i += size) {
      file.ReadPositions(frames[i], moving, &positions);
      (*counts)[i] = counter->Count(positions, ground);
    }
  } catch (const InputError &input_error) {
    error = input_error.what();
  }
  PetscCall(AgreeOnAllRanks(comm, error.empty(),
                            error.empty() ? file.path() + ": a frame could not be read" : error));
  PetscCall(GatherCounts(comm, counts));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Steps 2-3 of the file's header.
PetscErrorCode Check(MPI_Comm comm, const CrossingsOptions &options) {
  PetscFunctionBeginUser;
  const double start = MPI_Wtime();
  std::unique_ptr<ResultFile> file;
  SOFTBODY_CATCH_INPUT(comm, file = std::make_unique<ResultFile>(options.result));
  PetscCall(CheckJsonPath(comm, options.json));
  std::optional<GroundPlane> ground;
  if (file->ground_y()) ground = GroundPlane{*file->ground_y(), options.ground_tolerance};
  if (options.ground_set) ground = GroundPlane{options.ground, options.ground_tolerance};
  std::vector<int64_t> frames;
  for (int64_t f = 0; f < file->num_frames(); f += options.every) frames.push_back(f);
  std::vector<CrossingCounts> counts;
  PetscCall(CountFrames(comm, *file, ground, frames, &counts));
  CrossingsReport report;
  report.file = options.result;
  report.ground = ground;
  report.every = options.every;
  report.frames = frames;
  for (const int64_t f : frames) report.times.push_back(file->time(f));
  report.counts = counts;
  report.seconds = MPI_Wtime() - start;
  PetscCall(PrintReport(comm, report));
  PetscCall(WriteJsonReport(comm, options.json, report));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Step 1, then the check, then the warning about options nothing read.
PetscErrorCode Run(MPI_Comm comm, int argc, char **argv) {
  PetscFunctionBeginUser;
  std::vector<std::string> given;
  PetscCall(UnreadOptions(&given));
  CrossingsOptions options;
  PetscCall(ProcessCrossingsOptions(comm, &options));
  bool help_only = false;
  PetscCall(ProcessFileName(comm, argc, argv, &options, &help_only));
  if (!help_only) PetscCall(Check(comm, options));
  const Describer describe = [comm]() {
    CrossingsOptions unused;
    return ProcessCrossingsOptions(comm, &unused);
  };
  PetscCall(WarnUnusedOptions(comm, given, {describe}));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

int main(int argc, char **argv) {
  return RunTool(argc, argv, help, Run);
}
