// Mesh file readers. Not collective; throw InputError naming file and line.
#pragma once

#include <string>
#include <vector>

#include "fem/mesh.hpp"

namespace softbody {

// How closed OFF surfaces are turned into tetrahedra (see ReadOff).
struct MeshingOptions {
  // TetGen command-line switches without the leading '-' (TetGen's manual, section
  // 4.2): p = tetrahedralise the surface (required), q1.414 = radius-edge ratio
  // bound 1.414, Y = keep the surface triangulation, ... Checked by
  // CheckTetgenSwitches.
  std::string tetgen_switches = "pq1.414";
  // > 0: bound on every tetrahedron's volume, in the mesh file's units cubed
  // (adds TetGen's a<max_volume>); 0: no bound.
  double max_volume = 0;
};

// Empty when `switches` are usable as MeshingOptions::tetgen_switches, otherwise
// why not: they must contain 'p' and nothing but TetGen switch letters and their
// numbers; Q and V (softbody adds Q and keeps TetGen's log), and the switches that
// need input files softbody does not write (r, i, m, w), suppress the output it
// reads (N, E, I), remove surface vertices (R) or only detect intersections (d)
// are refused.
std::string CheckTetgenSwitches(const std::string &switches);

// Reads a tetrahedral mesh, choosing the reader from the extension: .mesh
// (ReadMedit), .off (ReadOff, meshed with `meshing`), .msh (ReadGmsh) or .h5 (a
// softbody mesh file, ReadMeshH5 in mesh_h5.hpp).
TetMesh ReadTetMesh(const std::string &path, const MeshingOptions &meshing = MeshingOptions());

// MEDIT .mesh: keywords `MeshVersionFormatted v`, `Dimension 3`, then sections
// `Vertices n` (n rows "x y z ref"), `Tetrahedra n` (n rows "a b c d ref",
// 1-based); other element sections (Triangles, Edges, ...) are read and ignored;
// `End` closes the file. Rejects out-of-range indices and degenerate tets.
TetMesh ReadMedit(const std::string &path);

// OFF surface: "OFF", then "nv nf [ne]" (ne is ignored), nv rows "x y z", nf rows
// "k i1 ... ik" (k >= 3 vertex indices, 0-based; anything after the k indices on
// the row, such as a colour, is ignored). The surface must be closed and must not
// intersect itself; its faces may be any planar polygons, in any orientation.
//
// The surface is tetrahedralised by the TetGen program (`tetgen` on PATH; Debian
// package tetgen), run as `tetgen -<switches>[a<max_volume>]JQ` on a .smesh file in
// a private temporary folder that is removed afterwards.
//
// \note Vertex order: the nv OFF vertices come first, in file order, then the
// points TetGen adds inside and on the surface. So vertex i < nv of the result is
// OFF vertex i (same coordinates, bit for bit), and velocities or constraints given
// by OFF vertex index keep their meaning. (TetGen with -p keeps its input points
// first and in order; J keeps the ones no tetrahedron uses, so an OFF vertex that
// no face uses and that lies outside the surface stays as a vertex of no
// tetrahedron. This is checked after every run.)
//
// Throws InputError "path:line: ..." for a malformed file (also for a vertex that
// repeats an earlier one, since TetGen would merge the two) and "path: ..." when
// TetGen is missing or fails, with TetGen's reason (for a self-intersecting surface,
// the intersecting faces found by `tetgen -d`; for an open one, that it encloses no
// volume), or when its output breaks the vertex-order promise above.
TetMesh ReadOff(const std::string &path, const MeshingOptions &meshing = MeshingOptions());

// The OFF surface as ReadOff reads and checks it, before TetGen runs.
struct OffSurface {
  std::vector<Eigen::RowVector3d> vertices;
  std::vector<long> vertex_lines;           // line of each vertex row
  std::vector<std::vector<int32_t>> faces;  // 0-based vertex indices, >= 3 each
};

// The first half of ReadOff: reads the OFF file and checks it as ReadOff does
// (throws the same InputErrors for a malformed file) without running TetGen.
OffSurface ReadOffSurface(const std::string &path);

// gmsh .msh, ASCII, format 2.2 (also 2.0, 2.1) or 4.1: `$MeshFormat`, `$Nodes`
// and `$Elements` sections; other sections ($PhysicalNames, $Entities, $Periodic,
// ...) are skipped. Keeps the 4-node tetrahedra (element type 4) and every node,
// also those no tetrahedron uses (such a vertex never moves); node tags map to
// 0-based indices in the order the nodes appear in the file. Binary files and
// other versions are rejected. Rejects unknown node tags, repeated node tags,
// degenerate tets and counts the file cannot hold.
TetMesh ReadGmsh(const std::string &path);

}  // namespace softbody
