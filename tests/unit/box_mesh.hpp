// A structured box mesh for the unit tests: the same Kuhn split as tools/box_mesh.py.
#pragma once

#include <utility>

#include "fem/element.hpp"
#include "fem/mesh.hpp"

namespace softbody {

// A box of nx x ny x nz cells, 6 Kuhn tets each (as tools/box_mesh.py), edge h.
inline TetMesh BoxMesh(int nx, int ny, int nz, double h) {
  TetMesh mesh;
  mesh.vertices.resize((nx + 1) * (ny + 1) * (nz + 1), 3);
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i)
        mesh.vertices.row(i + (nx + 1) * (j + (ny + 1) * k)) << i * h, j * h, k * h;
  const int paths[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  mesh.tets.resize(6 * nx * ny * nz, 4);
  int t = 0;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        for (const auto &path : paths) {
          int corner[3] = {i, j, k}, v[4];
          v[0] = i + (nx + 1) * (j + (ny + 1) * k);
          for (int s = 0; s < 3; ++s) {
            ++corner[path[s]];
            v[s + 1] = corner[0] + (nx + 1) * (corner[1] + (ny + 1) * corner[2]);
          }
          TetPositions X;
          for (int a = 0; a < 4; ++a) X.row(a) = mesh.vertices.row(v[a]);
          if (SignedVolume(X) < 0) std::swap(v[1], v[2]);
          mesh.tets.row(t++) << v[0], v[1], v[2], v[3];
        }
  return mesh;
}

}  // namespace softbody
