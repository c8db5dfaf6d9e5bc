"""Contact and the collision guard with every integrator, fixed steps.

Contact acts on the step's motion from x_n to x1 whatever the scheme: the
guard's swept test starts at x_n (not at a scheme's extrapolated base point),
constraints hold x1 (not newmark's midpoint), and a vertex the guard held ends
with its mean velocity (x1 - x_n) / dt. Checked against energy balance and the
exact crossing checker, independent of the scheme's coefficients:

(a) the default scene (two beams struck at 80 and 160 m/s, no gravity, the
    guard with self-contact holds the struck edges in the first steps),
    dt = 0.02 s, 10 steps, 1 rank, for be, bdf2 and newmark: the total energy
    (kinetic + elastic) never rises from one frame to the next by more than
    1e-6 of the initial energy (the struck beams only lose energy to Rayleigh
    damping; with the guard sweeping from the scheme's extrapolated base point
    bdf2 rose by 1.78 times the initial energy between two frames and its
    surface crossed itself in 448 face pairs), and no surface crosses another
    or its own body's in any frame. alpha is left out:
    its energy swings from frame to frame on this scene with the guard off as
    well (its start takes a_0 from the equation of motion, whose stiffness
    damping b K v_0 after the strike is far beyond the motion's scale;
    docs/integrators.md).
(b) a cube dropped 5 cm onto the ground with gravity, restitution 0,
    friction 0.3, dt = 0.01 s, 60 steps, 2 ranks, every scheme: the total energy
    (with the gravitational) never rises from one frame to the next by more
    than 1 % of the fall's energy, no vertex ends below the ground by more than
    round-off, no crossing, and the cube ends at rest (kinetic energy below
    1e-3 of the fall's). Without the restart of the history after a contact
    step, bdf2 gained 26 % of the fall's energy at the impact (its history
    extrapolates the velocity jump into a rebound) and alpha 4.4 %.
"""
import os
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()
work = os.path.abspath(args.work)
scenes = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scenes")
CROSSING_KINDS = ("free_free", "free_fixed", "self", "below_ground")  # softbody-crossings -json
# (a) The energies are sums of O(1e5) J terms: 1e-6 of the initial energy is far
# above their round-off and far below any gain the guard could make.
STRUCK_RISE = 1e-6
# (b) A frame's energy may rise by the solver's tolerance and by the contact gap's
# share of the fall (contacts end 1e-4 of an edge above the ground): 1 % of the fall.
DROP_RISE = 0.01
REST_KINETIC = 1e-3  # of the fall's energy, after 0.6 s (the cube lands at about 0.1 s)
GROUND_ROUND_OFF = 1e-10  # m


def energies(path):
    with h5py.File(path, "r") as f:
        return {k: np.asarray(f["energy/" + k][...], dtype=float).ravel()
                for k in ("kinetic", "elastic", "gravitational")}


def crossings(path, label, ranks=1):
    report = harness.run_crossings(args, checks, path, ranks=ranks)
    if report is not None:
        counts = {kind: max(frame[kind] for frame in report["frames"]) for kind in CROSSING_KINDS}
        checks.check(not any(counts.values()), f"{label}: largest crossing counts per frame {counts} (all 0)")


# (a) The struck beams.
for scheme, dt, steps in (("be", 0.02, 10), ("bdf2", 0.02, 10), ("newmark", 0.02, 10)):
    out = harness.fresh_result(work, f"struck-{scheme}")
    harness.run(args, 1, ["-scene", os.path.join(scenes, "default-scene.txt"), "-integrator", scheme,
                          "-dt", dt, "-steps", steps, "-output", out, "-quiet"])
    e = energies(out)
    total = e["kinetic"] + e["elastic"]
    rise = float(np.max(np.diff(total))) / total[0]
    checks.check(rise <= STRUCK_RISE, f"(a) {scheme}, dt {dt}: largest rise of the total energy between frames "
                 f"{rise:.3g} of the initial {total[0]:.4g} J (<= {STRUCK_RISE:g}); final {total[-1]:.4g} J")
    crossings(out, f"(a) {scheme}")

# (b) The cube dropped on the ground.
cube = harness.box_mesh(args, "cube.mesh", (0.5, 0.5, 0.5), (4, 4, 4))
drop = harness.write_scene(os.path.join(work, "drop.txt"),
                           [("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, 0.3, 0), (1, 0, 0, 0))])
fall = 1000.0 * 0.125 * 9.81 * 0.05  # J: the cube's bottom starts 0.05 m above the ground
for scheme in ("be", "bdf2", "newmark", "alpha"):
    out = harness.fresh_result(work, f"drop-{scheme}")
    harness.run(args, 2, ["-scene", drop, "-gravity", "0,-9.81,0", "-ground", "0", "-dt", "0.01", "-steps", 60,
                          "-restitution", "0", "-friction", "0.3", "-integrator", scheme, "-output", out, "-quiet"])
    e = energies(out)
    total = e["kinetic"] + e["elastic"] + e["gravitational"]
    rise = float(np.max(np.diff(total))) / fall
    checks.check(rise <= DROP_RISE, f"(b) {scheme}: largest rise of the total energy between frames {rise:.3g} "
                 f"of the fall's {fall:.4g} J (<= {DROP_RISE:g})")
    checks.check(e["kinetic"][-1] <= REST_KINETIC * fall,
                 f"(b) {scheme}: kinetic energy at 0.6 s {e['kinetic'][-1]:.3g} J "
                 f"(<= {REST_KINETIC:g} of the fall's {fall:.4g} J)")
    with h5py.File(out, "r") as f:
        lowest = float(np.min(f["positions"][:, :, 1]))
    checks.check(lowest >= -GROUND_ROUND_OFF, f"(b) {scheme}: lowest vertex in any frame at y = {lowest:.3g} m (>= 0)")
    crossings(out, f"(b) {scheme}", ranks=2)

checks.exit()
