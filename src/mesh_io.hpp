// Mesh file readers. Not collective; throw InputError naming file and line.
#pragma once

#include <string>

#include "mesh.hpp"

namespace softbody {

// Reads a tetrahedral mesh, choosing the reader from the extension (.mesh).
TetMesh ReadTetMesh(const std::string &path);

// MEDIT .mesh: keywords `MeshVersionFormatted v`, `Dimension 3`, then sections
// `Vertices n` (n rows "x y z ref"), `Tetrahedra n` (n rows "a b c d ref",
// 1-based); other element sections (Triangles, Edges, ...) are read and ignored;
// `End` closes the file. Rejects out-of-range indices and degenerate tets.
TetMesh ReadMedit(const std::string &path);

}  // namespace softbody
