"""Fixed bodies are not whole on any rank: each holds the fixed tets of its region.

A rank keeps its share of the fixed tets for the run, and its obstacles hold
those whose boxes meet its region, boxes around where its own free vertices
are and go; when they leave it, the tets are fetched again
(src/contact/fixed_tets.hpp, ContactSolver::KeepFixedRegion). One rank's
region is everything.

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
"""
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

TERRAIN = ((8.0, 0.5, 8.0), (32, 2, 32))
CUBE = ((0.5, 0.5, 0.5), (4, 4, 4))
CUBE_VERTICES = 125
RUN = ["-steps", "60", "-dt", "0.01", "-gravity", "0,-9.81,0"]
RANKS = (1, 3, 4)
RANK_TOLERANCE = 1e-9  # direct solver: round-off of sums over another partition
HELD_FRACTION = 0.25
HELD = re.compile(r"fixed tets held by a rank at most (\d+) of (\d+) \(fetched (\d+) times")
COLLISIONS = re.compile(r"; (\d+) vertex collisions")
SETUP = re.compile(r"meshes during contact's set-up ([0-9.e+-]+) MB")

args = harness.arguments()
checks = harness.Checks()


def scene():
    harness.box_mesh(args, "terrain.mesh", *TERRAIN)
    harness.box_mesh(args, "cube.mesh", *CUBE)
    path = os.path.join(args.work, "throw-on-terrain.txt")
    with open(path, "w") as f:
        f.write("2\n")
        f.write("terrain.mesh 1000 1e6 0.3 1 0 -0.25 0 1 0 0 0\n")
        f.write("cube.mesh 1000 1e5 0.3 0 -3 1.0 -3 1 0 0 0\n")
        f.write(f"{CUBE_VERTICES}\n")
        for v in range(CUBE_VERTICES):
            f.write(f"1 {v} 6 0 6\n")
    return path


def main():
    path = scene()
    runs = {}
    for ranks in RANKS:
        out = harness.fresh_result(args.work, f"throw-{ranks}")
        stdout = harness.run(args, ranks, ["-scene", path, "-output", out] + RUN).stdout
        runs[ranks] = (out, stdout, harness.read_frames(out))
    reference = runs[1][2]
    collisions = {r: int(m.group(1)) if (m := COLLISIONS.search(s)) else -1 for r, (_, s, _) in runs.items()}
    checks.check(collisions[1] > 0, f"1 rank: the landing is found by the vertex test ({collisions[1]} collisions)")
    for ranks in RANKS:
        out, stdout, frames = runs[ranks]
        held = HELD.search(stdout)
        if not checks.check(held is not None, f"{ranks} ranks: the summary counts the fixed tets held"):
            continue
        most, total, fetched = (int(g) for g in held.groups())
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
    checks.exit()


if __name__ == "__main__":
    main()
