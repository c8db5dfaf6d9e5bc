#!/usr/bin/env python3
"""./run bench keeps working: the quick ladder (tools/bench.py at 1e4 tets).

1. The ladder's meshes are correct, independently of the generator: at about
   1e3, 1e4 and 1e5 tets (the 1e6 rung is the same code), every tet is
   positively oriented (det[X1-X0, X2-X0, X3-X0] > 0), the volumes sum to the
   beam's 4 m^3, the count is within 20 % of the target, every interior face is
   shared by exactly two tets with opposite orientation, and the MEDIT file and
   the scene read back to the same mesh, struck on its two end faces with zero
   total momentum.
2. The 1e4 ladder runs in both modes, with the direct, warp and GAMG presets, on
   1 and 2 ranks, and writes bench.csv (one row per run, every run ok, every
   measured column positive) and bench.md (the table, the reference figures and
   the command that reproduces it).
"""
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

    study = os.path.join(args.work, "bench")
    command = [sys.executable, os.path.join(TOOLS, "bench.py"), "-softbody", args.softbody, "-mpiexec",
               args.mpiexec, "-bench_tets", "1e4", "-study_dir", study]
    result = subprocess.run(command, capture_output=True, text=True, timeout=540)
    print(result.stdout)
    if result.returncode != 0:
        print(result.stderr)
    checks.check(result.returncode == 0, "tools/bench.py -bench_tets 1e4 exits 0")
    rows = []
    csv_path = os.path.join(study, "bench.csv")
    if os.path.isfile(csv_path):
        with open(csv_path, newline="") as f:
            rows = list(csv.DictReader(f))
    expected = {(m, s, r) for m in ("linear", "corotational") for s in ("direct", "cg-warp", "cg-gamg") for r in (1, 2)}
    seen = {(row["mode"], row["solver"], int(row["ranks"])) for row in rows}
    checks.check(seen == expected and len(rows) == len(expected), f"bench.csv: {len(rows)} rows, one per run")
    for row in rows:
        label = f"{row['mode']} {row['solver']} {row['ranks']} rank(s)"
        if not checks.check(row["status"] == "ok", f"{label}: ran ({row['message']})"):
            continue
        positive = all(float(row[c]) > 0 for c in ("assemble_s", "factor_s", "step_s", "iterations", "peak_rss_mb",
                                                    "bandwidth_gbs", "bound_fraction", "matrix_nonzeros"))
        checks.check(positive and int(row["tets"]) == 10080 and int(row["vertices"]) == 2232,
                     f"{label}: measured columns positive, 10080 tets, 2232 vertices")
        if row["solver"] == "direct":
            checks.check(float(row["iterations"]) == 1 and float(row["factor_nonzeros"]) > float(row["matrix_nonzeros"]) / 2,
                         f"{label}: one solve per step with a factor of {float(row['factor_nonzeros']):.3g} nonzeros")
        if row["solver"] == "cg-warp" and row["mode"] == "corotational":
            checks.check(float(row["iterations"]) <= 8, f"{label}: {float(row['iterations']):.2f} iterations per step")
    md_path = os.path.join(study, "bench.md")
    text = open(md_path).read() if os.path.isfile(md_path) else ""
    checks.check("| tets | vertices | mode | solver | ranks |" in text and "Vega" in text and "./run bench" in text,
                 "bench.md holds the table, the reference figures and the command")
    checks.exit()


if __name__ == "__main__":
    main()
