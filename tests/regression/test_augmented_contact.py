"""Two-sided contact with an iterative solver takes the augmented Lagrangian path
(src/solvers/augmented_solve.cpp), and it solves the same problem as the
Delassus path does with a factorisation.

Scene: two 1 x 0.5 x 1 m boxes of 12 x 5 x 12 cells stacked 2 mm apart above
the ground, under gravity, linear mode, dt = 0.01 s, STEPS steps: the lower
box lands on the ground and the upper one on it, up to 290 two-sided rows
(found from both sides) beside the ground's one-sided ones: over the 300
rows from which an iterative solver takes the augmented path.

(a) With config/cg-gamg.opts the contact steps take the augmented path (-info
    reports it), and with the direct preset the Delassus path (no such line).
(b) A contact step costs a few unconstrained solves' CG iterations, not one
    solve per row: iterations per contact step at most ITERATION_RATIO times
    those of a step without contact (measured 21: 441 against 21, 45 before
    the multipliers carried over from step to step; the Delassus path with CG
    + GAMG, one solve per row, takes about 460).
(c) The augmented path's frames agree with the direct solver's (the Delassus
    path, exact complementarity) to AGREEMENT of the largest position and
    velocity (1 rank), and (d) on 2 ranks with its own 1-rank frames.
(e) No surface crosses another (softbody-crossings, when built).
(f) The multipliers of resting two-sided contacts carry into the next step
    (and into checkpoints): once the boxes rest, a solve takes at most
    RESTING_OUTER outer iterations (measured 4; 9 when every step started from
    zero), and a run restarted from a checkpoint taken at step STEPS / 2 equals
    the uninterrupted one bit for bit (it differs by about the solve's
    tolerance if the checkpoint's reactions are not restored).
"""
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STEPS = 8
ITERATION_RATIO = 100
# Both solves hold the rows to their tolerances (the augmented path 1e-8 of the
# velocities, or 1e-4 where rows found from both sides stall it; CG's relative
# 1e-10): the frames differ by the accumulated tolerances, not by round-off.
# Measured: positions 3.0e-7, velocities 3.2e-5 against the direct solver;
# 3.3e-11 and 1.7e-8 between 1 and 2 ranks.
AGREEMENT = {"positions": 1e-6, "velocities": 1e-4}
RESTING_OUTER = 5

args = harness.arguments()
checks = harness.Checks()

box = harness.box_mesh(args, "box.mesh", (1, 0.5, 1), (12, 5, 12))
scene = os.path.join(args.work, "stacked-scene.txt")
with open(scene, "w") as f:
    f.write(f"2\n{box} 1000 1e6 0.4 0 0 0.251 0 1 0 0 0\n{box} 1000 1e6 0.4 0 0 0.753 0 1 0 0 0\n")
OPTIONS = ["-scene", scene, "-mode", "linear", "-dt", "0.01", "-steps", str(STEPS), "-gravity", "0,-9.81,0",
           "-ground", "0", "-info", ":sys"]


def simulate(label, ranks, solver, extra=()):
    out = harness.fresh_result(args.work, label)
    result = harness.run(args, ranks, OPTIONS + ["-output", out, "-options_file",
                                                 os.path.join(ROOT, "config", solver)] + list(extra))
    return harness.read_frames(out), out, result.stdout


def iterations(stdout, kind):
    """CG iterations per step of the summary's steps line, with or without contact."""
    match = re.search(kind + r" \d+ \([^;]*; [\d.e+]+ solves and ([\d.e+]+) iterations per step\)", stdout)
    return float(match.group(1)) if match else float("nan")


augmented, augmented_path, augmented_out = simulate("augmented-1", 1, "cg-gamg.opts")
direct, _, direct_out = simulate("direct-1", 1, "direct.opts")
two_ranks, _, _ = simulate("augmented-2", 2, "cg-gamg.opts")

rows = [int(m) for m in re.findall(r"augmented Lagrangian path: (\d+) rows", augmented_out)]
checks.check(len(rows) > 0, f"(a) cg-gamg: {len(rows)} solves by the augmented path, "
             f"up to {max(rows, default=0)} two-sided rows")
checks.check("augmented Lagrangian path" not in direct_out, "(a) direct: the Delassus path")

with_contact, without = iterations(augmented_out, "with contact"), iterations(augmented_out, "without")
checks.check(with_contact <= ITERATION_RATIO * without,
             f"(b) CG iterations per contact step {with_contact:g} <= {ITERATION_RATIO} x {without:g} "
             f"(a step without contact)")

for name, other, label in (("direct solver (Delassus path)", direct, "c"),
                           ("2 ranks", two_ranks, "d")):
    for key, tolerance in AGREEMENT.items():
        difference = harness.relative_difference(augmented[key], other[key])
        checks.check(difference <= tolerance, f"({label}) {key} against the {name}: "
                     f"{difference:.1e} of the largest (<= {tolerance:g})")

outers = [int(m) for m in re.findall(r"augmented Lagrangian path: .*?, (\d+) outer iterations", augmented_out)]
checks.check(len(outers) >= 4 and max(outers[-3:]) <= RESTING_OUTER,
             f"(f) outer iterations per augmented solve {outers}: the last three (at rest) <= {RESTING_OUTER}")
part = harness.fresh_result(args.work, "augmented-part")
half = OPTIONS[:OPTIONS.index("-steps")] + ["-steps", str(STEPS // 2)] + OPTIONS[OPTIONS.index("-steps") + 2:]
harness.run(args, 1, half + ["-checkpoint_every", str(STEPS // 2), "-output", part, "-options_file",
                             os.path.join(ROOT, "config", "cg-gamg.opts")])
slot = harness.read_all_datasets(part)
reactions = slot.get("checkpoint/0/resting_reactions", np.zeros(0)).ravel()
bodies = slot.get("checkpoint/0/resting_contacts", np.zeros((0, 2)))
two_sided = reactions[bodies[:, 1] >= 0] if len(reactions) == len(bodies) else np.zeros(0)
checks.check(len(two_sided) > 0 and bool(np.all(two_sided > 0)),
             f"(f) the checkpoint at step {STEPS // 2} holds {len(two_sided)} resting two-sided contacts, "
             f"each with a positive reaction")
restarted, _, _ = simulate("augmented-restarted", 1, "cg-gamg.opts", ["-restart", part])
same = all(np.array_equal(augmented[k], restarted[k]) for k in ("time", "positions", "velocities"))
worst = max(float(np.abs(augmented[k][-1] - restarted[k][-1]).max()) for k in ("positions", "velocities")) \
    if len(restarted["time"]) == len(augmented["time"]) else float("nan")
checks.check(same, f"(f) restarted at step {STEPS // 2}: the frames equal the uninterrupted run's bit for bit"
             + ("" if same else f" (largest difference {worst:.1e})"))

report = harness.run_crossings(args, checks, augmented_path)
if report:
    worst = max(sum(frame[k] for k in ("free_free", "free_fixed", "self", "below_ground"))
                for frame in report["frames"])
    checks.check(worst == 0, f"(e) largest crossing count in a frame {worst} (0)")

checks.exit()
