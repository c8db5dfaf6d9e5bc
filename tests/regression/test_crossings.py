#!/usr/bin/env python3
"""softbody-crossings, the exact checker of result files (src/crossings, docs/contact-crossings.md).

Synthetic result files written with h5py, whose counts are known by construction:
(a) two unit corner tets, body B = body A moved by (0.2, 0.2, 0.2): they
    interpenetrate (free-free > 0, the count equal to an independent exact count,
    exact_triangles.py); moved by (3, 0, 0): 0; B = -A, touching A only at the
    origin: exactly 9 pairs (the 3 faces of each tet through the origin), because
    triangles are closed (touching is crossing). With A fixed (fixed bodies never
    move: the checker reads them from frame 0) the same counts are free-fixed; with both fixed nothing is counted; with A and B one body the same
    pairs are self pairs (they share no vertex index). A NaN vertex (a run that
    blew up): its triangles are counted apart and its frame is reported.
(b) A folded strip of 4 triangles whose last one pierces the first: exactly 1 self
    pair (the neighbours sharing a vertex or an edge are never counted); the fold
    opened: 0. A fan whose two faces share a vertex and cross elsewhere: 0 (faces
    sharing a vertex are never counted). One tet alone: 0.
(c) Ground: the file's ground_y, -ground overriding it, -ground_tolerance, fixed
    bodies' vertices below the ground not counted, no ground_y: not checked.
(d) Bad input: a missing file, a text file, an HDF5 file that is not a result, a
    result without /positions or without frames, a triangle index out of range, a fixed body that
    moves (the checker reads fixed bodies from frame 0), bad options: one line
    naming the file or option, non-zero exit (also on 2 ranks).
(e) A real run (scenes/contact/head-on-scene.txt, 2 ranks): every frame's counts
    equal the independent exact count, and the checker on 2 ranks reports what it
    reports on 1.
(f) The meshes of scenes/contact are what its README's commands write, and its
    scenes load.
Skipped when softbody-crossings was not built (no CGAL).
"""
import os
import subprocess
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import exact_triangles  # noqa: E402
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

args = harness.arguments()
checks = harness.Checks()
checker = harness.crossings_checker(args)

TET = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
TET_FACES = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]


def write_result(name, frames, triangles, vertex_body, body_fixed, ground_y=None):
    """A minimal result file: the datasets softbody-crossings reads."""
    path = os.path.join(args.work, name + ".h5")
    frames = np.asarray(frames, dtype=float)
    with h5py.File(path, "w") as f:
        f["time"] = 0.01 * np.arange(len(frames))
        f["positions"] = frames
        f["mesh/boundary_triangles"] = np.asarray(triangles, dtype=np.int32)
        f["mesh/vertex_body"] = np.asarray(vertex_body, dtype=np.int32)
        f["mesh/body_fixed"] = np.asarray(body_fixed, dtype=np.int32)
        if ground_y is not None:
            f.attrs["ground_y"] = float(ground_y)
    return path


def check_file(path, *options, ranks=1):
    """Runs the checker; returns its JSON report (None when it failed)."""
    return harness.run_crossings(args, checks, path, *options, ranks=ranks)


def frame_counts(report, kind):
    return [frame[kind] for frame in report["frames"]] if report else None


def two_tets(b_bodies=(0, 1)):
    """Frames: B interpenetrating A, B apart, B = -A touching A at the origin."""
    frames = [np.vstack([TET, TET + 0.2]), np.vstack([TET, TET + [3, 0, 0]]), np.vstack([TET, -TET])]
    triangles = TET_FACES + [[v + 4 for v in face] for face in TET_FACES]
    vertex_body = [b_bodies[0]] * 4 + [b_bodies[1]] * 4
    return frames, triangles, vertex_body


