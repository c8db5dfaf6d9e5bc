// softbody-convert: writes a softbody mesh file (.h5, io/mesh_h5.hpp) from a
// MEDIT .mesh, gmsh .msh or OFF surface .off (meshed here by TetGen, once), so
// that a large mesh is read in slabs by all ranks instead of whole by each.
//
// Sample runs
//   softbody-convert body.mesh body.h5
//   softbody-convert part.msh part.h5
//   softbody-convert torus.off torus.h5 -tetgen_switches pq1.2 -tetgen_max_volume 1e-3
//
// Steps: 1. read the options and the two file names; 2. rank 0 reads the input
// with the scene's readers (mesh_io.hpp: same checks, same vertex order) and
// writes the .h5 under a temporary name, renamed when complete; 3. every rank
// exits with rank 0's status (a bad input is one line naming the file).
#include <petscsys.h>

#include <string>
#include <vector>

#include "common/errors.hpp"
#include "common/options.hpp"
#include "common/unused_options.hpp"
#include "io/mesh_h5.hpp"
#include "io/mesh_io.hpp"
#include "io/scene.hpp"

static const char help[] =
    "softbody-convert: converts a tetrahedral mesh to a softbody mesh file (.h5) that all ranks\n"
    "read in slabs with parallel HDF5 (format: docs/scenes-and-output.md, 'Mesh files').\n"
    "Usage: softbody-convert IN.{mesh,msh,off} OUT.h5 [-tetgen_switches S] [-tetgen_max_volume V]\n"
    "An .off surface is meshed by TetGen here, once; the vertex order is the one the scene's\n"
    "reader gives (for .off: the OFF vertices first, then TetGen's).\n";

using namespace softbody;

namespace {

struct ConvertOptions {
  std::string input;       // IN.{mesh,msh,off}
  std::string output;      // OUT.h5
  MeshingOptions meshing;  // -tetgen_switches, -tetgen_max_volume
};

bool EndsWith(const std::string &s, const std::string &suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Collective. The two file names, which come first on the command line; with
// -help and no names, `*help_only` is set instead.
PetscErrorCode ProcessFileNames(MPI_Comm comm, int argc, char **argv, ConvertOptions *options,
                                bool *help_only) {
  PetscFunctionBeginUser;
  std::vector<std::string> names;
  for (int i = 1; i < argc && i <= 2 && argv[i][0] != '-'; ++i) names.push_back(argv[i]);
  PetscBool help = PETSC_FALSE;
  PetscCall(PetscOptionsHasHelp(nullptr, &help));
  *help_only = help && names.empty();
  if (*help_only) PetscFunctionReturn(PETSC_SUCCESS);
  PetscCheck(names.size() == 2, comm, PETSC_ERR_USER_INPUT,
             "usage: softbody-convert IN.{mesh,msh,off} OUT.h5 [options] (-help lists them)");
  options->input = names[0];
  options->output = names[1];
  PetscCheck(EndsWith(options->input, ".mesh") || EndsWith(options->input, ".msh") ||
                 EndsWith(options->input, ".off"),
             comm, PETSC_ERR_USER_INPUT,
             "%s: unknown mesh format (expected a MEDIT .mesh, a gmsh .msh or an OFF surface .off)",
             options->input.c_str());
  PetscCheck(EndsWith(options->output, ".h5"), comm, PETSC_ERR_USER_INPUT,
             "%s: the output must be a softbody mesh file ending in .h5", options->output.c_str());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective: rank 0 converts, every rank returns its status.
PetscErrorCode Convert(MPI_Comm comm, const ConvertOptions &options) {
  PetscFunctionBeginUser;
  PetscMPIInt rank = 0;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  std::string error;
  int64_t counts[2] = {0, 0};  // vertices, tets
  if (rank == 0) {
    try {
      const TetMesh mesh = ReadTetMesh(options.input, options.meshing);
      WriteMeshH5(options.output, mesh, options.input);
      counts[0] = mesh.num_vertices();
      counts[1] = mesh.num_tets();
    } catch (const InputError &input_error) {
      error = input_error.what();
    } catch (const std::bad_alloc &) {
      error = options.input + ": out of memory while converting";
    }
  }
  int length = static_cast<int>(error.size());
  PetscCallMPI(MPI_Bcast(&length, 1, MPI_INT, 0, comm));
  PetscCheck(length == 0, comm, PETSC_ERR_USER_INPUT, "%s",
             rank == 0 ? error.c_str() : "conversion failed on rank 0");
  PetscCall(PetscPrintf(comm,
                        "softbody-convert: wrote %s (%lld vertices, %lld tetrahedra) from %s\n",
                        options.output.c_str(), static_cast<long long>(counts[0]),
                        static_cast<long long>(counts[1]), options.input.c_str()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Collective. Steps 1-2 of the file's header, then the warning about options
// nothing read.
PetscErrorCode Run(MPI_Comm comm, int argc, char **argv) {
  PetscFunctionBeginUser;
  std::vector<std::string> given;
  PetscCall(UnreadOptions(&given));
  ConvertOptions options;
  PetscCall(ProcessMeshingOptions(comm, &options.meshing));
  bool help_only = false;
  PetscCall(ProcessFileNames(comm, argc, argv, &options, &help_only));
  if (!help_only) PetscCall(Convert(comm, options));
  const Describer describe = [comm]() {
    MeshingOptions unused;
    return ProcessMeshingOptions(comm, &unused);
  };
  PetscCall(WarnUnusedOptions(comm, given, {describe}));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

int main(int argc, char **argv) {
  return RunTool(argc, argv, help, Run);
}
