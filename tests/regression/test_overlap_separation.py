"""Free bodies placed overlapping are moved apart rigidly until their surfaces no longer cross.

Two 1 m cubes (scenes/contact/block.mesh) overlap by 0.5 m along x, without
gravity or ground, 6 steps, 1 and 2 ranks. Expected from the rule
(src/contact/overlap_separation.hpp) and the mesh alone: after each step while
the surfaces cross, each cube moves by half of one mean boundary edge h (computed
here from the mesh's boundary triangles) along the line between the centroids,
so the overlap shrinks by h per step and the surfaces are apart after
ceil(0.5 / h) steps (2 with h = 0.29 m).

(a) The load warns; softbody-crossings (exact predicates) finds free-free
    crossings in frame 0 and in every frame before that step count, and none from
    it on; the run summary says the pair was separated in that many steps.
(b) The motion is a rigid translation: every vertex of each cube is displaced
    by the same (+-h / 2, 0, 0) per separating step (1e-12 m), the pair's mass
    centroid stays (equal masses), and no velocity appears (below 1e-10 m/s in
    every frame: round-off).
(c) 2 ranks give the 1-rank positions (1e-12 relative).
Skipped when softbody-crossings was not built (no CGAL).
"""
import math
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BLOCK = os.path.join(ROOT, "scenes", "contact", "block.mesh")
OVERLAP = 0.5  # m along x, of 1 m cubes
STEPS = 6
POSITION_TOLERANCE = 1e-12  # m: translations of O(1) m coordinates, round-off only
RANK_TOLERANCE = 1e-12
SPEED_TOLERANCE = 1e-10  # m/s: the elastic forces of a translated mesh are round-off

args = harness.arguments()
checks = harness.Checks()
harness.crossings_checker(args)

scene = os.path.join(args.work, "overlap-scene.txt")
with open(scene, "w") as f:
    f.write("2\n")
    for x in (0.0, 1.0 - OVERLAP):
        f.write(f"{BLOCK} 1000 1e6 0.3 0 {x} 0.5 0 1 0 0 0\n")


def simulate(ranks):
    out = harness.fresh_result(args.work, f"overlap-{ranks}")
    result = harness.run(args, ranks, ["-scene", scene, "-dt", "0.01", "-steps", str(STEPS),
                                       "-output", out])
    return harness.read_frames(out), result.stdout, out


def mean_boundary_edge(frames):
    """The first cube's mean boundary edge (m) from its rest positions and boundary triangles."""
    body = frames["mesh/vertex_body"]
    rest = frames["mesh/rest_positions"]
    edges = set()
    for triangle in frames["mesh/boundary_triangles"]:
        if body[triangle[0]] != 0:
            continue
        for k in range(3):
            a, b = int(triangle[k]), int(triangle[(k + 1) % 3])
            edges.add((min(a, b), max(a, b)))
    return float(np.mean([np.linalg.norm(rest[b] - rest[a]) for a, b in edges]))


frames, stdout, path = simulate(1)
h = mean_boundary_edge(frames)
expected_steps = math.ceil(OVERLAP / h)
print(f"mean boundary edge {h:.4f} m: separated after {expected_steps} steps")

print("(a) crossings until the expected step, none after; the warning and the summary")
checks.check("start with their surfaces crossing" in stdout, "(a) the load warns of the overlapping pair")
found = re.search(r"placed overlapping, separated in (\d+) steps", stdout)
checks.check(found and int(found.group(1)) == expected_steps,
             f"(a) summary: separated in {found.group(1) if found else None} steps (expected {expected_steps})")
report = harness.run_crossings(args, checks, path)
if report:
    counts = [frame["free_free"] for frame in report["frames"]]
    checks.check(all(c > 0 for c in counts[:expected_steps]) and not any(counts[expected_steps:]),
                 f"(a) free-free crossing pairs per frame {counts}: > 0 in frames 0-{expected_steps - 1}, "
                 f"0 from frame {expected_steps} on")

print("(b) a rigid translation, no velocity")
positions, body = frames["positions"], frames["mesh/vertex_body"]
worst = 0.0
for step in range(1, STEPS + 1):
    moving = step <= expected_steps
    for b, sign in ((0, -1), (1, 1)):
        shift = np.array([sign * h / 2 if moving else 0.0, 0.0, 0.0])
        delta = positions[step][body == b] - positions[step - 1][body == b]
        worst = max(worst, float(np.abs(delta - shift).max()))
checks.check(worst <= POSITION_TOLERANCE,
             f"(b) every vertex moves by -+h/2 along x per separating step, then stays: "
             f"largest deviation {worst:.1e} m <= {POSITION_TOLERANCE}")
drift = float(np.abs(positions.mean(axis=1) - positions[0].mean(axis=0)).max())
checks.check(drift <= POSITION_TOLERANCE, f"(b) the pair's centroid stays: {drift:.1e} m")
speed = float(np.abs(frames["velocities"]).max())
checks.check(speed <= SPEED_TOLERANCE, f"(b) largest velocity in any frame {speed:.1e} m/s <= {SPEED_TOLERANCE}")

print("(c) 2 ranks")
two, _, _ = simulate(2)
difference = harness.relative_difference(two["positions"], frames["positions"])
checks.check(difference <= RANK_TOLERANCE, f"(c) 2 ranks vs 1: positions {difference:.1e} <= {RANK_TOLERANCE}")
checks.exit()
