#!/usr/bin/env python3
"""./run bench keeps working: the quick ladder (tools/bench.py at 1e4 tets).

1. The ladder's meshes are correct, independently of the generator: at about
   1e3, 1e4 and 1e5 tets (the 1e6 rung is the same code), every tet is
   positively oriented (det[X1-X0, X2-X0, X3-X0] > 0), the volumes sum to the
   beam's 4 m^3, the count is within 20 % of the target, every interior face is
   shared by exactly two tets with opposite orientation, and the MEDIT file and
   the scene read back to the same mesh, struck on its two end faces with zero
   total momentum.
2. The TetGen family's surface is the ellipsoid it claims: 162 vertices on the
   ellipsoid x^2/4 + y^2/9 + z^2/25 = 1 (to 1e-12), 320 triangles, every edge
   shared by two of them in opposite directions, enclosing a positive volume
   within 4 % of the ellipsoid's 40 pi m^3 (inscribed polyhedron).
3. Asked for 8 000 tets, the search for TetGen's volume bound meshes the
   ellipsoid with a count within 10 % of it.
4. The quick ladder (beam 1e4, TetGen volume bound 0.8 m^3) runs in both modes,
   with the direct, warp and GAMG presets, on 1 and 2 ranks, and writes
   bench.csv (one row per run, every run ok, every measured column positive)
   and bench.md (the table, the switches, the reference figures and the command
   that reproduces it). The TetGen rows have a mesh of 4 500-5 500 tets and 3-7
   tets per vertex; that mesh, read back from its .h5, has positively oriented
   tets whose volumes sum to the volume the OFF surface encloses (TetGen keeps
   the boundary, -p), and its scene strikes OFF vertices near both ends of the
   long axis with no net velocity.
No timing is asserted: the machine is shared.
"""
import argparse
import csv
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

TOOLS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools")
sys.path.insert(0, TOOLS)
import bench  # noqa: E402


