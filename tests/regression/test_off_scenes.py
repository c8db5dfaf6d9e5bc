#!/usr/bin/env python3
"""Scenes with OFF surfaces (tetrahedralised by TetGen on load) and gmsh meshes.

- tests/data/meshes/torus-scene.txt (one torus.off: a curved surface of genus 1,
  576 triangles), 2 ranks, 2 steps (the seed bunny.off scene is
  test_seed_off_scenes.py);
- tests/data/meshes/mixed-scene.txt: box_quads.off, cube.mesh, cube-4.1.msh and
  cube-2.2.msh (fixed), 2 ranks, 2 steps;
- the same with -tetgen_max_volume 0.01 and with -tetgen_switches pY;
- bad options and an open OFF surface: one error line, non-zero exit.

Expected vertex counts come from outside softbody: the OFF bodies' from running
the `tetgen` program here on a .smesh this script writes (same switches, plus J
and Q as softbody adds them), the others from counting the file's nodes. The
OFF vertices must be the body's first vertices, rigidly placed (identity
rotation: a constant shift).
"""
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

MESHES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "meshes")
STEPS = 2


def read_off(path):
    """Vertices (#V x 3) and faces (lists of 0-based indices) of an OFF file."""
    rows = []
    for line in open(path):
        line = line.split("#")[0].split()
        if line:
            rows.append(line)
    assert rows[0][0] == "OFF"
    rows[0] = rows[0][1:]
    if not rows[0]:
        rows.pop(0)
    nv, nf = int(rows[0][0]), int(rows[0][1])
    vertices = np.array([[float(x) for x in row[:3]] for row in rows[1:1 + nv]])
    faces = [[int(i) for i in row[1:1 + int(row[0])]] for row in rows[1 + nv:1 + nv + nf]]
    return vertices, faces


def tetgen_vertex_count(off, switches, folder):
    """Points of `tetgen -<switches>JQ` on the OFF surface, run here."""
    vertices, faces = read_off(off)
    smesh = os.path.join(folder, os.path.basename(off) + ".smesh")
    with open(smesh, "w") as f:
        f.write(f"{len(vertices)} 3 0 0\n")
        f.writelines(f"{i} {x!r} {y!r} {z!r}\n" for i, (x, y, z) in enumerate(vertices))
        f.write(f"{len(faces)} 0\n")
        f.writelines(f"{len(face)} " + " ".join(map(str, face)) + "\n" for face in faces)
        f.write("0\n0\n")
    subprocess.run(["tetgen", f"-{switches}JQ", smesh], check=True, capture_output=True, timeout=300)
    with open(smesh[:-len(".smesh")] + ".1.node") as f:
        return int(f.readline().split()[0])


def msh_node_count(path):
    lines = open(path).read().split("\n")
    header = lines[lines.index("$Nodes") + 1].split()
    return int(header[0] if len(header) == 1 else header[1])


def medit_vertex_count(path):
    tokens = open(path).read().split()
    return int(tokens[tokens.index("Vertices") + 1])


def tet_volumes(positions, tets):
    x = positions[tets]
    return np.linalg.det(np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=1)) / 6


def body_slices(frames):
    body = frames["mesh/vertex_body"]
    return [np.flatnonzero(body == b) for b in range(body.max() + 1)]


def check_run(checks, label, frames, expected_counts, off_bodies):
    """Frame count, per-body vertex counts, and OFF vertices first (rigid shift)."""
    checks.check(len(frames["time"]) == STEPS + 1, f"{label}: {len(frames['time'])} frames")
    slices = body_slices(frames)
    counts = [len(s) for s in slices]
    checks.check(counts == expected_counts, f"{label}: vertices per body {counts} (expected {expected_counts})")
    rest = frames["mesh/rest_positions"]
    for b, off in off_bodies:
        vertices, _ = read_off(off)
        first = slices[b][:len(vertices)]
        shift = rest[first] - vertices
        spread = np.abs(shift - shift[0]).max() / np.abs(vertices).max()
        checks.check(np.array_equal(first, slices[b][0] + np.arange(len(vertices))) and spread < 1e-12,
                     f"{label}: body {b}'s first {len(vertices)} vertices are {os.path.basename(off)}'s, "
                     f"shifted rigidly (spread {spread:.1e})")
    return slices


def expect_error(checks, args, label, options, expected):
    result = harness.run(args, 2, options, check=False)
    errors = [l for l in result.stderr.splitlines() if l.startswith("softbody: error:")]
    ok = result.returncode != 0 and len(errors) == 1 and expected in errors[0]
    checks.check(ok, f"{label}: exit {result.returncode}, {errors} contains {expected!r}")
    if not ok:
        print(result.stderr[-2000:])