def case_a():
    frames, triangles, vertex_body = two_tets()
    reference = exact_triangles.count_crossings(frames[0], triangles, vertex_body, [0, 0])
    expected = [reference["free_free"], 0, 9]
    checks.check(expected[0] > 0, f"(a) reference: interpenetrating tets cross in {expected[0]} pairs")
    free = check_file(write_result("a_free", frames, triangles, vertex_body, [0, 0]))
    checks.check(frame_counts(free, "free_free") == expected,
                 f"(a) free-free pairs per frame {frame_counts(free, 'free_free')} == {expected} "
                 "(overlap, apart, touching at one point)")
    checks.check(free and frame_counts(free, "free_fixed") == [0, 0, 0]
                 and frame_counts(free, "self") == [0, 0, 0], "(a) no free-fixed or self pairs")
    fixed = check_file(write_result("a_fixed", frames, triangles, vertex_body, [1, 0]))
    checks.check(frame_counts(fixed, "free_fixed") == expected and frame_counts(fixed, "free_free") == [0] * 3,
                 f"(a) A fixed: free-fixed pairs {frame_counts(fixed, 'free_fixed')} == {expected}")
    both = check_file(write_result("a_both_fixed", frames[:1], triangles, vertex_body, [1, 1]))
    checks.check(both and both["frames_with_crossings"] == 0,
                 "(a) both fixed, interpenetrating: nothing counted")
    blown_up = [frame.copy() for frame in frames]
    blown_up[1][4] = np.nan  # B's vertex 0: its 3 faces cannot be tested
    nan = check_file(write_result("a_nan", blown_up, triangles, vertex_body, [0, 0]))
    checks.check(nan and [f["nonfinite"] for f in nan["frames"]] == [0, 3, 0]
                 and frame_counts(nan, "free_free") == expected and nan["nonfinite_frames"] == 1
                 and nan["frames_with_crossings"] == 3,
                 "(a) a NaN vertex: its 3 triangles counted apart, the frame reported, the rest checked")
    frames, triangles, vertex_body = two_tets(b_bodies=(0, 0))
    one = check_file(write_result("a_one_body", frames, triangles, vertex_body, [0]))
    checks.check(frame_counts(one, "self") == expected and frame_counts(one, "free_free") == [0] * 3,
                 f"(a) A and B one body: self pairs {frame_counts(one, 'self')} == {expected}")
    if free:
        checks.check(free["frames_with_crossings"] == 2 and free["first_crossing_frame"] == 0
                     and free["first_clean_frame"] == 1 and free["clean_from_frame"] == -1
                     and free["kinds"]["free_free"] == {"frames": 2, "max": 9, "max_frame": 2},
                     f"(a) summary: {free['frames_with_crossings']} frames with crossings, first 0, "
                     "first clean 1, never clean from a frame on, at most 9 pairs in frame 2")


def case_b():
    # Strip t0..t3: t0 in z = 0; t3 = (3, 4, 5) pierces t0 at (0.45, 0.45, 0).
    strip = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0.5, 0.5, 1], [0.3, 0.6, 1],
                      [0.4, 0.4, -1]])
    opened = strip.copy()
    opened[5] = [0.4, 0.4, 0.5]
    triangles = [[0, 1, 2], [1, 2, 3], [2, 3, 4], [3, 4, 5]]
    for frame, name in ((strip, "folded"), (opened, "opened")):
        reference = exact_triangles.count_crossings(frame, triangles, [0] * 6, [0])["self"]
        checks.check(reference == (1 if name == "folded" else 0), f"(b) reference: {name} strip {reference}")
    report = check_file(write_result("b_strip", [strip, opened], triangles, [0] * 6, [0]))
    checks.check(frame_counts(report, "self") == [1, 0],
                 f"(b) folded strip: self pairs {frame_counts(report, 'self')} == [1, 0] (folded, opened)")
    fan = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0.5, 0.5, 1], [0.6, 0.4, -1]])
    fan_faces = [[0, 1, 2], [0, 3, 4]]
    checks.check(exact_triangles.triangles_meet([tuple(fan[v]) for v in fan_faces[0]],
                                                [tuple(fan[v]) for v in fan_faces[1]]),
                 "(b) reference: the fan's faces cross beyond their shared vertex")
    report = check_file(write_result("b_fan", [fan], fan_faces, [0] * 5, [0]))
    checks.check(frame_counts(report, "self") == [0], "(b) faces sharing a vertex: never counted")
    report = check_file(write_result("b_tet", [TET], TET_FACES, [0] * 4, [0]))
    checks.check(frame_counts(report, "self") == [0], "(b) one tet: its adjacent faces are not counted")


def case_c():
    free = TET.copy()
    free[0, 1] = -0.001             # vertex 0 at y = -0.001, the others at 0 or above
    fixed = TET + [5, -2, 0]        # all four below the ground
    positions = np.vstack([free, fixed])
    triangles = TET_FACES + [[v + 4 for v in face] for face in TET_FACES]
    path = write_result("c_ground", [positions], triangles, [0] * 4 + [1] * 4, [0, 1], ground_y=0.0)
    report = check_file(path)
    checks.check(frame_counts(report, "below_ground") == [1] and report["ground_y"] == 0
                 and abs(report["max_ground_depth"] - 0.001) < 1e-15,
                 f"(c) ground_y 0: {frame_counts(report, 'below_ground')} free vertex below (fixed ones "
                 "not counted), deepest 1 mm")
    report = check_file(path, "-ground", "0.5")
    checks.check(frame_counts(report, "below_ground") == [3] and report and report["ground_y"] == 0.5,
                 f"(c) -ground 0.5 overrides the file: {frame_counts(report, 'below_ground')} == [3]")
    report = check_file(path, "-ground_tolerance", "0.002")
    checks.check(frame_counts(report, "below_ground") == [0], "(c) -ground_tolerance 2 mm: none counted")
    path = write_result("c_no_ground", [positions], triangles, [0] * 4 + [1] * 4, [0, 1])
    report = check_file(path)
    checks.check(report and report["ground_y"] is None and frame_counts(report, "below_ground") == [0],
                 "(c) no ground_y in the file: the ground is not checked")
    report = check_file(path, "-ground", "0")
    checks.check(frame_counts(report, "below_ground") == [1], "(c) no ground_y, -ground 0: 1 vertex")


