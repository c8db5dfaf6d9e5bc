// softbody: implicit finite-element simulation of soft bodies on PETSc + MPI.
//
// Sample runs
//   mpirun -n 2 softbody -scene scenes/default-scene.txt -output results/default.h5
//   mpirun -n 2 softbody -scene S.txt -steps 200 -dt 0.01 -ksp_type cg -pc_type gamg -log_view
//   mpirun -n 2 softbody -scene S.txt -options_file config/cg-jacobi.opts -ksp_monitor
//   mpirun -n 2 softbody -scene S.txt -mode corotational -ksp_converged_reason
//   mpirun -n 2 softbody -scene S.txt -options_file config/practical3.opts -constraints C.txt
//   mpirun -n 2 softbody -scene S.txt -steps 1000 -output run.h5 -checkpoint_every 50
//   mpirun -n 2 softbody -scene S.txt -steps 2000 -restart run.h5    # continues run.h5
//
// Equations (linear and corotational): see integrator.hpp; collisions and
// constraints: contact.hpp. Data flow: scene -> free DOFs (METIS partition) ->
// element kernels on each rank's elements -> COO assembly -> KSP -> time loop
// (solve, then contact) -> HDF5 frames in natural vertex order. The run's steps:
// simulation.hpp; checkpoints and restart: checkpoint.hpp; progress line, -quiet
// and signals: run_control.hpp; options nothing read: unused_options.hpp.
#include <petscsys.h>

#include <cstdio>
#include <cstring>

#include "app/run_control.hpp"
#include "app/simulation.hpp"
#include "common/errors.hpp"

static const char help[] =
    "softbody: implicit finite-element soft-body simulation (PETSc + MPI).\n"
    "Usage: mpirun -n 2 softbody -scene SCENE.txt [-output OUT.h5] [options] [PETSc options]\n"
    "Solver presets: -options_file config/direct.opts (linear default),\n"
    "config/cg-warp.opts (corotational default), config/cg-gamg.opts,\n"
    "config/direct-mumps.opts, ...\n";

using namespace softbody;

namespace {

// Collective. The run (simulation.hpp), its objects destroyed before PetscFinalize.
PetscErrorCode Run(MPI_Comm comm, int *exit_code) {
  PetscFunctionBeginUser;
  Simulation simulation(comm);
  PetscCall(simulation.Run(exit_code));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Every -options_file on the command line can be opened; otherwise rank 0 says
// which cannot. Not collective beyond MPI_Comm_rank.
bool OptionsFilesReadable(int argc, char **argv) {
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "-options_file") != 0) continue;
    const char *path = i + 1 < argc ? argv[i + 1] : "";
    if (std::FILE *file = std::fopen(path, "r")) {
      std::fclose(file);
      continue;
    }
    if (rank == 0)
      std::fprintf(stderr, "softbody: error: option -options_file: cannot open '%s'\n", path);
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char **argv) {
  // MPI first: an unreadable -options_file is reported as one line by rank 0,
  // before PETSc would stop inside PetscInitialize with a traceback.
  MPI_Init(&argc, &argv);
  if (!OptionsFilesReadable(argc, argv)) {
    MPI_Finalize();
    return 1;
  }
  PetscCall(PetscInitialize(&argc, &argv, nullptr, help));
  PetscCall(InstallErrorHandler());
  PetscCall(InstallStopHandlers());
  int exit_code = 0;
  const PetscErrorCode status = Run(PETSC_COMM_WORLD, &exit_code);
  PetscCall(PetscFinalize());
  MPI_Finalize();
  return status == PETSC_SUCCESS ? exit_code : 1;
}
