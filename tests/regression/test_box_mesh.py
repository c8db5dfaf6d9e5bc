"""tools/box_mesh.py: structured box meshes are valid, conforming and run.

Generates a few meshes into the work folder, reads them back with a MEDIT
reader of its own and checks, independently of the generator: positive tet
volumes summing to Lx Ly Lz, every interior face shared by exactly two tets,
2 x 2 x (nx ny + ny nz + nz nx) boundary faces, equal to the file's Triangles
and oriented outward, Euler characteristic V - E + F - T = 1, --tets N within
a factor 1.5 of N; then runs softbody on one of them (2 ranks, 3 steps).
"""
import os
import subprocess
import sys

import numpy as np

import harness

TOOL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools", "box_mesh.py")


def generate(path, size, cells=None, tets=None, spelling=("-box_size", "-box_cells", "-box_tets")):
    """Runs tools/box_mesh.py; `spelling` names its three options (PETSc style by default)."""
    size_option, cells_option, tets_option = spelling
    command = [sys.executable, TOOL, path, size_option] + [repr(float(s)) for s in size]
    command += [cells_option] + [str(n) for n in cells] if cells else [tets_option, str(tets)]
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    if result.returncode != 0:
        print("command failed:", " ".join(command))
        print(result.stdout, result.stderr)
        sys.exit(1)
    return result.stdout


def read_medit(path):
    """Vertices (#V x 3), triangles (#B x 3, 0-based), their refs (#B), tets (#T x 4, 0-based).
    Stricter than softbody_tools.read_medit, as a test of the writer: the vertex and
    tet refs must be 0."""
    tokens = open(path).read().split()
    sections, pos = {}, 0
    widths = {"Vertices": 4, "Triangles": 4, "Tetrahedra": 5}
    while pos < len(tokens):
        word = tokens[pos]
        pos += 1
        if word == "End":
            break
        if word in ("MeshVersionFormatted", "Dimension"):
            pos += 1
        elif word in widths:
            n = int(tokens[pos])
            pos += 1
            rows = np.array(tokens[pos:pos + n * widths[word]], dtype=float).reshape(n, widths[word])
            pos += n * widths[word]
            sections[word] = rows
        else:
            raise ValueError(f"{path}: unexpected keyword {word}")
    vertices = sections["Vertices"][:, :3]
    triangles = sections["Triangles"][:, :3].astype(np.int64) - 1
    tets = sections["Tetrahedra"][:, :4].astype(np.int64) - 1
    assert np.all(sections["Vertices"][:, 3] == 0) and np.all(sections["Tetrahedra"][:, 4] == 0)
    refs = sections["Triangles"][:, 3].astype(np.int64)
    return vertices, triangles, refs, tets


def unique_rows(rows):
    """Sorted unique rows and how often each occurs."""
    return np.unique(np.sort(rows, axis=1), axis=0, return_counts=True)


def check_mesh(checks, name, path, size, cells):
    vertices, triangles, refs, tets = read_medit(path)
    nx, ny, nz = cells
    V, T = len(vertices), len(tets)
    checks.check(V == (nx + 1) * (ny + 1) * (nz + 1) and T == 6 * nx * ny * nz,
                 f"{name}: {V} vertices, {T} tets for {nx}x{ny}x{nz} cells")
    checks.check(tets.min() >= 0 and tets.max() < V and triangles.min() >= 0 and triangles.max() < V,
                 f"{name}: indices within 1..{V}")
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    checks.check(np.allclose(lo, 0, rtol=0, atol=1e-15) and np.allclose(hi, size, rtol=1e-15, atol=0),
                 f"{name}: vertices span [0,{size[0]}]x[0,{size[1]}]x[0,{size[2]}]")

    X = vertices[tets]
    det = np.einsum("ij,ij->i", np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), X[:, 3] - X[:, 0])
    volume = det / 6
    cell_volume = size[0] * size[1] * size[2] / (nx * ny * nz)
    checks.check(volume.min() > 0, f"{name}: every tet positively oriented "
                                   f"(min volume {volume.min():.3g} m^3, cell/6 {cell_volume / 6:.3g})")
    total = volume.sum()
    box = size[0] * size[1] * size[2]
    checks.check(abs(total - box) <= 1e-12 * box, f"{name}: volumes sum to {total!r} = Lx Ly Lz = {box!r}")

    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]], tets[:, [0, 1, 2]]])
    unique_faces, face_count = unique_rows(faces)
    expected_boundary = 2 * 2 * (nx * ny + ny * nz + nz * nx)
    checks.check(face_count.max() <= 2, f"{name}: no face belongs to more than two tets")
    boundary = unique_faces[face_count == 1]
    checks.check(len(boundary) == expected_boundary,
                 f"{name}: {len(boundary)} faces in one tet, expected 2*2*(nx ny + ny nz + nz nx) "
                 f"= {expected_boundary}")
    # A face in one tet must lie on the box surface: otherwise the mesh is not conforming.
    centroid = vertices[boundary].mean(axis=1)
    on_surface = np.any((np.abs(centroid) < 1e-12) | (np.abs(centroid - size) < 1e-12 * max(size)), axis=1)
    checks.check(bool(np.all(on_surface)), f"{name}: every face of one tet lies on the box surface "
                                           "(interior faces are shared by exactly two tets)")

    file_faces, file_count = unique_rows(triangles)
    checks.check(len(triangles) == expected_boundary and file_count.max() == 1
                 and np.array_equal(file_faces, boundary),
                 f"{name}: the file's {len(triangles)} Triangles are exactly the boundary faces")
    A, B, C = (vertices[triangles[:, c]] for c in range(3))
    normal = np.cross(B - A, C - A)
    outward = np.einsum("ij,ij->i", normal, (A + B + C) / 3 - np.asarray(size) / 2)
    checks.check(outward.min() > 0, f"{name}: every boundary triangle oriented outward")
    # Triangle refs name the side: 1 x=0, 2 x=Lx, 3 y=0, 4 y=Ly, 5 z=0, 6 z=Lz.
    axis, upper = (refs - 1) // 2, (refs - 1) % 2
    plane = np.where(upper == 1, np.asarray(size)[np.clip(axis, 0, 2)], 0.0)
    on_side = np.all(np.abs(np.stack([A, B, C])[:, np.arange(len(refs)), np.clip(axis, 0, 2)] - plane)
                     <= 1e-12 * max(size), axis=0)
    checks.check(bool(np.all((refs >= 1) & (refs <= 6) & on_side)),
                 f"{name}: triangle refs 1..6 name the side of the box each lies on")
    area = np.linalg.norm(normal, axis=1).sum() / 2
    surface = 2 * (size[0] * size[1] + size[1] * size[2] + size[2] * size[0])
    checks.check(abs(area - surface) <= 1e-12 * surface, f"{name}: boundary area {area!r} = {surface!r}")

    edges = np.concatenate([tets[:, [a, b]] for a in range(4) for b in range(a + 1, 4)])
    E = len(unique_rows(edges)[0])
    F = len(unique_faces)
    checks.check(V - E + F - T == 1, f"{name}: Euler characteristic V - E + F - T = "
                                     f"{V} - {E} + {F} - {T} = {V - E + F - T} (expected 1)")
    return vertices, tets


