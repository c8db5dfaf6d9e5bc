// The softbody HDF5 mesh file (.h5): a tetrahedral mesh that all ranks can read
// in slabs with parallel HDF5 (MPI-IO), written by `softbody-convert` from a
// .mesh, .msh or .off file.
//
// Format (version 1):
//   /vertices  [V][3] float64, vertex positions (m)
//   /tets      [T][4] int64, 0-based vertex indices (64 bits: no overflow at any T)
//   root attributes: format = "softbody-mesh" (string), version = 1 (int64),
//                    source = the file it was converted from (string)
// Both datasets are chunked in blocks of whole rows of at most kMeshChunkBytes, so
// a slab of rows is read as a few large requests. V >= 1 and T >= 1; no tet is
// degenerate (checked when written). The vertex order is the source's (for .off,
// ReadOff's order: the OFF vertices first, then TetGen's), so velocity and
// constraint indices keep their meaning.
#pragma once

#include <mpi.h>
#include <petscsys.h>

#include <Eigen/Core>
#include <cstdint>
#include <string>

#include "fem/mesh.hpp"
#include "io/parallel_hdf5.hpp"

namespace softbody {

constexpr char kMeshFormatName[] = "softbody-mesh";  // the root attribute `format`
constexpr int64_t kMeshFormatVersion = 1;            // the root attribute `version`

// Upper bound of a chunk of /vertices or /tets: 1 MiB holds 43 690 vertex rows or
// 32 768 tet rows, so a rank's slab of a large mesh is a few dozen large
// contiguous reads, the chunk index stays small (1e9 tets: ~1e5 chunks), and the
// chunk fits HDF5's default 1 MiB chunk cache, far below its 4 GiB chunk limit.
constexpr size_t kMeshChunkBytes = kMaxChunkBytes;  // parallel_hdf5.hpp

// Not collective (one process writes). Writes `mesh` to `path` in the format
// above, recording `source` as the file it came from. The file is written under a
// temporary name in the same folder and renamed to `path` only when complete, so
// a failed write leaves no file at `path` (an older file there is replaced only by
// a complete one). `chunk_rows` > 0 caps the rows per chunk below
// kMeshChunkBytes (tests use it to get many chunks from a small mesh).
// Throws InputError "path: ..." when the file cannot be written, or when the mesh
// is empty or has an out-of-range index or a degenerate tet.
void WriteMeshH5(const std::string &path, const TetMesh &mesh, const std::string &source,
                 size_t chunk_rows = 0);

struct MeshCounts {
  int64_t vertices = 0, tets = 0;
};

// Not collective. The vertex and tet counts of a softbody mesh file, checked as
// ReadMeshH5 checks the file's format and counts (the rows are not read).
// Throws InputError "path: ...".
MeshCounts ReadMeshH5Counts(const std::string &path);

// Not collective. Reads a whole softbody mesh file (the replicated path: every
// rank that calls it holds the whole mesh). Checks what ReadMeshSlabs checks, plus
// that no tet is degenerate and that the counts fit TetMesh's 32-bit indices.
// Throws InputError "path: ..." naming what is wrong.
TetMesh ReadMeshH5(const std::string &path);

// One rank's share of a softbody mesh file: its block of tet rows and its block of
// vertex rows (not the vertices of its tets: these come from their owners).
struct MeshSlabs {
  int64_t num_vertices = 0;  // V, global
  int64_t num_tets = 0;      // T, global
  int64_t first_vertex = 0;  // global row of vertices.row(0): floor(V r / P)
  int64_t first_tet = 0;     // global row of tets.row(0): floor(T r / P)
  // rows [first_vertex, floor(V (r + 1) / P)) of /vertices (m); may be empty
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> vertices;
  // rows [first_tet, floor(T (r + 1) / P)) of /tets, 0-based global vertex
  // indices, each in [0, V); may be empty
  Eigen::Matrix<int64_t, Eigen::Dynamic, 4, Eigen::RowMajor> tets;
};

// Collective on comm. Rank r of P reads its slabs (rows floor(N r / P) up to
// floor(N (r + 1) / P) of each dataset) with parallel HDF5: MPI-IO file access and
// collective hyperslab reads. Every rank checks its part and the ranks agree by
// reduction, so on bad input all of them return the same PETSC_ERR_USER_INPUT
// error, one line naming the file: missing or not an HDF5 file, not a softbody
// mesh (attributes format and version), a missing dataset or wrong shape or type,
// no vertices or no tets, a vertex index out of range in any rank's tets.
// Degenerate tets are not checked here (a rank does not hold its tets' corner
// coordinates); the consumer checks them with CheckTetVolumes once it has them.
PetscErrorCode ReadMeshSlabs(MPI_Comm comm, const std::string &path, MeshSlabs *slabs);

// Collective on comm. Checks that none of this rank's tets (global rows first_tet
// + t) is degenerate (|volume| <= kDegenerateVolume longest_edge^3, as every mesh
// reader checks), given `corners`, 4 rows per tet: the positions (m) of the tet's
// corners in order. On failure every rank returns the same PETSC_ERR_USER_INPUT
// error naming `path` and the first degenerate tet (1-based, as the text readers).
PetscErrorCode CheckTetVolumes(
    MPI_Comm comm, const std::string &path, int64_t first_tet,
    const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> &corners);

}  // namespace softbody
