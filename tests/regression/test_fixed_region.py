"""Fixed bodies are not whole on any rank: each holds the fixed tets of its region.

A rank keeps its share of the fixed tets for the run, and its obstacles hold
those whose boxes meet its region, boxes around where its own free vertices
are and go; when they leave it, the tets are fetched again
(src/contact/fixed_tets.hpp, ContactSolver::KeepFixedRegion). One rank's
region is everything, and so is every rank's when the fixed tets are small
(-contact_fixed_replicate_mb, default 64 MB at 140 B per tet): the scenes
below are small, so (a)-(d) set it to 0.

The scene: a fixed slab of terrain, 8 x 0.5 x 8 m (tools/box_mesh.py, 32 x 2 x
32 cells, 12 288 tets), its top at y = 0, and a free cube of 0.5 m (4 x 4 x 4
cells) thrown from above one corner at (6, 0, 6) m/s under gravity: it lands
about 3 m from where it started, far outside the region of its first fetch,
and slides on. The landing is found by the vertex test against the terrain's
tets (the run summary's vertex collisions).

(a) 3 and 4 ranks give the 1-rank positions and velocities in every frame to
    1e-9 relative (measured 1e-13), with the same number of vertex collisions,
    more than none. Without the fetches after the first (tried by hand) the
    landing is missed: no vertex collision, 68 queries outside a region, and
    the cube ends 1.25 m elsewhere.
(b) On 3 and 4 ranks the largest rank holds at most a quarter of the
    terrain's tets (measured 0.14), the tets were fetched more than once, and
    the summary warns of no query outside a region; on 1 rank every tet is
    held, fetched once.
(c) No rank holds a mesh whole during contact's set-up (the "whole scene"
    line's 0 MB, 4 ranks).
(d) The surfaces never cross: softbody-crossings counts no intersecting face
    pair in any frame of the 4-rank run.
(e) Small fixed bodies are held whole: the same cube thrown over a 2.5 x 0.5 x
    2.5 m slab (1 200 tets) on 3 ranks with the default threshold: one fetch,
    every fixed tet held by the largest rank, and the 1-rank result to 1e-9.
    With -contact_fixed_replicate_mb 0 the largest rank holds 972 of them.
(f) A negative -contact_fixed_replicate_mb ends with one line naming the
    option, exit status 1, on 2 ranks.
(g) Restart by region: the terrain run of (a) on 3 ranks stopped at step 30
    with a checkpoint and continued to step 60 equals the uninterrupted run bit
    for bit (the regions start empty and are fetched at the first step).
"""
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

TERRAIN = ((8.0, 0.5, 8.0), (32, 2, 32))
SLAB = ((2.5, 0.5, 2.5), (10, 2, 10))
CUBE = ((0.5, 0.5, 0.5), (4, 4, 4))
CUBE_VERTICES = 125
RUN = ["-steps", "60", "-dt", "0.01", "-gravity", "0,-9.81,0"]
BY_REGION = ["-contact_fixed_replicate_mb", "0"]
RANKS = (1, 3, 4)
RANK_TOLERANCE = 1e-9  # direct solver: round-off of sums over another partition
HELD_FRACTION = 0.25
HELD = re.compile(r"fixed tets held by a rank at most (\d+) of (\d+) \(fetched (\d+) times")
COLLISIONS = re.compile(r"; (\d+) vertex collisions")
SETUP = re.compile(r"meshes during contact's set-up ([0-9.e+-]+) MB")

args = harness.arguments()
checks = harness.Checks()


def scene(name, terrain, start, speed):
    """A fixed slab (its top at y = 0) and the cube thrown from `start` (x = z)
    at `speed` m/s along x and z."""
    harness.box_mesh(args, name + ".mesh", *terrain)
    harness.box_mesh(args, "cube.mesh", *CUBE)
    path = os.path.join(args.work, f"throw-on-{name}.txt")
    with open(path, "w") as f:
        f.write("2\n")
        f.write(f"{name}.mesh 1000 1e6 0.3 1 0 {-terrain[0][1] / 2} 0 1 0 0 0\n")
        f.write(f"cube.mesh 1000 1e5 0.3 0 {start} 1.0 {start} 1 0 0 0\n")
        f.write(f"{CUBE_VERTICES}\n")
        for v in range(CUBE_VERTICES):
            f.write(f"1 {v} {speed} 0 {speed}\n")
    return path


def held_counts(stdout):
    """(most tets a rank held, the scene's fixed tets, fetches) from the summary, or None."""
    held = HELD.search(stdout)
    return tuple(int(g) for g in held.groups()) if held else None