def expect_error(command, expected, label, ranks=1):
    if ranks > 1:
        command = [args.mpiexec, "-n", str(ranks), *command]
    run = subprocess.run(command, capture_output=True, text=True, timeout=120, env=harness.mpi_environment())
    lines = [line for line in (run.stdout + run.stderr).splitlines() if "softbody: error" in line]
    checks.check(run.returncode != 0 and len(lines) == 1 and expected in lines[0],
                 f"(d) {label}: exit {run.returncode}, {lines[:2]} names '{expected}'")


def case_d():
    missing = os.path.join(args.work, "missing.h5")
    text = os.path.join(args.work, "text.h5")
    with open(text, "w") as f:
        f.write("not hdf5\n")
    other = os.path.join(args.work, "other.h5")
    with h5py.File(other, "w") as f:
        f["vertices"] = np.zeros((4, 3))
    frames, triangles, vertex_body = two_tets()
    no_positions = write_result("no_positions", frames, triangles, vertex_body, [0, 0])
    with h5py.File(no_positions, "a") as f:
        del f["positions"]
    bad_index = write_result("bad_index", frames, [[0, 1, 99]], vertex_body, [0, 0])
    good = write_result("good", frames, triangles, vertex_body, [0, 0])
    empty = write_result("no_frames", np.zeros((0, 8, 3)), triangles, vertex_body, [1, 0])
    moving_fixed = write_result("moving_fixed", frames, triangles, vertex_body, [0, 1])
    for ranks in (1, 2):
        expect_error([checker, missing], f"{missing}: cannot read", "a missing file", ranks)
    expect_error([checker, text], f"{text}: not an HDF5 file", "a text file")
    expect_error([checker, other], f"{other}: not a softbody result file", "an HDF5 file that is not a result")
    expect_error([checker, no_positions], "no /positions", "a result without /positions")
    expect_error([checker, bad_index], "index 99", "a triangle index out of range")
    expect_error([checker, moving_fixed], "fixed body 1 moves", "a fixed body that moves")
    expect_error([checker, moving_fixed], "fixed body 1 moves", "a fixed body that moves", ranks=2)
    expect_error([checker, empty], "holds no frame", "a result without frames")
    expect_error([checker], "usage: softbody-crossings", "no file name")
    expect_error([checker, good, "-every", "0"], "option -every", "-every 0")
    expect_error([checker, good, "-ground", "abc"], "option -ground", "-ground abc")
    expect_error([checker, good, "-json", os.path.join(args.work, "no", "dir.json")], "option -json",
                 "-json in a missing folder")


def case_e():
    scene = os.path.join(ROOT, "scenes", "contact", "head-on-scene.txt")
    out = harness.fresh_result(args.work, "head_on")
    harness.run(args, 2, ["-scene", scene, "-dt", "0.01", "-steps", "20", "-output", out])
    one, two = check_file(out), check_file(out, ranks=2)
    if not (one and two):
        return
    checks.check(one["frames"] == two["frames"], "(e) the checker on 2 ranks reports what it reports on 1")
    with h5py.File(out, "r") as f:
        positions = f["positions"][...]
        triangles = f["mesh/boundary_triangles"][...]
        vertex_body = f["mesh/vertex_body"][...]
        body_fixed = f["mesh/body_fixed"][...]
    kinds = ("free_free", "free_fixed", "self")
    differing = []
    for frame in one["frames"]:
        reference = exact_triangles.count_crossings(positions[frame["frame"]], triangles, vertex_body,
                                                    body_fixed)
        if any(reference[k] != frame[k] for k in kinds):
            differing.append((frame["frame"], reference, {k: frame[k] for k in kinds}))
    most = max(frame["free_free"] for frame in one["frames"])
    checks.check(not differing, f"(e) head-on run, {len(one['frames'])} frames (up to {most} free-free "
                 f"pairs): the counts equal the independent exact count {differing[:2]}")


def case_f():
    contact = os.path.join(ROOT, "scenes", "contact")
    for name, size, cells in (("cube", (1, 1, 1), (6, 6, 6)), ("block", (1, 1, 1), (4, 4, 4)),
                              ("sheet", (3, 0.05, 1), (30, 1, 10)), ("bar", (0.1, 0.1, 1.4), (1, 1, 7))):
        path = os.path.join(args.work, name + ".mesh")
        subprocess.run([sys.executable, os.path.join(ROOT, "tools", "box_mesh.py"), path, "-box_size",
                        *map(str, size), "-box_cells", *map(str, cells)], check=True, capture_output=True)
        with open(path, "rb") as a, open(os.path.join(contact, name + ".mesh"), "rb") as b:
            checks.check(a.read() == b.read(), f"(f) scenes/contact/{name}.mesh is what its README's "
                         "box_mesh.py command writes, byte for byte")
    for scene in ("head-on", "wedge", "sheet", "stack"):
        run = harness.run(args, 1, ["-scene", os.path.join(contact, scene + "-scene.txt"), "-steps", "0"],
                          check=False)
        checks.check(run.returncode == 0, f"(f) scenes/contact/{scene}-scene.txt loads (-steps 0)")


case_a()
case_b()
case_c()
case_d()
case_e()
case_f()
checks.exit()
