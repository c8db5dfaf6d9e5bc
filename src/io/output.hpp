// Results on disk.
//
// HDF5 (natural vertex order, every vertex of every body, fixed ones included),
// written by all ranks together through MPI-IO (parallel_hdf5.hpp; a single
// rank uses HDF5's POSIX driver): rank r of P
// writes the rows of its natural slab, vertices [V r / P, V (r + 1) / P) and
// tets [T r / P, T (r + 1) / P), at their natural offsets; rank 0 writes the
// scalars and the .xdmf.
//   /time [F] (s), /positions [F][V][3] (m), /velocities [F][V][3] (m/s),
//   /energy/kinetic [F], /energy/elastic [F], /energy/gravitational [F] (J),
//   /mesh/tets [T][4], /mesh/boundary_triangles [B][3] (0-based natural vertex
//   indices), /mesh/vertex_body [V], /mesh/rest_positions [V][3],
//   /mesh/body_fixed [bodies] (1 for fixed bodies), /mesh/body_material
//   [bodies][3] (density kg/m^3, Young's modulus Pa, Poisson ratio);
//   /checkpoint (checkpoint.hpp).
// The frame datasets are chunked by one frame and at most kMaxChunkBytes of
// its rows. Frame 0 is the initial state. The file is flushed every
// -flush_every frames (default: every frame), and OUT.xdmf beside it (a
// ParaView time series of the deformed mesh with velocity and body index as
// point fields) is written when the file is opened and extended after every
// flush, listing only the frames already on disk: a run killed at any moment
// leaves a file and an .xdmf that open, with every frame up to the last flush
// listed. The file may hold up to -flush_every unlisted (possibly torn) frames
// beyond them, being written at the kill; -restart cuts them.
// Root attributes (rank 0's values, written by every rank): "complete" is 0
// until the run has finished (1); "interrupted" is the signal that stopped the
// run early (0: none); "gravity" [3] (m/s^2) and "ground_y" (m, only with a
// ground plane); then the run's statistics (set-up and loop seconds, solver
// iterations, ...).
//
// Matrices: PETSc binary files of M, K and D in the natural order of the free
// vertices' coordinates (xyzxyz).
#pragma once

#include <hdf5.h>
#include <petscmat.h>

#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "fem/assembly.hpp"
#include "fem/mesh_share.hpp"
#include "fem/partition.hpp"
#include "io/parallel_hdf5.hpp"
#include "io/scene.hpp"

namespace softbody {

struct OutputOptions {
  std::string path;          // -output FILE.h5 ("" = write nothing)
  PetscInt every = 1;        // -output_every k
  PetscInt flush_every = 1;  // -flush_every k: flush the file and extend the .xdmf every k frames
  std::string matrix_dir;    // -export_matrices DIR ("" = none)
};

// Collective. Reads -output -output_every -flush_every -export_matrices.
PetscErrorCode ProcessOutputOptions(MPI_Comm comm, OutputOptions *options);

// Collective. Fails (one line naming `option`) unless rank 0 could create or
// overwrite `path` and the .xdmf beside it: the folder exists and is writable,
// neither is a folder, and the name does not end in .xdmf. Creates nothing.
PetscErrorCode CheckOutputPath(MPI_Comm comm, const char *option, const std::string &path);

// Rank 0 collective: Bcasts rank 0's verdict, and every rank fails with the same
// user-facing message when rank 0 failed.
PetscErrorCode AgreeOnSuccess(MPI_Comm comm, bool ok, const std::string &message);

// Collective: every rank fails with the same user-facing message unless every
// rank succeeded (`ok` may differ between ranks).
PetscErrorCode AgreeOnAllRanks(MPI_Comm comm, bool ok, const std::string &message);

// Not collective. The body of each natural vertex of a slab (from the bodies' counts).
std::vector<int32_t> SlabVertexBodies(const Scene &scene, RowSlab vertices);

// Not collective. The share's tets as rows of 4 natural vertices (as the result
// file stores them).
std::vector<int32_t> ShareTetRows(const MeshShare &share);

// PETSc-ordered DOF vectors <-> natural-order vectors of every vertex, split in
// even slabs: rank r of P holds natural vertices [V r / P, V (r + 1) / P) (3
// values each, block size 3). Memory per rank: O(its slab + its owned DOFs).
// Collective except where noted.
class NaturalSlab {
 public:
  NaturalSlab() = default;
  NaturalSlab(const NaturalSlab &) = delete;
  NaturalSlab &operator=(const NaturalSlab &) = delete;
  ~NaturalSlab();

