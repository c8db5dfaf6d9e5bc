"""The cost of contact steps (issue 14) and what was done to cut it, checked on
the wedge drop (scenes/contact/wedge-scene.txt: a soft cube dropped edge-first
onto a fixed wedge; it falls free for 0.2 s, then lands; -dt 0.01, 60 steps).

(a) The run summary's "steps" line splits the time loop's steps into those with
    contact and those without: both kinds occur, they add up to the steps
    taken, and their solves add up to the summary's.
(b) The guard keeps its answer for positions it has just found clean
    (-contact_guard_reuse, on by default): with it the frames are bit for bit
    those of -contact_guard_reuse 0, and some probes repeat a clean one (none
    without), linear and corotational, 2 ranks.
(c) Linear mode with the direct solver: the constrained solves' preconditioner
    sees the constraints (solvers/constraint_correction.hpp), so each contact
    solve ends in at most 2 CG iterations (the plain preconditioner needs about
    one per constraint: 10 to 40 here, as with -constraint_correction 0);
    corotational mode (the warp preconditioner) keeps the plain one.
(d) The two-sided (Delassus) solve's complementarity problem settles in a
    few active-set solves: a 1 x 0.5 x 1 m box of 6 x 4 x 7 cells landing flat
    on another resting on the ground (1 rank, -info :ksp): every two-sided
    solve ends exact in at most MAX_ACTIVE_SET_SOLVES (measured 4; one row
    changing side per solve took 33 on the first contact, and 100 then
    Gauss-Seidel at 1e4 tets).
(e) The two-sided solve keeps the columns A^-1 e of its rows' vertices while
    A keeps its values (two_sided_solve.cpp), on the stack of three blocks
    (scenes/contact/stack-scene.txt, linear, 2 ranks, 100 steps of 0.01 s):
    the frames agree with -constraint_correction 0 (a back-solve per row in
    every solve) to 1e-9 of the largest position and velocity (measured 1e-13
    m and 3.6e-13 m/s), and a contact step takes at most a quarter of its
    back-solves (measured 13.5 against 175). On 1 rank the back-solve per row
    runs four rows per sweep of the factor (TiledFactor::SolveColumns through
    the PC's PCMatApply): its frames agree with the kept columns' to the same
    1e-9 (measured 2e-12 m).
"""
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENE = os.path.join(ROOT, "scenes", "contact", "wedge-scene.txt")
MAX_ACTIVE_SET_SOLVES = 12
STACK = os.path.join(ROOT, "scenes", "contact", "stack-scene.txt")
AGREEMENT = 1e-9         # of the largest |x| and |v|: the solver's round-off, not its tolerance
BACK_SOLVE_SHARE = 0.25  # measured 13.5 / 175
OPTIONS = ["-options_file", os.path.join(ROOT, "config", "practical3.opts"), "-dt", "0.01", "-steps", "60"]
STEPS = 60

args = harness.arguments()
checks = harness.Checks()


def simulate(label, ranks, extra=(), scene=SCENE, options=OPTIONS):
    out = harness.fresh_result(args.work, label)
    result = harness.run(args, ranks, ["-scene", scene, "-output", out] + options + list(extra))
    return harness.read_frames(out), result.stdout


def step_kinds(stdout):
    """(steps, solves per step, iterations per step) with contact and without."""
    line = re.search(r"steps +with contact (\d+) \(.*?; ([\d.e+-]+) solves and ([\d.e+-]+) iterations per step\), "
                     r"without (\d+) \(.*?; ([\d.e+-]+) solves and ([\d.e+-]+) iterations per step\)", stdout)
    if not line:
        return None
    g = line.groups()
    return (int(g[0]), float(g[1]), float(g[2])), (int(g[3]), float(g[4]), float(g[5]))


def probes(stdout):
    found = re.search(r"(\d+) probes, (\d+) of them repeating a clean one's positions", stdout)
    return (int(found.group(1)), int(found.group(2))) if found else None


def same_frames(a, b):
    """Every dataset equal, bit for bit."""
    return a.keys() == b.keys() and all(np.array_equal(np.asarray(a[k]), np.asarray(b[k])) for k in a)


print("(a) the summary's steps with and without contact")
frames, stdout = simulate("linear", 2, ["-mode", "linear"])
kinds = step_kinds(stdout)
solves = re.search(r"(\d+) solves, iterations per step", stdout)
checks.check(kinds is not None and solves is not None, "(a) the summary has a steps line and a solves count")
if kinds and solves:
    (contact_steps, contact_solves, _), (free_steps, free_solves, _) = kinds
    total = contact_steps * contact_solves + free_steps * free_solves
    checks.check(contact_steps > 0 and free_steps > 0 and contact_steps + free_steps == STEPS,
                 f"(a) {contact_steps} steps with contact and {free_steps} without, of {STEPS}")
    checks.check(abs(total - int(solves.group(1))) < 0.01 * int(solves.group(1)) + 1,
                 f"(a) their solves add up: {total:.1f} against the summary's {solves.group(1)}")

