"""Checkpoints and restart and the restart file's early
checks (item 8).

Each case runs N steps uninterrupted, then N/2 steps with -checkpoint_every,
then -restart from that file with -steps N, and compares the frames:
(a) linear (direct solver), 2 ranks, the beam scene: the continued run (into
    a new file, and the checkpointed file continued in place) equals the
    uninterrupted one bit for bit at every frame; the new file holds the first
    frames copied from the restart file; the in-place file is complete.
(b) corotational (CG + GAMG), 2 ranks, a struck bar with a -deform event
    before and one after the checkpoint and a -dt_schedule change after it:
    bit for bit.
(c) contact: a cube dropped on the ground (gravity, restitution, friction),
    2 ranks, checkpoint while it rests (the checkpoint holds resting
    contacts): bit for bit, in both modes; two cubes thrown at each other
    (free bodies as obstacles): bit for bit; a cube landing on a fixed cube
    with a third of it over the edge (the checkpoint holds resting contacts
    of the edge's points): bit for bit; the stack of three blocks
    (scenes/contact/stack-scene.txt: two-sided contacts throughout, whose
    solve keeps columns of A^-1 across steps, two_sided_solve.cpp): bit for
    bit (a kept block of A^-1 whose entries depended on which vertices
    entered it together failed this).
(d) 2 ranks -> 1 rank: to round-off (linear, direct: 1e-12 of the largest
    displacement) or the solver tolerance (corotational, CG rtol 1e-10: 1e-7).
(e) restart twice in a row (checkpoints alternate between two slots).
(f) fail early, with one line naming the option, before any step and leaving
    no new output (2 ranks; every third case on 1 rank too): a restart file of
    another scene (bodies, material, placement), a file without checkpoint,
    a missing file, -steps before the checkpoint, a different number of
    -deform events, -checkpoint_every without -output; -output into a missing
    folder or onto a folder is reported before the scene is read.
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


def path(name):
    return harness.fresh_result(work, name)


def compare(label, reference, result, exact=True, tolerance=0.0):
    a, b = harness.read_frames(reference), harness.read_frames(result)
    same_times = len(a["time"]) == len(b["time"]) and np.array_equal(a["time"], b["time"])
    if exact:
        ok = same_times and all(np.array_equal(a[k], b[k]) for k in ("positions", "velocities"))
        worst = 0.0 if ok or not same_times else max(np.abs(a[k] - b[k]).max() for k in ("positions", "velocities"))
        checks.check(ok and b["complete"] == 1,
                     f"{label}: {len(b['time'])} frames, positions and velocities bit for bit equal"
                     + ("" if ok else f" (largest difference {worst:.3e})"))
    else:
        scale = np.abs(a["positions"][-1] - a["mesh/rest_positions"]).max()
        difference = np.abs(a["positions"][-1] - b["positions"][-1]).max() / scale
        checks.check(same_times and difference < tolerance and b["complete"] == 1,
                     f"{label}: last frame's positions differ by {difference:.2e} of the largest displacement "
                     f"(< {tolerance:g})")
    return b


def restart_case(name, label, scene, options, steps, ranks=2, restart_ranks=None, exact=True, tolerance=0.0,
                 in_place=True):
    full, part, cont = path(name + "_full"), path(name + "_part"), path(name + "_cont")
    harness.run(args, ranks, ["-scene", scene, "-steps", steps, "-output", full, "-quiet"] + options)
    harness.run(args, ranks, ["-scene", scene, "-steps", steps // 2, "-checkpoint_every", steps // 2,
                              "-output", part, "-quiet"] + options)
    checkpoint = harness.read_all_datasets(part)
    harness.run(args, restart_ranks or ranks, ["-scene", scene, "-steps", steps, "-restart", part,
                                               "-output", cont, "-quiet"] + options)
    compare(f"{label}, new file", full, cont, exact, tolerance)
    if in_place:
        harness.run(args, restart_ranks or ranks, ["-scene", scene, "-steps", steps, "-restart", part,
                                                   "-quiet"] + options)
        compare(f"{label}, continued in place", full, part, exact, tolerance)
    return checkpoint


cube = harness.box_mesh(args, "cube.mesh", (0.5, 0.5, 0.5), (4, 4, 4))
bar_mesh = harness.box_mesh(args, "bar.mesh", (1.0, 0.25, 0.25), (8, 2, 2))
# The bar struck sideways at its x = 0 end (vertices i = 0 of the 9 x 3 x 3 grid).
bar = harness.write_scene(os.path.join(work, "bar.txt"),
                          [("bar.mesh", 1000.0, 1e5, 0.3, 0, (0, 0, 0), (1, 0, 0, 0))],
                          [(0, 9 * j + 27 * k, (0, 0, 2.0)) for j in range(3) for k in range(3)])

print("(a) linear, direct solver")
restart_case("a", "(a) linear 2 ranks, beam scene", beam, [], 30)

print("(b) corotational, CG + GAMG, -deform, -dt_schedule")
restart_case("b", "(b) corotational 2 ranks", bar,
             ["-mode", "corotational", "-deform", "0:0.1:1.05,1,1;0:0.5:1,0.95,1", "-dt_schedule", "0.4:0.01"],
             40)

print("(c) contact")
drop = harness.write_scene(os.path.join(work, "drop.txt"),
                           [("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, 0.3, 0), (1, 0, 0, 0))])
pair = harness.write_scene(os.path.join(work, "pair.txt"),
                           [("cube.mesh", 1000.0, 1e6, 0.3, 0, (-0.6, 0.3, 0), (1, 0, 0, 0)),
                            ("cube.mesh", 1000.0, 1e6, 0.3, 0, (0.6, 0.4, 0), (1, 0, 0, 0))],
                           [(0, k, (3.0, 0, 0)) for k in range(125)] + [(1, k, (-3.0, 0, 0)) for k in range(125)])
world = ["-gravity", "0,-9.81,0", "-ground", "0", "-dt", "0.01", "-restitution", "0.2", "-friction", "0.3"]
checkpoint = restart_case("drop", "(c) drop, linear", drop, world, 60)
resting = checkpoint["checkpoint/0/resting_contacts"]
checks.check(len(resting) > 0 and bool(np.all(resting[:, 1] == -1)),
             f"(c) the checkpoint at step 30 holds {len(resting)} resting contacts with the ground")
restart_case("drop_corotational", "(c) drop, corotational", drop, world + ["-mode", "corotational"], 60,
             in_place=False)
restart_case("pair", "(c) pair of free bodies", pair, world, 60, in_place=False)
ledge = harness.write_scene(os.path.join(work, "ledge.txt"),
                            [("cube.mesh", 1000.0, 1e6, 0.3, 1, (0, 0, 0), (1, 0, 0, 0)),
                             ("cube.mesh", 1000.0, 1e6, 0.3, 0, (0.15, 0.51, 0), (1, 0, 0, 0))])
checkpoint = restart_case("ledge", "(c) cube on a fixed cube's edge", ledge, world, 60, in_place=False)
root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
restart_case("stack", "(c) stack of three blocks (two-sided contacts)",
             os.path.join(root, "scenes", "contact", "stack-scene.txt"),
             ["-options_file", os.path.join(root, "config", "practical3.opts"), "-dt", "0.01"], 60,
             in_place=False)
resting = checkpoint["checkpoint/0/resting_contacts"]
checks.check(bool(np.any(resting[:, 1] <= -2)),
             f"(c) the ledge checkpoint holds {int(np.sum(resting[:, 1] <= -2))} resting sharp-edge contacts "
             f"(written -2 - feature point)")

print("(d) another rank count")
restart_case("d_linear", "(d) linear 2->1 ranks, beam scene", beam, [], 30, restart_ranks=1, exact=False,
             tolerance=1e-12, in_place=False)
restart_case("d_corotational", "(d) corotational 2->1 ranks", bar, ["-mode", "corotational"], 40, restart_ranks=1,
             exact=False, tolerance=1e-7, in_place=False)

print("(e) two restarts in a row")
full, chain = path("chain_full"), path("chain")
harness.run(args, 2, ["-scene", bar, "-steps", 30, "-output", full, "-quiet", "-mode", "corotational"])
harness.run(args, 2, ["-scene", bar, "-steps", 10, "-checkpoint_every", 4, "-output", chain, "-quiet",
                      "-mode", "corotational"])
harness.run(args, 2, ["-scene", bar, "-steps", 20, "-checkpoint_every", 4, "-restart", chain, "-quiet",
                      "-mode", "corotational"])
with h5py.File(chain, "r") as f:
    slots = sorted(int(f[f"checkpoint/{s}"].attrs["step"]) for s in (0, 1))
harness.run(args, 2, ["-scene", bar, "-steps", 30, "-restart", chain, "-quiet", "-mode", "corotational"])
compare(f"(e) restarted at 10, then at 20 (slots hold steps {slots})", full, chain)

print("(f) fail early")
other = harness.write_scene(os.path.join(work, "other.txt"),
                            [("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, 0.3, 0), (1, 0, 0, 0)),
                             ("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, 2, 0), (1, 0, 0, 0))])
softer = harness.write_scene(os.path.join(work, "softer.txt"),
                             [("cube.mesh", 1000.0, 5e5, 0.3, 0, (0, 0.3, 0), (1, 0, 0, 0))])
moved = harness.write_scene(os.path.join(work, "moved.txt"),
                            [("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, 0.4, 0), (1, 0, 0, 0))])
no_checkpoint = path("no_checkpoint")
harness.run(args, 1, ["-scene", drop, "-steps", 2, "-output", no_checkpoint, "-quiet"])
part = os.path.join(work, "drop_part.h5")  # the drop's checkpoint at step 30 from (c)
fresh = os.path.join(work, "must_not_exist.h5")
with open(os.path.join(work, "regular_file"), "w") as f:
    f.write("not a folder\n")
cases = [
    ("a restart file of another scene", ["-scene", other, "-steps", 40, "-restart", part, "-output", fresh],
     ["option -restart", "does not match the scene", "1 body, the scene 2"]),
    ("another material", ["-scene", softer, "-steps", 40, "-restart", part, "-output", fresh],
     ["option -restart", "does not match the scene", "material"]),
    ("other rest positions", ["-scene", moved, "-steps", 40, "-restart", part, "-output", fresh],
     ["option -restart", "does not match the scene", "rest positions"]),
    ("no checkpoint in the file", ["-scene", drop, "-steps", 40, "-restart", no_checkpoint, "-output", fresh],
     ["option -restart", "no checkpoint"]),
    ("a missing restart file", ["-scene", drop, "-steps", 40, "-restart", os.path.join(work, "nothing.h5"),
                                "-output", fresh], ["option -restart", "cannot open"]),
    ("-steps before the checkpoint", ["-scene", drop, "-steps", 20, "-restart", part, "-output", fresh] + world,
     ["option -steps", "before the checkpoint", "step 30"]),
    ("another number of -deform events", ["-scene", drop, "-steps", 40, "-restart", part, "-output", fresh,
                                          "-deform", "0:0.5:1,1.1,1"], ["option -restart", "-deform"]),
    ("-checkpoint_every without -output", ["-scene", drop, "-steps", 4, "-checkpoint_every", 2],
     ["option -checkpoint_every", "-output"]),
    ("-output into a missing folder", ["-scene", os.path.join(work, "no_scene_read.txt"), "-steps", 4,
                                       "-output", os.path.join(work, "no_folder", "x.h5")],
     ["option -output", "does not exist"]),
    ("-output under a regular file", ["-scene", drop, "-steps", 4,
                                      "-output", os.path.join(work, "regular_file", "x.h5")],
     ["option -output", "not a folder"]),
    ("-output onto a folder", ["-scene", drop, "-steps", 4, "-output", work], ["option -output", "folder"]),
]
for number, (label, options, keys) in enumerate(cases):
    for ranks in ((2, 1) if number % 3 == 0 else (2,)):
        r = harness.run(args, ranks, options, check=False, timeout=120)
        errors = [line for line in r.stderr.splitlines() if line.startswith("softbody: error:")]
        ok = (r.returncode != 0 and len(errors) == 1 and all(k in errors[0] for k in keys)
              and "PETSC ERROR" not in r.stderr and "run summary" not in r.stdout and not os.path.exists(fresh))
        checks.check(ok, f"(f) [{ranks} rank{'s' if ranks > 1 else ''}] {label}: exit {r.returncode}, "
                         f"'{errors[0] if errors else r.stderr.strip()[:200]}'")
checks.exit()