def main():
    args = harness.arguments()
    checks = harness.Checks()
    folder = tempfile.mkdtemp(dir=args.work)

    # 1. A scene of our own mixing the three formats.
    mixed = os.path.join(MESHES, "mixed-scene.txt")
    box = os.path.join(MESHES, "box_quads.off")
    counts = [tetgen_vertex_count(box, "pq1.414", folder), medit_vertex_count(os.path.join(MESHES, "cube.mesh")),
              msh_node_count(os.path.join(MESHES, "cube-4.1.msh")), msh_node_count(os.path.join(MESHES, "cube-2.2.msh"))]
    out = os.path.join(args.work, "mixed.h5")
    harness.run(args, 2, ["-scene", mixed, "-steps", STEPS, "-output", out])
    frames = harness.read_frames(out)
    slices = check_run(checks, "mixed", frames, counts, [(0, box)])
    v0 = frames["velocities"][0]
    checks.check(np.array_equal(v0[slices[0][7]], [0, 0, 1]) and np.array_equal(v0[slices[2][44]], [0, 1, 0])
                 and np.abs(v0).sum() == 2,
                 "mixed: initial velocities on OFF vertex 7 and gmsh node 45 only")
    fixed = frames["positions"][:, slices[3]]
    checks.check(np.array_equal(fixed[-1], fixed[0]), "mixed: the fixed gmsh cube does not move")
    moved = np.abs(frames["positions"][-1][slices[0]] - frames["positions"][0][slices[0]]).max()
    checks.check(moved > 0, f"mixed: the OFF box moves ({moved:.3g} m)")

    # 2. -tetgen_max_volume and -tetgen_switches reach TetGen (the OFF body only).
    out = os.path.join(args.work, "mixed-fine.h5")
    harness.run(args, 2, ["-scene", mixed, "-steps", STEPS, "-output", out, "-tetgen_max_volume", 0.01])
    fine = harness.read_frames(out)
    fine_counts = [tetgen_vertex_count(box, "pq1.414a0.01", folder)] + counts[1:]
    fine_slices = check_run(checks, "max volume 0.01", fine, fine_counts, [(0, box)])
    rest, tets = fine["mesh/rest_positions"], fine["mesh/tets"]
    box_tets = tets[np.isin(tets[:, 0], fine_slices[0])]
    volumes = np.abs(tet_volumes(rest, box_tets))
    checks.check(len(box_tets) >= 100 and volumes.max() <= 0.01 * (1 + 1e-12) and abs(volumes.sum() - 1) < 1e-12,
                 f"max volume 0.01: {len(box_tets)} tets in the box, largest {volumes.max():.4g} m^3, "
                 f"total {volumes.sum():.15g} m^3")
    out = os.path.join(args.work, "mixed-Y.h5")
    harness.run(args, 2, ["-scene", mixed, "-steps", STEPS, "-output", out, "-tetgen_switches", "pY"])
    check_run(checks, "switches pY", harness.read_frames(out),
              [tetgen_vertex_count(box, "pY", folder)] + counts[1:], [(0, box)])

    # 3. Bad options and a bad surface: one line naming the option or the file.
    expect_error(checks, args, "switches with Q", ["-scene", mixed, "-tetgen_switches", "pq1.2Q"],
                 "option -tetgen_switches: 'Q' is not allowed")
    expect_error(checks, args, "switches without p", ["-scene", mixed, "-tetgen_switches", "q1.2"],
                 "option -tetgen_switches:")
    expect_error(checks, args, "negative volume", ["-scene", mixed, "-tetgen_max_volume", -1],
                 "option -tetgen_max_volume: must be >= 0")
    expect_error(checks, args, "volume not a number", ["-scene", mixed, "-tetgen_max_volume", "abc"],
                 "option -tetgen_max_volume: 'abc' is not a finite number")
    open_scene = harness.write_scene(os.path.join(folder, "open-scene.txt"),
                                     [(os.path.join(MESHES, "open_box.off"), 1000, 1e5, 0.3, 0, (0, 0, 0), (1, 0, 0, 0))])
    expect_error(checks, args, "open surface", ["-scene", open_scene], "open_box.off: TetGen")

    # 4. A curved surface of genus 1 (its tets must fill the torus, not its hole).
    torus = os.path.join(MESHES, "torus.off")
    frames = check_off_scene(checks, args, "torus", os.path.join(MESHES, "torus-scene.txt"), torus, folder)
    vertices, faces = read_off(torus)
    a, b, c = (vertices[[f[k] for f in faces]] for k in range(3))
    enclosed = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6  # divergence theorem, outward faces
    volumes = tet_volumes(frames["mesh/rest_positions"], frames["mesh/tets"])
    checks.check(volumes.min() > 0 and abs(volumes.sum() / enclosed - 1) < 1e-10,
                 f"torus: {len(volumes)} positive tets whose volumes sum to the surface's enclosed volume "
                 f"{enclosed:.12g} (relative difference {volumes.sum() / enclosed - 1:.1e}, < 1e-10)")
    checks.exit()


def check_off_scene(checks, args, label, scene, off, folder):
    """A one-body OFF scene, 2 ranks, STEPS steps: TetGen's vertex count, the OFF
    vertices first; returns the frames."""
    out = os.path.join(args.work, label + ".h5")
    result = harness.run(args, 2, ["-scene", scene, "-steps", STEPS, "-output", out])
    frames = harness.read_frames(out)
    check_run(checks, label, frames, [tetgen_vertex_count(off, "pq1.414", folder)], [(0, off)])
    summary = next((l.strip() for l in result.stdout.splitlines() if l.strip().startswith("scene")), "")
    print("   ", summary)
    return frames


if __name__ == "__main__":
    main()