def main():
    args = harness.arguments()
    checks = harness.Checks()
    work = os.path.abspath(args.work)

    cases = [("unit", (1.0, 1.0, 1.0), (1, 1, 1)),
             ("slab", (2.0, 0.5, 0.25), (3, 2, 1)),
             ("beam", (4.0, 1.0, 1.0), (8, 3, 2)),
             ("box", (0.3, 0.7, 1.1), (4, 5, 6))]
    meshes = {}
    for name, size, cells in cases:
        path = os.path.join(work, name + ".mesh")
        generate(path, size, cells=cells)
        meshes[name] = check_mesh(checks, name, path, size, cells)

    for size, target in [((4.0, 1.0, 1.0), 50), ((4.0, 1.0, 1.0), 3000), ((1.0, 1.0, 1.0), 1000),
                         ((2.0, 1.0, 0.1), 5000), ((1.0, 3.0, 2.0), 20000)]:
        path = os.path.join(work, "target.mesh")
        generate(path, size, tets=target)
        vertices, _, _, tets = read_medit(path)
        checks.check(target / 1.5 <= len(tets) <= target * 1.5,
                     f"-box_size {size} -box_tets {target}: {len(tets)} tets (within a factor 1.5)")
        # The chosen cell counts, recovered from the vertex coordinates.
        cells = tuple(len(np.unique(vertices[:, c])) - 1 for c in range(3))
        check_mesh(checks, f"tets{target}", path, size, cells)

    # scenes/beam.mesh is what scenes/README.md says generated it.
    committed = os.path.join(os.path.dirname(TOOL), "..", "scenes", "beam.mesh")
    if os.path.exists(committed):
        path = os.path.join(work, "scenes-beam.mesh")
        for spelling in (("-box_size", "-box_cells", "-box_tets"), ("--box-size", "--box-cells", "--box-tets"),
                         ("--size", "--cells", "--tets")):
            generate(path, (4, 1, 1), cells=(24, 6, 6), spelling=spelling)
            with open(path, "rb") as a, open(committed, "rb") as b:
                checks.check(a.read() == b.read(), f"scenes/beam.mesh = box_mesh.py {spelling[0]} 4 1 1 "
                                                   f"{spelling[1]} 24 6 6, byte for byte")

    # The program accepts a generated mesh and runs it; vertex 8 = (i, j, k) = (8, 0, 0)
    # is a corner of the beam's x = Lx end.
    scene = harness.write_scene(os.path.join(work, "beam-scene.txt"),
                                [("beam.mesh", 1000.0, 1e5, 0.45, False, (0, 0, 0), (1, 0, 0, 0))],
                                [(0, 8, (0.0, 0.0, 1.0))])
    h5 = os.path.join(work, "beam.h5")
    result = harness.run(args, 2, ["-scene", scene, "-steps", "3", "-output", h5])
    checks.check(result.returncode == 0 and os.path.exists(h5), "softbody runs the generated beam on 2 ranks")
    frames = harness.read_frames(h5)
    positions = frames["positions"]
    vertices = meshes["beam"][0]
    checks.check(positions.shape[1:] == vertices.shape and len(positions) == 4
                 and np.all(np.isfinite(positions)),
                 f"output: {len(positions)} frames of {positions.shape[1]} vertices, finite")
    rest = frames["mesh/rest_positions"]
    checks.check(np.allclose(rest, vertices - np.array([2.0, 0.5, 0.5]), rtol=0, atol=1e-12),
                 "output: rest positions = the mesh moved by minus the box centre (its centroid)")
    moved = np.abs(positions[-1] - positions[0]).max()
    checks.check(moved > 0, f"output: the struck beam moved ({moved:.3g} m)")
    checks.exit()


if __name__ == "__main__":
    main()
