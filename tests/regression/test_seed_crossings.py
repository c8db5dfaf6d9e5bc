#!/usr/bin/env python3
"""softbody-crossings on coursework scenes (../shared/seed-data; docs/contact-crossings.md).

(a) infomgp-p3/bunny-scene.txt dropped on the ground (config/practical3.opts, 200
    steps, 2 ranks): the checker's counts of every 10th frame and of the frames with
    the most self pairs equal an independent exact count (tests/regression/
    exact_triangles.py), and the checker's figures for all frames on 2 ranks equal
    those on 1. The counts themselves are not asserted: they measure the solver.
(b) infomgp-p3/fertility-scene.txt places its two statues overlapping: its first
    frame (-steps 0) has free-free crossings, as many as the independent count.
Skipped without the seed data or without softbody-crossings (no CGAL).
"""
import os
import sys

import h5py

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import exact_triangles  # noqa: E402
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PRACTICAL3 = os.path.join(ROOT, "config", "practical3.opts")
KINDS = ("free_free", "free_fixed", "self", "below_ground")
EVERY = 10  # frames compared with the (slower) independent count: every 10th

args = harness.arguments()
checks = harness.Checks()
bunny_scene = harness.seed(args, "infomgp-p3", "bunny-scene.txt")
fertility_scene = harness.seed(args, "infomgp-p3", "fertility-scene.txt")
harness.crossings_checker(args)


def check_file(path, ranks=1):
    return harness.run_crossings(args, checks, path, ranks=ranks)


def reference_counts(path, frame):
    with h5py.File(path, "r") as f:
        ground = f.attrs.get("ground_y")
        return exact_triangles.count_crossings(
            f["positions"][frame], f["mesh/boundary_triangles"][...], f["mesh/vertex_body"][...],
            f["mesh/body_fixed"][...], None if ground is None else float(ground))


def compare(path, report, frames, label):
    differing = []
    for frame in frames:
        reference = reference_counts(path, frame)
        ours = {k: report["frames"][frame][k] for k in KINDS}
        if reference != ours:
            differing.append((frame, reference, ours))
    checks.check(not differing, f"{label}: frames {frames[:4]}{'...' if len(frames) > 4 else ''} "
                 f"({len(frames)}) equal the independent exact count {differing[:2]}")


out = harness.fresh_result(args.work, "bunny")
harness.run(args, 2, ["-scene", bunny_scene, "-options_file", PRACTICAL3, "-steps", "200", "-output", out])
one, two = check_file(out), check_file(out, ranks=2)
if one and two:
    checks.check(one["frames"] == two["frames"], "(a) bunny: the checker on 2 ranks reports what it reports on 1")
    most_self = sorted(range(len(one["frames"])), key=lambda i: -one["frames"][i]["self"])[:3]
    frames = sorted(set(range(0, len(one["frames"]), EVERY)) | set(most_self))
    print(f"(a) bunny: {one['frames_with_crossings']} of {one['frames_checked']} frames with crossings, "
          f"self pairs up to {one['kinds']['self']['max']} (frame {one['kinds']['self']['max_frame']})")
    compare(out, one, frames, "(a) bunny")

out = harness.fresh_result(args.work, "fertility")
harness.run(args, 1, ["-scene", fertility_scene, "-options_file", PRACTICAL3, "-steps", "0", "-output", out])
report = check_file(out)
if report:
    checks.check(report["frames"][0]["free_free"] > 0,
                 f"(b) fertility: the statues overlap at load: {report['frames'][0]['free_free']} free-free pairs")
    compare(out, report, [0], "(b) fertility")
checks.exit()
