"""Contact in parallel with halos: each rank reads only the vertices near its own.

When free bodies can meet, a rank receives from the others only their vertices
within -contact_halo_reach longest tet edges of its own (src/contact/free_state.hpp),
and its obstacle grids hold only the tets and triangles that came whole.

(a) The halo is complete: two cubes thrown at each other (scenes/contact/head-on,
    free against free) on 3 ranks give bit-for-bit the positions and velocities
    of the same run with a halo reach of 1e9 edges (every vertex near a rank's
    box sent), and the run summary's bytes sent by the busiest rank are fewer
    with the halo (each rank sends only what lies near another's part).
(b) The same with distance constraints on every boundary edge (-edge_bounds: the
    constrained vertices are fetched as a fixed set) and with impulse spreading
    (its weights summed over ranks): the halo equals the full reach bit for bit.
(c) Impulse spreading alone (a cube dropped on the ground, no free-free
    contact) does not depend on the rank count: 1 and 3 ranks agree to 1e-9
    relative (sums over ranks differ by round-off only).
(d) A halo reach below one edge is refused with one line naming the option.
(e) Free against free does not depend on the rank count: the skewed head-on
    scene (scenes/contact/skew-scene.txt, no vertex in the plane of the other
    cube's faces), 60 steps with the guard, gives on 3 and 4 ranks the 1-rank
    positions and velocities to 1e-9 relative in linear mode (measured 2e-14)
    and 1e-8 in corotational mode (its Newton and CG tolerances; measured
    1e-11). The aligned head-on scene, whose vertices lie exactly in the other
    cube's face planes, is left to round-off (its inside tests flip) and is not
    compared.
(f) The pairs that start closer than the guard's separation, counted per owner
    of a pair's lowest moving vertex on its part of the surfaces and summed
    (src/contact/collision_guard.cpp): three blocks placed with touching faces
    report the same count on 1, 3 and 4 ranks, and more than none.
"""
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = os.path.join(ROOT, "scenes", "contact")
HEAD_ON = ["-scene", os.path.join(SCENES, "head-on-scene.txt"), "-dt", "0.01", "-steps", "40"]
FULL = ["-contact_halo_reach", "1e9"]
RANK_TOLERANCE = 1e-9
COROTATIONAL_TOLERANCE = 1e-8  # the Newton iteration's and CG's tolerances

args = harness.arguments()
checks = harness.Checks()


def simulate(label, options, ranks):
    """(frames, kB sent by the busiest rank or None, stdout) of one run."""
    out = harness.fresh_result(args.work, label)
    result = harness.run(args, ranks, options + ["-output", out])
    sent = re.search(r"free state exchanged \d+ times \(halo and constrained vertices: ([0-9.e+]+) kB",
                     result.stdout)
    return harness.read_frames(out), float(sent.group(1)) if sent else None, result.stdout


def same_as_full(label, options):
    halo, halo_kb, _ = simulate(label, options, 3)
    full, full_kb, _ = simulate(label + "-full", options + FULL, 3)
    for key in ("positions", "velocities"):
        checks.check(np.array_equal(halo[key], full[key]),
                     f"{label}: {key} with the halo equal bit for bit to a full reach "
                     f"(largest difference {np.abs(halo[key] - full[key]).max():.1e})")
    checks.check(halo_kb is not None and full_kb is not None and halo_kb < full_kb,
                 f"{label}: busiest rank sent {halo_kb} kB with the halo, {full_kb} kB with a full reach")


print("(a) free against free, 3 ranks")
same_as_full("head-on", HEAD_ON)
print("(b) edge bounds and impulse spreading, 3 ranks")
same_as_full("head-on-bounds", HEAD_ON + ["-edge_bounds", "0.8,1.25", "-impulse_spreading"])

print("(c) impulse spreading on 1 and 3 ranks")
lone = harness.write_scene(os.path.join(args.work, "lone.txt"),
                          [(os.path.join(SCENES, "block.mesh"), 1000, 1e6, 0.3, 0, (0, 0.6, 0), (1, 0, 0, 0))])
DROP = ["-scene", lone, "-gravity", "0,-9.81,0", "-ground", "0", "-impulse_spreading", "-dt", "0.01",
        "-steps", "40"]
one, _, _ = simulate("spread-1", DROP, 1)
three, _, _ = simulate("spread-3", DROP, 3)
for key in ("positions", "velocities"):
    difference = harness.relative_difference(three[key], one[key])
    checks.check(difference <= RANK_TOLERANCE,
                 f"(c) {key}: 3 ranks vs 1 relative difference {difference:.1e} <= {RANK_TOLERANCE}")

print("(d) bad reach")
bad = harness.run(args, 2, HEAD_ON + ["-contact_halo_reach", "0.5", "-output",
                                       harness.fresh_result(args.work, "bad")], check=False)
lines = [line for line in (bad.stdout + bad.stderr).splitlines() if "-contact_halo_reach" in line]
checks.check(bad.returncode != 0 and lines, f"(d) exit {bad.returncode}, message {lines[:1]}")

print("(e) free against free on 1, 3 and 4 ranks, both modes")
SKEW = ["-scene", os.path.join(SCENES, "skew-scene.txt"), "-dt", "0.01", "-steps", "60"]
for mode, tolerance in (("linear", RANK_TOLERANCE), ("corotational", COROTATIONAL_TOLERANCE)):
    reference, _, stdout = simulate(f"skew-{mode}-1", SKEW + ["-mode", mode], 1)
    collisions = re.search(r"(\d+) vertex collisions", stdout)
    checks.check(collisions is not None and int(collisions.group(1)) > 0,
                 f"(e) {mode}: the cubes collide: {collisions.group(0) if collisions else None}")
    for ranks in (3, 4):
        run, _, _ = simulate(f"skew-{mode}-{ranks}", SKEW + ["-mode", mode], ranks)
        for key in ("positions", "velocities"):
            difference = harness.relative_difference(run[key], reference[key])
            checks.check(difference <= tolerance,
                         f"(e) {mode}, {ranks} ranks vs 1: {key} relative difference {difference:.1e} <= "
                         f"{tolerance}")
print("(f) surface pairs closer than the separation at the start, 1, 3 and 4 ranks")
BLOCK = os.path.join(SCENES, "block.mesh")
touching = harness.write_scene(os.path.join(args.work, "touching.txt"),
                               [(BLOCK, 1000, 1e6, 0.3, 0, (0, 0.5, 0), (1, 0, 0, 0)),
                                (BLOCK, 1000, 1e6, 0.3, 0, (0, 1.5, 0.3), (1, 0, 0, 0)),
                                (BLOCK, 1000, 1e6, 0.3, 0, (0.2, 2.5, 0), (1, 0, 0, 0))])
counts = []
for ranks in (1, 3, 4):
    stdout = harness.run(args, ranks, ["-scene", touching, "-gravity", "0,-9.81,0", "-ground", "0",
                                       "-dt", "0.01", "-steps", "1"]).stdout
    close = re.search(r"\((\d+) at the scene's start\)", stdout)
    counts.append(int(close.group(1)) if close else None)
checks.check(counts[0] is not None and counts[0] > 0 and counts.count(counts[0]) == len(counts),
             f"(f) close pairs at the start on 1, 3 and 4 ranks: {counts} (equal and more than none)")
checks.exit()
