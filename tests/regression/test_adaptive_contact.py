"""-dt_adapt with collisions, friction, the collision guard and distance constraints.

For backward Euler and bdf2 (second order):
(a) the default scene (two struck beams, collisions and the guard on), 2 steps
    at -tol 1e-3, 1 rank: substeps were rejected and repeated
    (rejected_steps > 0 in the result file), and no surface crosses another
    or its own body's (softbody-crossings: 0 crossings);
(b) a cube dropped on the ground with gravity, friction 0.3 and restitution 0,
    -tol 1e-4, 2 ranks: substeps were rejected, no surface crosses, no vertex
    below the ground, the total energy (kinetic, elastic, gravitational) never
    rises from one frame to the next by more than round-off (1e-10 of the
    energy of the fall; the adaptive bdf2 restarts its history after a
    contact's velocity jump, test_integrators_contact.py checks fixed steps), and
    the cube comes to rest on the ground;
(c) restart bit for bit: the drop with -dt_adapt, 2 ranks, checkpoint two
    steps after the impact (resting contacts and the substep size in the
    checkpoint; -dt_adapt_horizon given, as the first part runs fewer -steps),
    positions and velocities of every frame equal;
(d) distance constraints (tests/data/constraints/hang.txt: two cubes hanging
    from a fixed one by 50 links, gravity), -tol 1e-3, 2 ranks: substeps were
    rejected, every link keeps its rest length to 1e-6 in every frame;
(e) a rejected substep leaves no trace (the contact solver's resting contacts
    are restored with the state): be with -dt_adapt -tol 1e-4 on a cube
    settling from 1 mm onto the ground without friction (a rejected attempt
    ends with resting contacts that the repeated, smaller substep must not
    inherit) equals, bit for bit at every frame, a fixed-step run of the
    accepted substeps (their sizes from -info, given by -dt_schedule; be keeps
    no history, so the same substeps must give the same state). Without the
    restore the frames differ by 5e-6 m.
"""
import math
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
SCHEMES = ("be", "bdf2")
# Energies are sums over every vertex of terms of the fall's size: round-off.
ENERGY_ROUND_OFF = 1e-10
GROUND_ROUND_OFF = 1e-10  # m: contacts end the contact gap above the ground
CROSSING_KINDS = ("free_free", "free_fixed", "self", "below_ground")  # softbody-crossings -json


def attributes(path):
    with h5py.File(path, "r") as f:
        return {k: float(f.attrs[k]) for k in ("accepted_steps", "rejected_steps", "min_dt", "max_dt")}


def crossings(path, label, ranks=1):
    report = harness.run_crossings(args, checks, path, ranks=ranks)
    if report is not None:
        counts = {kind: max(frame[kind] for frame in report["frames"]) for kind in CROSSING_KINDS}
        checks.check(not any(counts.values()), f"{label}: largest crossing counts per frame {counts} (all 0)")


for scheme in SCHEMES:
    out = harness.fresh_result(work, f"default_{scheme}")
    harness.run(args, 1, ["-scene", os.path.join(scenes, "default-scene.txt"), "-steps", 2, "-integrator",
                          scheme, "-dt_adapt", "-tol", "1e-3", "-output", out, "-quiet"])
    a = attributes(out)
    checks.check(a["rejected_steps"] > 0, f"(a) {scheme}, default scene: {a['accepted_steps']:.0f} substeps "
                 f"accepted, {a['rejected_steps']:.0f} rejected (> 0), dt {a['min_dt']:.2e} .. {a['max_dt']:.2e} s")
    crossings(out, f"(a) {scheme}, default scene")

