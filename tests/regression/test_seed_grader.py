#!/usr/bin/env python3
"""The official coursework grader's reference data (../shared/seed-data/cggs-cw2).

Seed data only (skipped without ../shared): the references are the grader's.
The matrices and the integrator are checked against independent python
computations on the project's own meshes by test_energy.py (M, K, energies)
and the C++ unit tests (element stiffness, shear scale).

1. For every <mesh>-section1.data: a one-mesh scene (density 2.5, Young 10000,
   Poisson 0.3, free, identity placement) run on 2 ranks with -steps 0
   -shear_scale 0.25 -export_matrices: M, K and D must equal the reference to
   1e-9 relative (max abs difference / max abs reference entry).
2. fertility-scene.txt, 5 steps on 2 ranks: the last frame's velocities and
   positions must equal section2.data to 1e-8 relative. The coursework has no
   collisions, so this runs with -contact_guard 0: with the collision guard (the
   default) the vertex launched at 1000 m/s would not pass through its own
   statue's surface, as it does in the grader's trajectory (3 guard passes, 7
   colliding pairs), and the default run is checked to differ for that reason.
3. Negative controls (the comparisons can fail): with the default -shear_scale 1
   the stiffness and the 5-step state must NOT match (relative difference > 1e-3).
"""
import glob
import os
import shutil
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

MATRIX_TOLERANCE = 1e-9
STATE_TOLERANCE = 1e-8
CONTROL_MINIMUM = 1e-3
COMMON = ["-dt", 0.02, "-alpha", 0.1, "-beta", 0.1]

RECORD = np.dtype([("row", "<i4"), ("col", "<i4"), ("value", "<f8")])


def read_sections(path, layout):
    """Reads a grader file laid out as `layout` ('m' sparse matrix, 'v' vector)."""
    data = open(path, "rb").read()
    offset = 0
    items = []
    for kind in layout:
        if kind == "m":
            rows, cols, nnz = np.frombuffer(data, dtype="<i4", count=3, offset=offset)
            offset += 12
            records = np.frombuffer(data, dtype=RECORD, count=int(nnz), offset=offset)
            offset += int(nnz) * RECORD.itemsize
            items.append((records["row"].astype(np.int64), records["col"].astype(np.int64),
                          records["value"].astype(np.float64), (int(rows), int(cols))))
        else:
            (n,) = np.frombuffer(data, dtype="<i4", count=1, offset=offset)
            offset += 4
            items.append(np.frombuffer(data, dtype="<f8", count=int(n), offset=offset).copy())
            offset += int(n) * 8
    if offset != len(data):
        raise ValueError(f"{path}: {len(data) - offset} trailing bytes after layout {layout}")
    return items


def relative_matrix_difference(ours, reference):
    """max |ours - reference| / max |reference| over all entries (duplicates summed)."""
    (ro, co, vo, so), (rr, cr, vr, sr) = ours, reference
    if so != sr:
        return float("inf"), f"shape {so} != reference {sr}"
    keys = np.concatenate([ro * sr[1] + co, rr * sr[1] + cr])
    values = np.concatenate([vo, -vr])
    unique, inverse = np.unique(keys, return_inverse=True)
    difference = np.bincount(inverse, weights=values, minlength=len(unique))
    unique_r, inverse_r = np.unique(rr * sr[1] + cr, return_inverse=True)
    ref_summed = np.bincount(inverse_r, weights=vr, minlength=len(unique_r))
    scale = np.abs(ref_summed).max()
    return float(np.abs(difference).max() / scale), f"max |ref| {scale:.6g}"