  // `like` is a PETSc-ordered DOF vector; the scatter is built from
  // layout.natural_of_owned (this rank's owned vertices only); the slab's rest
  // positions are copied from the share (whose vertex slab is this slab).
  PetscErrorCode Setup(const MeshShare &share, const DofLayout &layout, Vec like);
  // A natural vector: each rank's slab holds the rest positions (rest = true) or zeros.
  PetscErrorCode CreateVector(bool rest, Vec *natural) const;
  // natural <- dofs at the free vertices (the others keep their values).
  PetscErrorCode Gather(Vec dofs, Vec natural) const;
  // dofs <- natural (the values of the free vertices).
  PetscErrorCode Scatter(Vec natural, Vec dofs) const;
  // Not collective. Vertices of the scene, and this rank's slab of them (after Setup).
  int32_t num_vertices() const { return num_vertices_; }
  RowSlab vertices() const { return slab_; }

 private:
  int32_t num_vertices_ = 0;
  RowSlab slab_;
  std::vector<double> rest_;      // the slab's rest positions (m)
  VecScatter scatter_ = nullptr;  // PETSc-ordered free DOFs -> natural slabs of all vertices
  Vec natural_template_ = nullptr;
};

// A result file to continue (restart): its first `frames` frames are kept.
struct Continuation {
  std::string source;  // the restart file (may be the output path itself)
  PetscInt frames = 0;
};

class ResultWriter {
 public:
  ResultWriter() = default;
  ResultWriter(const ResultWriter &) = delete;
  ResultWriter &operator=(const ResultWriter &) = delete;
  ~ResultWriter();

  // Collective. Creates the file (every rank its slab of the mesh) with the
  // empty series, and rank 0 its .xdmf; fails on every rank when one cannot. With `continuation`,
  // the file starts with the continued file's first frames instead: the same file, cut back to them
  // (source == path), or a new file with a copy of them. `like` is a PETSc-ordered DOF vector.
  PetscErrorCode Open(MPI_Comm comm, const OutputOptions &options, const Scene &scene,
                      const DofLayout &layout, const MeshShare &share, Vec like,
                      const Continuation *continuation = nullptr);
  // Collective. Root attributes describing the world the bodies move in, for
  // readers such as tools/render.py: "gravity" (3 doubles, m/s^2) and, when
  // the scene has a ground plane, "ground_y" (m).
  PetscErrorCode WriteWorld(const double gravity[3], const double *ground_y);
  // Collective. A text attribute of the file's root (every rank gives the same value).
  PetscErrorCode WriteTextAttribute(const char *name, const std::string &value);
  // Collective. Appends one frame; flushes every options.flush_every frames.
  PetscErrorCode WriteFrame(PetscReal time, Vec positions, Vec velocities,
                            const EnergySample &energy);
  // Collective. Flushes the file, then extends the .xdmf by the frames written
  // since the last flush.
  PetscErrorCode Flush();
  // Collective. Writes the run's statistics as root attributes (name, value:
  // e.g. "loop_seconds"), "interrupted" (the signal that stopped the run, 0:
  // none) and "complete" (1 unless interrupted), flushes, completes the .xdmf
  // and closes.
  PetscErrorCode Close(const std::vector<std::pair<std::string, double>> &statistics,
                       int interrupted_by = 0);

  PetscInt frames() const { return static_cast<PetscInt>(times_.size()); }
  const std::string &path() const { return options_.path; }
  // The HDF5 file, open on every rank (MPI-IO): collective use only.
  hid_t file() const { return file_; }
  const NaturalSlab &natural_slab() const { return natural_; }
  MPI_Comm comm() const { return comm_; }

 private:
  PetscErrorCode CreateFile(const Scene &scene, const MeshShare &share, bool *created);
  PetscErrorCode WriteMesh(const Scene &scene, const MeshShare &share, bool *written);
  bool ContinueInPlace(const Continuation &continuation);
  bool CopyFrames(const Continuation &continuation);
  PetscErrorCode OpenXdmf();
  bool ExtendXdmf();

  MPI_Comm comm_ = MPI_COMM_NULL;
  PetscMPIInt rank_ = 0, size_ = 1;
  OutputOptions options_;
  hid_t file_ = -1;
  NaturalSlab natural_;
  Vec positions_ = nullptr, velocities_ = nullptr;  // natural slabs (3 values per vertex)
  int32_t num_vertices_ = 0;
  int64_t num_tets_ = 0;
  std::vector<double> times_;
  // The .xdmf (rank 0): frames it lists, and where its closing tags start.
  std::FILE *xdmf_ = nullptr;
  size_t xdmf_frames_ = 0;
  long xdmf_tail_ = 0;
};

// Collective. Writes DIR/M.bin, DIR/K.bin, DIR/D.bin (D = alpha M + beta K).
// K is the rest stiffness (in both modes).
PetscErrorCode ExportMatrices(const std::string &dir, const DofLayout &layout,
                              const LocalElements &elements, PetscReal shear_scale, Vec lumped_mass,
                              PetscReal alpha, PetscReal beta);

}  // namespace softbody