cube = harness.box_mesh(args, "cube.mesh", (0.5, 0.5, 0.5), (4, 4, 4))
drop = harness.write_scene(os.path.join(work, "drop.txt"),
                           [("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, 0.3, 0), (1, 0, 0, 0))])
world = ["-scene", drop, "-gravity", "0,-9.81,0", "-ground", "0", "-dt", "0.01", "-restitution", "0",
         "-friction", "0.3", "-dt_adapt", "-tol", "1e-4", "-quiet"]
fall = 1000.0 * 0.125 * 9.81 * 0.05  # J: the cube's bottom starts 0.05 m above the ground

for scheme in SCHEMES:
    out = harness.fresh_result(work, f"drop_{scheme}")
    harness.run(args, 2, world + ["-integrator", scheme, "-steps", 60, "-output", out])
    a = attributes(out)
    r = harness.read_frames(out)
    energy = r["energy/kinetic"] + r["energy/elastic"] + r["energy/gravitational"]
    rise = np.diff(energy).max()
    lowest = r["positions"][:, :, 1].min()
    kinetic = r["energy/kinetic"][-1]
    checks.check(a["rejected_steps"] > 0, f"(b) {scheme} drop: {a['accepted_steps']:.0f} substeps accepted, "
                 f"{a['rejected_steps']:.0f} rejected (> 0), dt {a['min_dt']:.2e} .. {a['max_dt']:.2e} s")
    checks.check(rise <= ENERGY_ROUND_OFF * fall and lowest > -GROUND_ROUND_OFF and kinetic < 1e-3 * fall,
                 f"(b) {scheme} drop: largest rise of the total energy between frames {rise:.2e} J "
                 f"(<= {ENERGY_ROUND_OFF:g} of the fall's {fall:.3g} J), lowest vertex y = {lowest:.2e} m, "
                 f"kinetic energy at the end {kinetic:.2e} J (< 1e-3 of the fall)")
    crossings(out, f"(b) {scheme} drop", ranks=2)

    steps = 24  # the impact is at t = 0.101 s: the checkpoint at 0.12 s, resting on the ground
    full, part, cont = (harness.fresh_result(work, f"restart_{scheme}_{n}") for n in ("full", "part", "cont"))
    # The first part runs fewer -steps: the horizon of -tol (by default the run's length) is given.
    options = world + ["-integrator", scheme, "-dt_adapt_horizon", repr(steps * 0.01)]
    harness.run(args, 2, options + ["-steps", steps, "-output", full])
    harness.run(args, 2, options + ["-steps", steps // 2, "-checkpoint_every", steps // 2, "-output", part])
    harness.run(args, 2, options + ["-steps", steps, "-restart", part, "-output", cont])
    x, y = harness.read_frames(full), harness.read_frames(cont)
    same = len(x["time"]) == len(y["time"]) and all(np.array_equal(x[k], y[k])
                                                    for k in ("time", "positions", "velocities"))
    checks.check(same, f"(c) {scheme} drop, -dt_adapt: {len(y['time'])} frames bit for bit equal after the "
                       "restart")

# (d) distance constraints: two cubes hanging from a fixed one by tests/data/constraints/hang.txt.
links = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "constraints", "hang.txt")
with open(links) as f:
    pairs = [tuple(map(int, line.split()[:4])) for line in f.read().splitlines()[1:] if line.strip()]
hang = harness.write_scene(os.path.join(work, "hang.txt"),
                           [("cube.mesh", 1000.0, 1e6, 0.3, 1, (0, 0, 0), (1, 0, 0, 0)),
                            ("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, -0.75, 0), (1, 0, 0, 0)),
                            ("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, -1.5, 0), (1, 0, 0, 0))])
VERTICES_PER_CUBE = 125  # the 4 x 4 x 4-cell cube: the meshes' vertices follow each other
for scheme in SCHEMES:
    out = harness.fresh_result(work, f"hang_{scheme}")
    harness.run(args, 2, ["-scene", hang, "-constraints", links, "-gravity", "0,-9.81,0", "-dt", "0.01", "-steps", 20,
                          "-integrator", scheme, "-dt_adapt", "-tol", "1e-3", "-output", out, "-quiet"])
    r, a = harness.read_frames(out), attributes(out)
    ends = np.array([(m1 * VERTICES_PER_CUBE + v1, m2 * VERTICES_PER_CUBE + v2) for m1, v1, m2, v2 in pairs])
    rest = r["mesh/rest_positions"]
    length = np.linalg.norm(r["positions"][:, ends[:, 0]] - r["positions"][:, ends[:, 1]], axis=2)
    worst = np.abs(length / np.linalg.norm(rest[ends[:, 0]] - rest[ends[:, 1]], axis=1) - 1).max()
    checks.check(a["rejected_steps"] > 0 and worst < 1e-6 and r["complete"] == 1,
                 f"(d) {scheme}, {len(pairs)} distance constraints: {a['accepted_steps']:.0f} substeps accepted, "
                 f"{a['rejected_steps']:.0f} rejected (> 0); largest |distance / rest - 1| over the frames "
                 f"{worst:.1e} (< 1e-6)")

# (e) a rejected substep leaves no trace: be (no history) with -dt_adapt against a fixed-step run of
# the accepted substeps (-info lists them; -dt_schedule wherever the size changes).
slow = harness.write_scene(os.path.join(work, "slow.txt"),
                           [("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, 0.251, 0), (1, 0, 0, 0))])
common = ["-scene", slow, "-gravity", "0,-9.81,0", "-ground", "0", "-restitution", "0", "-friction", "0",
          "-integrator", "be"]
STEP, STEPS, SMALLEST = 0.01, 10, 2 ** 60  # the ladder's units: dt / 2^60
adaptive_out, fixed_out = harness.fresh_result(work, "replay_adaptive"), harness.fresh_result(work, "replay_fixed")
r = harness.run(args, 1, common + ["-dt", STEP, "-steps", STEPS, "-dt_adapt", "-tol", "1e-4", "-output", adaptive_out,
                                   "-info"])
sizes = [float(line.split("substep of ")[1].split()[0]) for line in r.stdout.splitlines() if "substep of" in line]
elapsed, schedule = 0, []
for size in sizes:
    if not schedule or schedule[-1][1] != size:
        schedule.append((elapsed * STEP / SMALLEST, size))
    elapsed += SMALLEST >> round(math.log2(STEP / size))
harness.run(args, 1, common + ["-dt", repr(schedule[0][1]), "-steps", len(sizes), "-output", fixed_out,
                               "-dt_schedule", ",".join(f"{t!r}:{h!r}" for t, h in schedule[1:])])
a, b = harness.read_frames(adaptive_out), harness.read_frames(fixed_out)
matched = [int(np.argmin(np.abs(b["time"] - t))) for t in a["time"]]
same = all(abs(b["time"][j] - t) < 1e-12 and np.array_equal(a["positions"][i], b["positions"][j])
           and np.array_equal(a["velocities"][i], b["velocities"][j]) for i, (t, j) in enumerate(zip(a["time"], matched)))
checks.check(same and attributes(adaptive_out)["rejected_steps"] > 0 and len(sizes) > STEPS,
             f"(e) be, a cube settling 1 mm onto the ground (friction 0): {len(sizes)} accepted substeps, "
             f"{attributes(adaptive_out)['rejected_steps']:.0f} rejected; a fixed-step run of the accepted "
             f"substeps ({len(schedule)} sizes by -dt_schedule) equals it bit for bit in all {len(a['time'])} frames")
checks.exit()
