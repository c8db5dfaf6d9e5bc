#!/usr/bin/python3
"""Structured tetrahedral mesh of a box, written as a MEDIT .mesh file.

The box [0,Lx] x [0,Ly] x [0,Lz] is cut into nx x ny x nz hexahedral cells and
every cell into 6 tetrahedra by the Kuhn (Freudenthal) split: all six share the
cell's main diagonal from its corner (i,j,k) to its corner (i+1,j+1,k+1), and
each follows one monotone path along the cell's edges between those corners.
Every cell is split the same way, so the faces of neighbouring cells match
(the mesh is conforming), and the mesh is symmetric under the point reflection
through the box centre.

Numbering (0-based; the file is 1-based):
  vertex (i, j, k), 0 <= i <= nx, ... has index i + (nx+1) * (j + (ny+1) * k)
  at (i Lx/nx, j Ly/ny, k Lz/nz): x varies fastest, then y, then z.
  Every tet is positively oriented: det[X1-X0, X2-X0, X3-X0] > 0.

File sections: Vertices (ref 0), Triangles (the boundary faces, oriented with
outward normals (b-a) x (c-a); ref = side of the box: 1 x=0, 2 x=Lx, 3 y=0,
4 y=Ly, 5 z=0, 6 z=Lz), Tetrahedra (ref 0), End.

Usage:
  box_mesh.py OUT.mesh -box_size 4 1 1 -box_cells 24 6 6
  box_mesh.py OUT.mesh -box_size 4 1 1 -box_tets 5000
(--box-size, --box-cells, --box-tets and the older --size, --cells, --tets work too.)
Only numpy is needed (Debian's /usr/bin/python3 + python3-numpy); a million
tets take a few seconds.
"""
import argparse
import itertools
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from softbody_tools import ToolParser, add_option  # noqa: E402

# The six Kuhn tets of the unit cube: (0,0,0) -> +e_a -> +e_b -> +e_c = (1,1,1)
# for every permutation (a, b, c) of the axes; odd permutations are negatively
# oriented, so their middle two vertices are swapped.
def _kuhn_tets():
    tets = []
    for perm in itertools.permutations(range(3)):
        corner = [0, 0, 0]
        path = [tuple(corner)]
        for axis in perm:
            corner[axis] = 1
            path.append(tuple(corner))
        inversions = sum(1 for a in range(3) for b in range(a + 1, 3) if perm[a] > perm[b])
        if inversions % 2:
            path[1], path[2] = path[2], path[1]
        tets.append(path)
    return np.array(tets, dtype=np.int64)  # 6 x 4 x 3 corner offsets (0/1)


KUHN = _kuhn_tets()
# Faces of a positively oriented tet (0,1,2,3) with outward normals.
OUTWARD_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)


def box_mesh(size, cells):
    """Returns (vertices #V x 3 float64, tets #T x 4 int64, 0-based)."""
    nx, ny, nz = cells
    lx, ly, lz = size
    xs = np.linspace(0.0, lx, nx + 1)
    ys = np.linspace(0.0, ly, ny + 1)
    zs = np.linspace(0.0, lz, nz + 1)
    # Index order i fastest: meshgrid with indexing="ij" over (z, y, x), then reverse columns.
    zz, yy, xx = np.meshgrid(zs, ys, xs, indexing="ij")
    vertices = np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])

    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()                  # one entry per cell
    # Vertex index of cell corner + offset (di, dj, dk), for the 6 x 4 Kuhn corners.
    offsets = KUHN[..., 0] + (nx + 1) * (KUHN[..., 1] + (ny + 1) * KUHN[..., 2])  # 6 x 4
    base = i + (nx + 1) * (j + (ny + 1) * k)                   # cells
    tets = (base[:, None, None] + offsets[None, :, :]).reshape(-1, 4)
    return vertices, tets


def boundary_faces(tets, num_vertices):
    """Faces that belong to exactly one tet, oriented outward (needs positive tets)."""
    faces = tets[:, OUTWARD_FACES].reshape(-1, 3)
    key_rows = np.sort(faces, axis=1)
    if num_vertices ** 3 < 2 ** 62:
        keys = (key_rows[:, 0] * num_vertices + key_rows[:, 1]) * num_vertices + key_rows[:, 2]
        order = np.argsort(keys, kind="stable")
        sorted_keys = keys[order]
        same_next = sorted_keys[1:] == sorted_keys[:-1]
    else:
        order = np.lexsort((key_rows[:, 2], key_rows[:, 1], key_rows[:, 0]))
        s = key_rows[order]
        same_next = np.all(s[1:] == s[:-1], axis=1)
    unique = np.ones(len(order), dtype=bool)
    unique[1:] &= ~same_next
    unique[:-1] &= ~same_next
    return faces[np.sort(order[unique])]


