"""Restitution and energy at impact (-restitution e): a stiff block dropped on
the ground bounces to e^2 of its fall height, and no step gains energy.

The body: a 0.5 m cube (tools/box_mesh.py, 4 x 4 x 4 cells), density 1000,
E 1e7, nu 0.3 (a fairly stiff block: its impact lasts a few steps), dropped
flat from rest with its centroid 1 m above its resting height; dt = 0.002 s,
1.5 s, mass damping off (-alpha 0: it would slow the centroid's flight and the
ratio would not be e^2 even for a rigid ball; stiffness damping b = 0.1 s stays,
it acts on the deformation only). Height: the centroid's height above its
resting height (the centroid of the e = 0 run's last frame, lying still),
centroid from the mesh's lumped masses. Rebound: the centroid's highest point
after the first impact. The figures come from the result file (positions and
the energies it records every step).

(a) e = 0: no rebound (below 1 % of the fall); kinetic + elastic +
    gravitational energy never increases from one step to the next (1e-9 of the
    initial total).
(b) e = 0.5 and 0.8, linear mode on 1 and 2 ranks, e = 0.8 corotational on
    2: rebound within 5 % of e^2 times the fall height (measured -1.6 % and
    -1.3 %: backward Euler's own loss in the flight, about g dt / v of the
    height each way); no step gains energy (1e-9 of the
    initial total), the bounce included. (The former model, e J / M given as a
    uniform velocity after each impact step, rose to 0.22 and 0.58 of the fall,
    -11 % and -10 % at dt = 0.01 s.)
(c) A ball (a geodesic sphere of the cube's width, TetGen), e = 0 and 0.8, 2
    ranks: the same checks (measured -1.5 % for e = 0.8).
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()

SIZE = 0.5                      # cube edge (m)
RHO, YOUNG, NU = 1000.0, 1e7, 0.3
FALL = 1.0                      # centroid height above its resting height at the start (about, m)
DT, STEPS = 0.002, 750
TOLERANCE = 0.05                # rebound vs e^2 of the fall
ENERGY_ROUND_OFF = 1e-9         # a step's energy gain, relative to the initial total

harness.box_mesh(args, "cube.mesh", (SIZE, SIZE, SIZE), (4, 4, 4))
scene = harness.write_scene(os.path.join(args.work, "drop.txt"),
                            [("cube.mesh", RHO, YOUNG, NU, 0, (0, SIZE / 2 + FALL, 0), (1, 0, 0, 0))])
# The ball: a geodesic sphere of radius SIZE / 2 (tools/bench.py's surface, 162
# vertices), tetrahedralised by TetGen on load (tets up to 5e-4 m^3).
sys.path.insert(0, harness.TOOLS)
from bench import ellipsoid_surface  # noqa: E402
BALL_FREQUENCY, BALL_MAX_VOLUME = 4, 5e-4
points, triangles = ellipsoid_surface((SIZE / 2,) * 3, BALL_FREQUENCY)
with open(os.path.join(args.work, "ball.off"), "w") as f:
    f.write(f"OFF\n{len(points)} {len(triangles)} 0\n")
    f.writelines(f"{p[0]:.17g} {p[1]:.17g} {p[2]:.17g}\n" for p in points)
    f.writelines(f"3 {a} {b} {c}\n" for a, b, c in triangles)
ball_scene = harness.write_scene(os.path.join(args.work, "ball.txt"),
                                 [("ball.off", RHO, YOUNG, NU, 0, (0, SIZE / 2 + FALL, 0), (1, 0, 0, 0))])


def drop(e, ranks, mode="linear", body=scene, name="drop"):
    """(centroid height per frame, index of the frame ending the first compression, total energy per frame)."""
    out = harness.fresh_result(args.work, f"{name}_e{e}_{ranks}_{mode}")
    harness.run(args, ranks, ["-scene", body, "-output", out, "-gravity", "0,-9.81,0", "-ground", "0",
                              "-restitution", str(e), "-dt", str(DT), "-steps", str(STEPS), "-alpha", "0",
                              "-mode", mode, *(["-tetgen_max_volume", str(BALL_MAX_VOLUME)] if body == ball_scene
                                               else [])])
    frames = harness.read_frames(out)
    masses = harness.lumped_masses(frames["mesh/tets"], frames["mesh/rest_positions"],
                                   frames["mesh/vertex_body"], [RHO])
    height = frames["positions"][:, :, 1] @ masses / masses.sum()
    # Contacts end -contact_gap (1e-4) mean boundary edges above the ground.
    touch = int(np.argmax(frames["positions"][:, :, 1].min(axis=1) <= 1e-3 * SIZE))
    low = touch + int(np.argmin(height[touch:touch + int(0.2 / DT)]))
    total = frames["energy/kinetic"] + frames["energy/elastic"] + frames["energy/gravitational"]
    return height, low, total


def energy_check(label, total):
    gain = np.diff(total)
    worst = int(np.argmax(gain))
    checks.check(gain[worst] <= ENERGY_ROUND_OFF * abs(total[0]),
                 f"{label}: no step gains energy: largest step-to-step change {gain[worst]:+.3e} J "
                 f"({gain[worst] / abs(total[0]):+.1e} of the initial {total[0]:.5g} J, at step {worst + 1}; "
                 f"limit {ENERGY_ROUND_OFF:g})")


print("(a) e = 0")
height, low, total = drop(0.0, 1)
rest = height[-1]
fall = height[0] - rest
rise = height[low:].max() - rest
checks.check(rise < 0.01 * fall,
             f"(a) e = 0: rebound {rise:.2e} m < 1 % of the fall {fall:.4f} m (resting centroid at {rest:.5f} m)")
energy_check("(a) e = 0", total)

print("(b) e = 0.5 and 0.8")
for e, ranks, mode in ((0.5, 1, "linear"), (0.5, 2, "linear"), (0.8, 1, "linear"), (0.8, 2, "linear"),
                       (0.8, 2, "corotational")):
    height, low, total = drop(e, ranks, mode)
    ranks = f"{ranks} ({mode})"
    rise = height[low:].max() - rest
    ratio = rise / fall
    checks.check(abs(ratio / e ** 2 - 1) < TOLERANCE,
                 f"(b) e = {e}, ranks {ranks}: rebound {rise:.4f} m = {ratio:.4f} of the fall {fall:.4f} m vs "
                 f"e^2 = {e * e:.2f} ({100 * (ratio / e ** 2 - 1):+.2f} %, within {100 * TOLERANCE:g} %)")
    energy_check(f"(b) e = {e}, ranks {ranks}", total)
print("(c) a ball")
height, low, total = drop(0.0, 2, body=ball_scene, name="ball")
ball_rest = height[-1]
ball_fall = height[0] - ball_rest
energy_check("(c) ball, e = 0", total)
height, low, total = drop(0.8, 2, body=ball_scene, name="ball")
ratio = (height[low:].max() - ball_rest) / ball_fall
checks.check(abs(ratio / 0.64 - 1) < TOLERANCE,
             f"(c) ball, e = 0.8, 2 ranks: rebound {ratio:.4f} of the fall {ball_fall:.4f} m (resting centroid "
             f"{ball_rest:.5f} m) vs e^2 = 0.64 ({100 * (ratio / 0.64 - 1):+.2f} %, within {100 * TOLERANCE:g} %)")
energy_check("(c) ball, e = 0.8", total)
checks.exit()