def main():
    args = harness.arguments()
    checks = harness.Checks()
    folder = harness.seed(args, "cggs-cw2")
    references = sorted(glob.glob(os.path.join(folder, "*-section1.data")))
    checks.check(len(references) >= 10,
                 f"found {len(references)} *-section1.data reference files (expected >= 10)")

    # 1. Matrices of every reference mesh.
    for data_path in references:
        name = os.path.basename(data_path)[: -len("-section1.data")]
        mesh = os.path.join(folder, name + ".mesh")
        if not checks.check(os.path.exists(mesh), f"{name}: mesh {mesh} exists"):
            continue
        work = os.path.join(args.work, name)
        os.makedirs(work, exist_ok=True)
        scene = harness.write_scene(os.path.join(work, "scene.txt"),
                                    [(mesh, 2.5, 10000.0, 0.3, False, (0, 0, 0), (1, 0, 0, 0))])
        matrices = os.path.join(work, "matrices")
        shutil.rmtree(matrices, ignore_errors=True)  # no stale matrices from an earlier run
        harness.run(args, 2, ["-scene", scene, "-steps", 0, "-shear_scale", 0.25] + COMMON
                    + ["-export_matrices", matrices])
        reference = read_sections(data_path, "mmmv")
        for index, label in enumerate("MKD"):
            ours = harness.read_petsc_aij(os.path.join(matrices, f"{label}.bin"))
            error, note = relative_matrix_difference(ours, reference[index])
            checks.check(error <= MATRIX_TOLERANCE,
                         f"{name}: {label} relative difference {error:.3e} <= {MATRIX_TOLERANCE:g}"
                         f" ({reference[index][3][0]} rows, {note})")

    # Negative control: standard shear (s = 1) must not reproduce the grader's K.
    control = os.path.join(folder, "bunny-section1.data")
    if os.path.exists(control):
        work = os.path.join(args.work, "control-shear1")
        os.makedirs(work, exist_ok=True)
        scene = harness.write_scene(
            os.path.join(work, "scene.txt"),
            [(os.path.join(folder, "bunny.mesh"), 2.5, 10000.0, 0.3, False, (0, 0, 0), (1, 0, 0, 0))])
        matrices = os.path.join(work, "matrices")
        shutil.rmtree(matrices, ignore_errors=True)  # no stale matrices from an earlier run
        harness.run(args, 2, ["-scene", scene, "-steps", 0] + COMMON + ["-export_matrices", matrices])
        reference = read_sections(control, "mmmv")
        error, _ = relative_matrix_difference(
            harness.read_petsc_aij(os.path.join(matrices, "K.bin")), reference[1])
        checks.check(error > CONTROL_MINIMUM,
                     f"control: bunny K with default -shear_scale 1 differs by {error:.3e} "
                     f"(must be > {CONTROL_MINIMUM:g})")

    # 2. Trajectory: 5 steps of fertility-scene.txt against section2.data.
    scene = harness.seed(args, "cggs-cw2", "fertility-scene.txt")
    velocities_ref, positions_ref, _ = read_sections(
        harness.seed(args, "cggs-cw2", "section2.data"), "vvv")
    for shear, expect_match in ((0.25, True), (1.0, False)):
        out = os.path.join(args.work, f"f-shear{shear:g}.h5")
        options = ["-scene", scene, "-steps", 5] + COMMON + ["-output", out, "-contact_guard", 0]
        if shear != 1.0:
            options += ["-shear_scale", shear]
        harness.run(args, 2, options)
        frames = harness.read_frames(out)
        checks.check(len(frames["time"]) == 6 and abs(frames["time"][-1] - 0.1) < 1e-12,
                     f"shear {shear:g}: 6 frames, last at t = {frames['time'][-1]:.6g} s")
        velocities = frames["velocities"][-1].reshape(-1)
        positions = frames["positions"][-1].reshape(-1)
        ev = harness.relative_difference(velocities, velocities_ref)
        ex = harness.relative_difference(positions, positions_ref)
        absolute = (f"(max abs diff {np.abs(velocities - velocities_ref).max():.3e} of "
                    f"{np.abs(velocities_ref).max():.4g}; "
                    f"positions {np.abs(positions - positions_ref).max():.3e} of "
                    f"{np.abs(positions_ref).max():.4g})"
                    if velocities.shape == velocities_ref.shape
                    and positions.shape == positions_ref.shape else
                    f"(shape {velocities.shape} vs reference {velocities_ref.shape})")
        if expect_match:
            checks.check(ev <= STATE_TOLERANCE,
                         f"section2: velocities relative difference {ev:.3e} <= {STATE_TOLERANCE:g} {absolute}")
            checks.check(ex <= STATE_TOLERANCE,
                         f"section2: positions relative difference {ex:.3e} <= {STATE_TOLERANCE:g}")
        else:
            checks.check(ev > CONTROL_MINIMUM,
                         f"control: section2 velocities with -shear_scale 1 differ by {ev:.3e} "
                         f"(must be > {CONTROL_MINIMUM:g}) {absolute}")
    # The default (guard on) stops the launched vertex at its statue's surface.
    out = os.path.join(args.work, "f-guarded.h5")
    result = harness.run(args, 2, ["-scene", scene, "-steps", 5, "-shear_scale", 0.25, "-output", out] + COMMON)
    guarded = harness.read_frames(out)["velocities"][-1].reshape(-1)
    ev = harness.relative_difference(guarded, velocities_ref)
    checks.check(ev > CONTROL_MINIMUM and "colliding surface pairs" in result.stdout,
                 f"control: with the collision guard (default) section2 velocities differ by {ev:.3e} "
                 f"(must be > {CONTROL_MINIMUM:g}): the guard stopped a surface crossing")
    checks.exit()


if __name__ == "__main__":
    main()