def check_mesh(checks, target):
    vertices, tets, cells = bench.beam_mesh(target)
    X = vertices[tets]
    det = np.einsum("ij,ij->i", np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), X[:, 3] - X[:, 0])
    volume = np.prod(bench.BEAM_SIZE)
    checks.check(det.min() > 0, f"{target}: all {len(tets)} tets positively oriented (smallest det {det.min():.3g})")
    checks.check(abs(det.sum() / 6 - volume) <= 1e-12 * volume,
                 f"{target}: volumes sum to {det.sum() / 6:.15g} m^3 (beam {volume:g} m^3)")
    checks.check(abs(len(tets) / target - 1) <= 0.2, f"{target}: {len(tets)} tets within 20 % of the target")
    # Interior faces: each shared by two tets with opposite orientation.
    faces = tets[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    checks.check(counts.max() <= 2, f"{target}: no face shared by more than two tets")
    # Orientation of each face copy: rotated to start at its smallest vertex, (a, b, c)
    # and (a, c, b) are the two orientations; the two copies of an interior face differ.
    first = np.argmin(faces, axis=1)
    rows = np.arange(len(faces))
    b, c = faces[rows, (first + 1) % 3], faces[rows, (first + 2) % 3]
    orientation = (b < c).astype(np.int64)
    shared = counts[inverse] == 2
    order = np.argsort(inverse[shared], kind="stable")
    pairs = orientation[shared][order].reshape(-1, 2)
    checks.check(len(pairs) > 0 and bool(np.all(pairs[:, 0] != pairs[:, 1])),
                 f"{target}: the {len(pairs)} interior faces are shared with opposite orientations")
    nx, ny, nz = cells
    boundary = 2 * 2 * (nx * ny + ny * nz + nz * nx)
    checks.check(int((counts == 1).sum()) == boundary, f"{target}: {boundary} boundary faces")


def check_ellipsoid(checks):
    vertices, triangles = bench.ellipsoid_surface()
    a, b, c = bench.ELLIPSOID_SEMI_AXES
    level = (vertices[:, 0] / a) ** 2 + (vertices[:, 1] / b) ** 2 + (vertices[:, 2] / c) ** 2
    checks.check(len(vertices) == 162 and len(triangles) == 320 and abs(level - 1).max() < 1e-12,
                 f"ellipsoid: {len(vertices)} vertices on the ellipsoid, {len(triangles)} triangles")
    edges = {}
    for t in triangles:
        for k in range(3):
            edge = (int(t[k]), int(t[(k + 1) % 3]))
            edges[edge] = edges.get(edge, 0) + 1
    closed = all(n == 1 and edges.get((j, i)) == 1 for (i, j), n in edges.items())
    checks.check(closed and len(edges) == 2 * 480,
                 "ellipsoid: closed, every edge in two triangles, consistently oriented")
    X = vertices[triangles]
    volume = np.einsum("ij,ij->i", X[:, 0], np.cross(X[:, 1], X[:, 2])).sum() / 6
    exact = 4 / 3 * np.pi * a * b * c
    checks.check(0.96 * exact <= volume < exact, f"ellipsoid: encloses {volume:.4g} m^3 outward (smooth: {exact:.4g})")
    return volume


def check_tetgen_files(checks, study, surface_volume):
    import h5py
    folder = os.path.join(study, "meshes")
    scene = os.path.join(folder, "ellipsoid-a0.8.txt")
    mesh = os.path.join(folder, "ellipsoid-a0.8.h5")
    if not checks.check(os.path.isfile(scene) and os.path.isfile(mesh), "meshes/ellipsoid-a0.8.{h5,txt} written"):
        return
    with h5py.File(mesh, "r") as f:
        vertices, tets = f["vertices"][...], f["tets"][...]
    X = vertices[tets]
    det = np.einsum("ij,ij->i", np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), X[:, 3] - X[:, 0])
    checks.check(det.min() > 0 and abs(det.sum() / 6 - surface_volume) <= 1e-9 * surface_volume,
                 f"ellipsoid-a0.8.h5: {len(tets)} positive tets, volume {det.sum() / 6:.12g} m^3 = the surface's")
    surface, _ = bench.ellipsoid_surface()
    checks.check(np.array_equal(vertices[:len(surface)], surface), "ellipsoid-a0.8.h5: the OFF vertices come first")
    lines = [line.split() for line in open(scene) if line.strip() and not line.startswith("#")]
    count = int(lines[2][0])
    indices = np.array([int(line[1]) for line in lines[3:3 + count]])
    velocities = np.array([[float(x) for x in line[2:5]] for line in lines[3:3 + count]])
    z = surface[indices, 2] if count and indices.max() < len(surface) else np.zeros(1)
    ends = np.abs(z) >= (1 - 2 * bench.STRIKE_END_FRACTION) * bench.ELLIPSOID_SEMI_AXES[2]
    checks.check(count > 0 and bool(ends.all()) and abs(velocities.sum(axis=0)).max() < 1e-12
                 and np.allclose(np.abs(velocities[:, 1]), bench.STRIKE_SPEED),
                 f"scene strikes {count} surface vertices near the ends of z along y, no net velocity")


def check_search(checks, args, folder):
    os.makedirs(folder, exist_ok=True)
    surface = os.path.join(folder, "ellipsoid.off")
    bench.write_off(surface, *bench.ellipsoid_surface())
    options = argparse.Namespace(convert=os.path.join(os.path.dirname(os.path.abspath(args.softbody)),
                                                      "softbody-convert"), timeout=120)
    target = 8000
    bound, tets = bench.search_volume_bound(options, surface, target, os.path.join(folder, "search.h5"))
    checks.check(abs(tets / target - 1) <= 0.1, f"volume bound {bound:g} m^3 gives {tets} tets for {target}")


