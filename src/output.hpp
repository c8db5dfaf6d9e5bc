// Results on disk.
//
// HDF5 (written by rank 0 after a gather; natural vertex order, every vertex of
// every body, fixed ones included):
//   /time [F] (s), /positions [F][V][3] (m), /velocities [F][V][3] (m/s),
//   /energy/kinetic [F], /energy/elastic [F], /energy/gravitational [F] (J),
//   /mesh/tets [T][4], /mesh/boundary_triangles [B][3] (0-based natural vertex
//   indices), /mesh/vertex_body [V], /mesh/rest_positions [V][3],
//   /mesh/body_fixed [bodies] (1 for fixed bodies).
// Frame 0 is the initial state. The file is flushed after every frame; its root
// attribute "complete" is 0 until the run has finished (1); then the run's
// statistics (set-up and loop seconds, solver iterations, ...) are root attributes. An .xdmf beside it
// (same name), written at the end, describes the frames as a ParaView time series.
//
// Matrices: PETSc binary files of M, K and D in the natural order of the free
// vertices' coordinates (xyzxyz).
#pragma once

#include <hdf5.h>
#include <petscmat.h>

#include <string>
#include <utility>
#include <vector>

#include "assembly.hpp"
#include "partition.hpp"
#include "scene.hpp"

namespace softbody {

struct OutputOptions {
  std::string path;         // -output FILE.h5 ("" = write nothing)
  PetscInt every = 1;       // -output_every k
  std::string matrix_dir;   // -export_matrices DIR ("" = none)
};

// Collective. Reads -output -output_every -export_matrices.
PetscErrorCode ProcessOutputOptions(MPI_Comm comm, OutputOptions *options);

class ResultWriter {
 public:
  ResultWriter() = default;
  ResultWriter(const ResultWriter &) = delete;
  ResultWriter &operator=(const ResultWriter &) = delete;
  ~ResultWriter();

  // Collective. Creates the file and writes the mesh; fails on every rank when
  // rank 0 cannot create it. `like` is a PETSc-ordered DOF vector.
  PetscErrorCode Open(MPI_Comm comm, const std::string &path, const Scene &scene,
                      const DofLayout &layout, Vec like);
  // Collective. Appends one frame.
  PetscErrorCode WriteFrame(PetscReal time, Vec positions, Vec velocities,
                            const EnergySample &energy);
  // Collective. Writes the run's statistics as root attributes (name, value:
  // e.g. "loop_seconds"), marks the file complete, writes the .xdmf and closes.
  PetscErrorCode Close(const std::vector<std::pair<std::string, double>> &statistics);

  PetscInt frames() const { return static_cast<PetscInt>(times_.size()); }

 private:
  PetscErrorCode Gather(Vec dofs, Vec natural);

  MPI_Comm comm_ = MPI_COMM_NULL;
  PetscMPIInt rank_ = 0;
  std::string path_;
  hid_t file_ = -1;
  VecScatter to_natural_ = nullptr;  // PETSc-ordered free DOFs -> rank 0, all vertices
  Vec positions_ = nullptr, velocities_ = nullptr;  // rank 0: 3 V natural; others: empty
  int32_t num_vertices_ = 0;
  int64_t num_tets_ = 0;
  std::vector<double> times_;
};

// Collective. Writes DIR/M.bin, DIR/K.bin, DIR/D.bin (D = alpha M + beta K).
// K is the rest stiffness (in both modes).
PetscErrorCode ExportMatrices(const std::string &dir, const DofLayout &layout,
                              const LocalElements &elements, PetscReal shear_scale,
                              Vec lumped_mass, PetscReal alpha, PetscReal beta);

}  // namespace softbody