def side_of_faces(vertices, faces, size):
    """Box side (1..6, see the module doc) of each boundary face."""
    centroid = vertices[faces].mean(axis=1)
    side = np.zeros(len(faces), dtype=np.int64)
    tol = 1e-9 * max(size)
    for axis in range(3):
        side[np.abs(centroid[:, axis]) <= tol] = 2 * axis + 1
        side[np.abs(centroid[:, axis] - size[axis]) <= tol] = 2 * axis + 2
    assert np.all(side > 0), "a boundary face is on no side of the box"
    return side


def cells_for_tets(size, target):
    """nx, ny, nz with 6 nx ny nz close to target and cells as cubic as possible.

    The axes are decided one at a time, shortest ideal count first: for the
    ideal cube edge h of the axes still open, the axis gets floor or ceil of
    L / h cells (at least 1), and the remaining axes are re-fitted to the cells
    left. Of the (at most 8) results, the one with the least
    |log(count / target)| + log(longest cell edge / shortest) / 4 wins."""
    size = [float(s) for s in size]
    results = []

    def fit(chosen, cells_left):
        open_axes = [a for a in range(3) if a not in chosen]
        if not open_axes:
            cells = [chosen[a] for a in range(3)]
            steps = [size[a] / cells[a] for a in range(3)]
            count = 6 * math.prod(cells)
            cost = abs(math.log(count / target)) + 0.25 * math.log(max(steps) / min(steps))
            results.append((cost, cells))
            return
        h = (math.prod(size[a] for a in open_axes) / max(cells_left, 1.0)) ** (1.0 / len(open_axes))
        axis = min(open_axes, key=lambda a: size[a] / h)
        ideal = size[axis] / h
        for n in sorted({max(1, math.floor(ideal)), max(1, math.ceil(ideal))}):
            fit({**chosen, axis: n}, cells_left / n)

    fit({}, target / 6.0)
    return min(results)[1]


def write_medit(path, vertices, tets, faces, refs):
    """MEDIT .mesh, 1-based indices; coordinates printed as shortest round-trip reprs."""
    with open(path, "w") as f:
        f.write("MeshVersionFormatted 1\n\nDimension 3\n\n")
        f.write(f"Vertices\n{len(vertices)}\n")
        f.write(("%r %r %r 0\n" * len(vertices)) % tuple(vertices.ravel().tolist()))
        f.write(f"\nTriangles\n{len(faces)}\n")
        tri = np.column_stack([faces + 1, refs])
        f.write(("%d %d %d %d\n" * len(tri)) % tuple(tri.ravel().tolist()))
        f.write(f"\nTetrahedra\n{len(tets)}\n")
        f.write(("%d %d %d %d 0\n" * len(tets)) % tuple((tets + 1).ravel().tolist()))
        f.write("\nEnd\n")


def main(argv=None):
    parser = ToolParser(
        allow_abbrev=False,
        description="Structured tetrahedral mesh of the box [0,Lx]x[0,Ly]x[0,Lz] "
                    "(6 Kuhn tets per hexahedral cell), written as MEDIT .mesh.")
    parser.add_argument("output", metavar="OUT.mesh", help="MEDIT file to write")
    add_option(parser, "box_size", "--size", dest="size", nargs=3, type=float, metavar=("LX", "LY", "LZ"),
               default=[1.0, 1.0, 1.0], help="box edge lengths in metres (default 1 1 1)")
    group = parser.add_mutually_exclusive_group(required=True)
    add_option(group, "box_cells", "--cells", dest="cells", nargs=3, type=int, metavar=("NX", "NY", "NZ"),
               help="number of hexahedral cells along x, y, z (6 tets each)")
    add_option(group, "box_tets", "--tets", dest="tets", type=int, metavar="N",
               help="choose the cells for about N tets, with cells as close to cubes as possible")
    args = parser.parse_args(argv)

    size = args.size
    if not all(s > 0 and math.isfinite(s) for s in size):
        parser.error("-box_size: every edge length must be positive")
    if args.cells is not None:
        cells = args.cells
        if not all(n >= 1 for n in cells):
            parser.error("-box_cells: every count must be >= 1")
    else:
        if args.tets < 1:
            parser.error("-box_tets: N must be >= 1")
        cells = cells_for_tets(size, args.tets)

    vertices, tets = box_mesh(size, cells)
    if len(vertices) > 2 ** 31 - 1:
        parser.error("too many vertices for 32-bit indices")
    faces = boundary_faces(tets, len(vertices))
    refs = side_of_faces(vertices, faces, size)
    write_medit(args.output, vertices, tets, faces, refs)
    print(f"{args.output}: box {size[0]:g} x {size[1]:g} x {size[2]:g} m, "
          f"cells {cells[0]} x {cells[1]} x {cells[2]}, "
          f"{len(vertices)} vertices, {len(faces)} boundary triangles, {len(tets)} tetrahedra")
    return 0


if __name__ == "__main__":
    sys.exit(main())