print("(b) the guard's reuse of a clean probe changes nothing")
for mode in ("linear", "corotational"):
    reused, out_reused = (frames, stdout) if mode == "linear" else simulate(f"{mode}", 2, ["-mode", mode])
    again, out_again = simulate(f"{mode}-no-reuse", 2, ["-mode", mode, "-contact_guard_reuse", "0"])
    counts, counts_again = probes(out_reused), probes(out_again)
    checks.check(same_frames(reused, again), f"(b) {mode}: frames bit for bit with -contact_guard_reuse 0")
    checks.check(counts is not None and counts[1] > 0 and counts_again is not None and counts_again[1] == 0
                 and counts[0] == counts_again[0],
                 f"(b) {mode}: probes (all, repeating a clean one) {counts} with reuse, {counts_again} without")

print("(c) contact solves with the constraint correction (linear, direct solver)")
if kinds:
    (contact_steps, contact_solves, contact_iterations), _ = kinds
    checks.check(contact_iterations <= 2 * contact_solves,
                 f"(c) linear: {contact_iterations:g} CG iterations per contact step in {contact_solves:g} solves")
for name, label, options in (
        ("linear-plain", "linear, -constraint_correction 0 (plain preconditioner)",
         ["-mode", "linear", "-constraint_correction", "0"]),
        ("corotational-check", "corotational (plain preconditioner)", ["-mode", "corotational"])):
    plain = step_kinds(simulate(name, 1, options)[1])
    if plain:
        (steps, solves_per_step, iterations), _ = plain
        checks.check(iterations > 2 * solves_per_step,
                     f"(c) {label}: {iterations:g} iterations per contact step in {solves_per_step:g} solves")

print("(d) the two-sided solve's complementarity problem (a box landing flat on another)")
box = harness.box_mesh(args, "flat-box.mesh", (1.0, 0.5, 1.0), (6, 4, 7))
flat_scene = os.path.join(args.work, "flat-scene.txt")
with open(flat_scene, "w") as f:  # centroids 1 mm above the ground and 2 mm above the lower box
    f.write(f"2\n{box} 1000 1e6 0.4 0 0 0.251 0 1 0 0 0\n{box} 1000 1e6 0.4 0 0 0.753 0 1 0 0 0\n")
info = harness.run(args, 1, ["-scene", flat_scene, "-gravity", "0,-9.81,0", "-ground", "0", "-steps", "3",
                             "-info", ":ksp"]).stdout
solves = re.findall(r"two-sided contact solve: (\d+) rows .*?, (\d+) active-set solves, .*?\((\w[\w-]*)\)", info)
checks.check(len(solves) > 0, f"(d) {len(solves)} two-sided solves reported")
for rows, pivots, how in solves:
    checks.check(how == "exact" and int(pivots) <= MAX_ACTIVE_SET_SOLVES,
                 f"(d) {rows} rows: {pivots} active-set solves <= {MAX_ACTIVE_SET_SOLVES}, {how}")

print("(e) the two-sided solve's kept columns (stack, linear, 2 ranks)")
stack_options = ["-options_file", os.path.join(ROOT, "config", "practical3.opts"), "-dt", "0.01", "-steps", "100",
                 "-output_every", "10"]


def check_agreement(kept, plain, label):
    """(e): frames with the kept columns and with a back-solve per row agree."""
    for key in ("positions", "velocities"):
        a, b = np.asarray(kept[key]), np.asarray(plain[key])
        difference, largest = np.abs(a - b).max(), np.abs(b).max()
        checks.check(a.shape == b.shape and difference <= AGREEMENT * largest,
                     f"(e) {label}{key}: largest difference {difference:.2e} <= {AGREEMENT:g} x {largest:.3g}")


kept, kept_out = simulate("stack-columns", 2, [], STACK, stack_options)
plain, plain_out = simulate("stack-per-row", 2, ["-constraint_correction", "0"], STACK, stack_options)
check_agreement(kept, plain, "")
kinds_kept, kinds_plain = step_kinds(kept_out), step_kinds(plain_out)
checks.check(kinds_kept is not None and kinds_plain is not None, "(e) both summaries have a steps line")
if kinds_kept and kinds_plain:
    with_columns, per_row = kinds_kept[0][2], kinds_plain[0][2]
    checks.check(with_columns <= BACK_SOLVE_SHARE * per_row,
                 f"(e) back-solves per contact step {with_columns:g} <= {BACK_SOLVE_SHARE:g} x {per_row:g}")
one_kept, _ = simulate("stack-columns-1", 1, [], STACK, stack_options)
one_rows, _ = simulate("stack-per-row-1", 1, ["-constraint_correction", "0"], STACK, stack_options)
check_agreement(one_kept, one_rows, "1 rank, rows four per sweep: ")
checks.exit()