def small_body():
    """(e): a small fixed slab is held whole, fetched once."""
    path = scene("slab", SLAB, -0.8, 1.5)
    frames = {}
    for ranks in (1, 3):
        out = harness.fresh_result(args.work, f"slab-{ranks}")
        stdout = harness.run(args, ranks, ["-scene", path, "-output", out] + RUN).stdout
        frames[ranks] = harness.read_frames(out)
        counts = held_counts(stdout)
        if ranks == 3 and checks.check(counts is not None, "small slab, 3 ranks: the summary counts the tets"):
            most, total, fetched = counts
            checks.check(most == total and fetched == 1,
                         f"small slab, 3 ranks: the largest rank holds {most} of {total} fixed tets after "
                         f"{fetched} fetches (expected all, after 1)")
    for key in ("positions", "velocities"):
        difference = harness.relative_difference(frames[3][key], frames[1][key])
        checks.check(difference <= RANK_TOLERANCE,
                     f"small slab, 3 ranks: {key} {difference:.1e} relative from 1 rank's (at most {RANK_TOLERANCE:g})")


def main():
    path = scene("terrain", TERRAIN, -3, 6)
    runs = {}
    for ranks in RANKS:
        out = harness.fresh_result(args.work, f"throw-{ranks}")
        stdout = harness.run(args, ranks, ["-scene", path, "-output", out] + RUN + BY_REGION).stdout
        runs[ranks] = (out, stdout, harness.read_frames(out))
    reference = runs[1][2]
    collisions = {r: int(m.group(1)) if (m := COLLISIONS.search(s)) else -1 for r, (_, s, _) in runs.items()}
    checks.check(collisions[1] > 0, f"1 rank: the landing is found by the vertex test ({collisions[1]} collisions)")
    for ranks in RANKS:
        out, stdout, frames = runs[ranks]
        counts = held_counts(stdout)
        if not checks.check(counts is not None, f"{ranks} ranks: the summary counts the fixed tets held"):
            continue
        most, total, fetched = counts
        warned = "queries outside a rank's region" in stdout
        checks.check(not warned, f"{ranks} ranks: no query fell outside a rank's region")
        if ranks == 1:
            checks.check(most == total and fetched == 1,
                         f"1 rank: every fixed tet held ({most} of {total}), fetched once ({fetched})")
            continue
        checks.check(most <= HELD_FRACTION * total,
                     f"{ranks} ranks: the largest rank holds {most} of {total} fixed tets "
                     f"({most / total:.2f}, at most {HELD_FRACTION})")
        checks.check(fetched > 1, f"{ranks} ranks: fetched again as the cube moved ({fetched} times)")
        checks.check(collisions[ranks] == collisions[1],
                     f"{ranks} ranks: {collisions[ranks]} vertex collisions, as on 1 rank ({collisions[1]})")
        for key in ("positions", "velocities"):
            difference = harness.relative_difference(frames[key], reference[key])
            checks.check(difference <= RANK_TOLERANCE,
                         f"{ranks} ranks: {key} {difference:.1e} relative from 1 rank's "
                         f"(at most {RANK_TOLERANCE:g})")
    setup = SETUP.search(runs[4][1])
    checks.check(setup is not None and float(setup.group(1)) == 0,
                 f"4 ranks: no mesh whole during contact's set-up ({setup.group(0) if setup else 'no line'})")
    report = harness.run_crossings(args, checks, runs[4][0])
    if report:
        worst = max(max(frame[kind] for kind in ("free_fixed", "free_free", "self")) for frame in report["frames"])
        checks.check(worst == 0, f"4 ranks: no crossing face pair in any of {len(report['frames'])} frames "
                     f"(worst frame {worst})")
    small_body()
    bad_option(path)
    restart(path, runs[3][2])
    checks.exit()


def restart(path, uninterrupted):
    """(g): a checkpoint halfway, continued, equals the uninterrupted 3-rank run."""
    part = harness.fresh_result(args.work, "throw-part")
    half = ["-steps", "30", "-checkpoint_every", "30"]
    harness.run(args, 3, ["-scene", path, "-output", part] + RUN + BY_REGION + half)
    continued = harness.fresh_result(args.work, "throw-continued")
    harness.run(args, 3, ["-scene", path, "-output", continued, "-restart", part] + RUN + BY_REGION)
    frames = harness.read_frames(continued)
    for key in ("positions", "velocities"):
        checks.check(np.array_equal(frames[key], uninterrupted[key]),
                     f"(g) restart on 3 ranks: {key} bit for bit those of the uninterrupted run")


def bad_option(path):
    """(f): a negative threshold is refused."""
    out = harness.fresh_result(args.work, "bad")
    bad = harness.run(args, 2, ["-scene", path, "-output", out, "-contact_fixed_replicate_mb", "-1"] + RUN,
                      check=False)
    lines = [l for l in (bad.stdout + bad.stderr).splitlines() if "-contact_fixed_replicate_mb" in l]
    checks.check(bad.returncode == 1 and len(lines) >= 1 and lines[0].startswith("softbody: error: option"),
                 f"(f) negative threshold: exit {bad.returncode}, {lines[:1]}")


if __name__ == "__main__":
    main()
