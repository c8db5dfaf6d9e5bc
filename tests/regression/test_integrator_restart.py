"""Every -integrator with checkpoints and restart, contact, gravity, damping,
-deform and -dt_schedule.

For each of bdf2, newmark and alpha (be: test_restart.py), 2 ranks:
(a) restart bit for bit: N steps uninterrupted against N/2 steps with a
    checkpoint and a restart from it to N (positions and velocities of every
    frame equal), with the scheme's history in the checkpoint
    (checkpoint/*/integrator names the scheme; bdf2 stores previous_positions
    and previous_velocities, alpha accelerations): the linear beam scene; a
    corotational struck bar with a -deform event before and one after the
    checkpoint and a -dt_schedule change after it; a cube dropped on the
    ground with gravity, friction and restitution, linear and corotational
    (checkpoint while it rests).
(b) the drop: no vertex ends more than 1 mm below the ground (the contact
    solver's tolerance is far below that), the cube comes to rest (kinetic
    energy at the end below 1e-3 of the energy of the fall) and its centre of
    mass at the end lies within 2 % of the cube's half height above the
    ground (resting under its weight).
(c) the history datasets are what they claim: for bdf2 the checkpoint's
    previous_positions equal the positions of the frame one step before the
    checkpoint (every step a frame), bit for bit.
(d) a checkpoint of another integrator is continued with a fresh history (no
    error): be's checkpoint restarted with bdf2 runs to the end.
(e) -dt_adapt -tol 1e-4: the struck bar restarts bit for bit with bdf2 (linear
    and corotational) and alpha (linear): the checkpoint holds the substep
    size and the previous velocities the error estimate needs (-dt_adapt_horizon
    given: the first part runs fewer -steps, and the horizon of -tol defaults to
    the run's length).
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
beam = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scenes", "beam-scene.txt")
SCHEMES = ("bdf2", "newmark", "alpha")
GROUND_TOLERANCE = 1e-3  # m


def path(name):
    return harness.fresh_result(work, name)


def restart_case(name, label, scene, options, steps):
    full, part, cont = path(name + "_full"), path(name + "_part"), path(name + "_cont")
    harness.run(args, 2, ["-scene", scene, "-steps", steps, "-output", full, "-quiet"] + options)
    harness.run(args, 2, ["-scene", scene, "-steps", steps // 2, "-checkpoint_every", steps // 2,
                          "-output", part, "-quiet"] + options)
    with h5py.File(part, "r") as f:
        slot = f["checkpoint/0"]
        stored = (slot.attrs["integrator"].decode() if "integrator" in slot.attrs else "",
                  sorted(k for k in slot.keys()))
    harness.run(args, 2, ["-scene", scene, "-steps", steps, "-restart", part, "-output", cont, "-quiet"] + options)
    a, b = harness.read_frames(full), harness.read_frames(cont)
    same = len(a["time"]) == len(b["time"]) and all(np.array_equal(a[k], b[k]) for k in ("time", "positions",
                                                                                         "velocities"))
    worst = 0.0 if same or len(a["time"]) != len(b["time"]) else \
        max(np.abs(a[k] - b[k]).max() for k in ("positions", "velocities"))
    checks.check(same and b["complete"] == 1,
                 f"{'' if label.startswith('(') else '(a) '}{label}: {len(b['time'])} frames bit for bit equal after the restart"
                 + ("" if same else f" (largest difference {worst:.3e})")
                 + f"; checkpoint integrator '{stored[0]}', datasets {', '.join(stored[1])}")
    return full, part


cube = harness.box_mesh(args, "cube.mesh", (0.5, 0.5, 0.5), (4, 4, 4))
bar_mesh = harness.box_mesh(args, "bar.mesh", (1.0, 0.25, 0.25), (8, 2, 2))
bar = harness.write_scene(os.path.join(work, "bar.txt"),
                          [("bar.mesh", 1000.0, 1e5, 0.3, 0, (0, 0, 0), (1, 0, 0, 0))],
                          [(0, 9 * j + 27 * k, (0, 0, 2.0)) for j in range(3) for k in range(3)])
drop = harness.write_scene(os.path.join(work, "drop.txt"),
                           [("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, 0.3, 0), (1, 0, 0, 0))])
world = ["-gravity", "0,-9.81,0", "-ground", "0", "-dt", "0.01", "-restitution", "0.2", "-friction", "0.3"]
expected_datasets = {"bdf2": {"previous_positions", "previous_velocities"}, "alpha": {"accelerations"},
                     "newmark": set()}

for scheme in SCHEMES:
    integrator = ["-integrator", scheme]
    full, part = restart_case(f"beam_{scheme}", f"{scheme}, linear, beam scene", beam, integrator, 30)
    with h5py.File(part, "r") as f:
        slot = f["checkpoint/0"]
        names = set(slot.keys())
        ok = slot.attrs["integrator"].decode() == scheme and expected_datasets[scheme] <= names
    checks.check(ok, f"(a) {scheme}: the checkpoint names the integrator and holds "
                     f"{sorted(expected_datasets[scheme]) or 'no extra vectors'}")
    if scheme == "bdf2":
        frames = harness.read_frames(full)
        with h5py.File(part, "r") as f:
            previous = f["checkpoint/0/previous_positions"][()]
        checks.check(np.array_equal(previous, frames["positions"][14]),
                     "(c) bdf2: the checkpoint's previous_positions (after step 15) are the positions "
                     "of step 14 bit for bit")
    restart_case(f"bar_{scheme}", f"{scheme}, corotational bar, -deform, -dt_schedule", bar,
                 integrator + ["-mode", "corotational", "-deform", "0:0.1:1.05,1,1;0:0.5:1,0.95,1",
                               "-dt_schedule", "0.4:0.01"], 40)
    for mode in ("linear", "corotational"):
        full, _ = restart_case(f"drop_{mode}_{scheme}", f"{scheme}, {mode} drop on the ground", drop,
                               world + integrator + ["-mode", mode], 100)
        r = harness.read_frames(full)
        lowest = r["positions"][:, :, 1].min()
        fall = 1000.0 * 0.125 * 9.81 * 0.3
        kinetic = r["energy/kinetic"][-1]
        centre = r["positions"][-1][:, 1].mean()
        checks.check(lowest > -GROUND_TOLERANCE and kinetic < 1e-3 * fall and abs(centre / 0.25 - 1) < 0.02,
                     f"(b) {scheme}, {mode} drop: lowest vertex y = {lowest:.2e} m (> -{GROUND_TOLERANCE:g}), "
                     f"kinetic energy at the end {kinetic:.2e} J (< 1e-3 of the fall's {fall:.3g} J), "
                     f"centre at {centre:.4f} m (0.25 m to 2 %)")

for scheme, mode in (("bdf2", "linear"), ("bdf2", "corotational"), ("alpha", "linear")):
    restart_case(f"adapt_{mode}_{scheme}", f"(e) {scheme}, {mode} struck bar, -dt_adapt", bar,
                 ["-integrator", scheme, "-mode", mode, "-dt_adapt", "-tol", "1e-4", "-dt", "0.05",
                  "-dt_adapt_horizon", "1.0"], 20)  # 20 steps of 0.05 s: the first part runs only 10

part = path("switch_part")
harness.run(args, 2, ["-scene", beam, "-steps", 10, "-checkpoint_every", 10, "-output", part, "-quiet"])
cont = path("switch_cont")
r = harness.run(args, 2, ["-scene", beam, "-steps", 20, "-restart", part, "-output", cont, "-quiet",
                          "-integrator", "bdf2"], check=False)
frames = harness.read_frames(cont) if r.returncode == 0 else None
checks.check(frames is not None and frames["complete"] == 1 and np.isfinite(frames["positions"]).all(),
             f"(d) be's checkpoint continued with -integrator bdf2: exit {r.returncode}")
checks.exit()