def main():
    args = harness.arguments()
    checks = harness.Checks()

    for target in (1000, 10000, 100000):
        check_mesh(checks, target)

    # The files the ladder writes read back to the same mesh and a struck beam.
    folder = os.path.join(args.work, "meshes")
    for name in os.listdir(folder) if os.path.isdir(folder) else []:
        os.remove(os.path.join(folder, name))
    scene = bench.write_beam(folder, 10000)
    vertices, _, _, tets = harness.read_medit(os.path.join(folder, "beam-10000.mesh"))
    expected_vertices, expected_tets, _ = bench.beam_mesh(10000)
    checks.check(np.array_equal(tets, expected_tets) and np.allclose(vertices, expected_vertices, rtol=0, atol=1e-15),
                 "beam-10000.mesh reads back to the generated mesh")
    lines = [line.split() for line in open(scene) if line.strip() and not line.startswith("#")]
    count = int(lines[2][0])
    velocities = np.array([[float(x) for x in line[2:5]] for line in lines[3:3 + count]])
    indices = np.array([int(line[1]) for line in lines[3:3 + count]])
    ends = (np.abs(vertices[indices, 0]) < 1e-12) | (np.abs(vertices[indices, 0] - bench.BEAM_SIZE[0]) < 1e-12)
    checks.check(count > 0 and ends.all() and abs(velocities[:, 2]).min() == bench.STRIKE_SPEED,
                 f"scene strikes {count} end-face vertices at {bench.STRIKE_SPEED} m/s")
    checks.check(abs(velocities.sum(axis=0)).max() < 1e-12, "the strike carries no net momentum (equal end faces)")

    surface_volume = check_ellipsoid(checks)
    check_search(checks, args, os.path.join(args.work, "search"))

    study = os.path.join(args.work, "bench")
    command = [sys.executable, os.path.join(TOOLS, "bench.py"), "-softbody", args.softbody, "-mpiexec",
               args.mpiexec, "-bench_tets", "1e4", "-bench_tetgen_volumes", "0.8", "-study_dir", study]
    result = subprocess.run(command, capture_output=True, text=True, timeout=540)
    print(result.stdout)
    if result.returncode != 0:
        print(result.stderr)
    checks.check(result.returncode == 0, "tools/bench.py -bench_tets 1e4 -bench_tetgen_volumes 0.8 exits 0")
    check_tetgen_files(checks, study, surface_volume)
    rows = []
    csv_path = os.path.join(study, "bench.csv")
    if os.path.isfile(csv_path):
        with open(csv_path, newline="") as f:
            rows = list(csv.DictReader(f))
    expected = {(mesh, m, s, r) for mesh in ("beam", "tetgen") for m in ("linear", "corotational")
                for s in ("direct", "cg-warp", "cg-gamg") for r in (1, 2)}
    seen = {(row["mesh"], row["mode"], row["solver"], int(row["ranks"])) for row in rows}
    checks.check(seen == expected and len(rows) == len(expected), f"bench.csv: {len(rows)} rows, one per run")
    for row in rows:
        label = f"{row['mesh']} {row['mode']} {row['solver']} {row['ranks']} rank(s)"
        if not checks.check(row["status"] == "ok", f"{label}: ran ({row['message']})"):
            continue
        positive = all(float(row[c]) > 0 for c in ("assemble_s", "factor_s", "step_s", "iterations", "peak_rss_mb",
                                                    "bandwidth_gbs", "bound_fraction", "matrix_nonzeros",
                                                    "assemble_rate"))
        tets, vertices = int(row["tets"]), int(row["vertices"])
        if row["mesh"] == "beam":
            checks.check(positive and tets == 10080 and vertices == 2232,
                         f"{label}: measured columns positive, 10080 tets, 2232 vertices")
        else:
            checks.check(positive and 4500 <= tets <= 5500 and 3 <= tets / vertices <= 7,
                         f"{label}: measured columns positive, {tets} tets (4500-5500), {vertices} vertices")
        if row["solver"] == "direct":
            checks.check(float(row["iterations"]) == 1 and float(row["factor_nonzeros"]) > float(row["matrix_nonzeros"]) / 2,
                         f"{label}: one solve per step with a factor of {float(row['factor_nonzeros']):.3g} nonzeros")
        if row["solver"] == "cg-warp" and row["mode"] == "corotational":
            checks.check(float(row["iterations"]) <= 8, f"{label}: {float(row['iterations']):.2f} iterations per step")
    md_path = os.path.join(study, "bench.md")
    text = open(md_path).read() if os.path.isfile(md_path) else ""
    checks.check("| mesh | tets | vertices | mode | solver | ranks |" in text and "Vega" in text
                 and "./run bench" in text and "| tetgen |" in text and "tetgen -pq1.414a0.8 " in text,
                 "bench.md holds the table with the TetGen rows, their switches, the reference figures and the command")
    checks.exit()


if __name__ == "__main__":
    main()
