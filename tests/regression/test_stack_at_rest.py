"""Three blocks stacked on the ground (scenes/contact/stack-scene.txt) come to rest.

Free-free contact is two-sided (src/solvers/projected_solve.hpp): a vertex and
the other body's face point get equal and opposite impulses in the same solve.
Before, each side's vertex was sent to the midpoint of the two predictions and
its reaction acted on its own body only; the stack never came to rest
(frictionless, kinetic energy 0.27 to 0.58 of the potential energy after 10 s).

The scene with blocks of 2 x 2 x 2 cells (tools/box_mesh.py; the scene's own
4 x 4 x 4 take 4 times longer and behave alike), frictionless (the scene as
given), dt = 0.01 s, STEPS steps, 2 ranks, linear and corotational mode:
(a) the kinetic energy at the end is below KINETIC_BOUND of the initial
    gravitational energy (measured 4.3e-6 and 4.6e-6 at 0.5 s; before, 2.8e-2 and
    2.0e-2);
(b) the stack's gravitational energy drop is the drop of a monolithic
    1 x 3 x 1 m column of the same material and mesh size (2 x 6 x 2 cells)
    within DROP_TOLERANCE: the blocks carry each other's weight as the column's
    layers do (measured 0.2 % and 0.3 % off; before, the stacks sank into each
    other, 2.2 and 1.7 times the column's drop);
(c) softbody-crossings (exact predicates): no crossing pair in any frame.
(d) Issue 14's goal on the scene as given (blocks of 4 x 4 x 4 cells,
    frictionless), linear mode, 1 rank, 10 s (1 000 steps): kinetic energy below
    1e-6 of the initial gravitational energy, and no crossing. The guard's
    zones between free bodies used to push the whole stack sideways (their held
    vertices' reactions: 2.6 N along x = z), a drift of 5 mm/s at 10 s, 1.7e-6;
    with the impulse they create from nothing taken back (contact.hpp,
    CancelHeldImpulse, outside the directions in which the ground holds the
    stack), 1.8e-10; also checked below 1e-8 (1.7e-7 when the part the ground
    answers was taken back too).
Skipped when softbody-crossings was not built (no CGAL): (c) and (d)'s crossings.
"""
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STACK = os.path.join(ROOT, "scenes", "contact", "stack-scene.txt")
STEPS = 50
CELLS = 2
OPTIONS = ["-options_file", os.path.join(ROOT, "config", "practical3.opts"), "-dt", "0.01",
           "-steps", str(STEPS), "-output_every", "5"]
KINETIC_BOUND = 1e-4   # of the initial gravitational energy
DROP_TOLERANCE = 0.05  # relative to the column's drop
REST_GOAL = 1e-6       # issue 14: "kinetic energy below 1e-6 of the stack's potential energy"
# Measured 1.8e-10; 1.7e-7 when the held vertices' whole impulse was taken back,
# the part the ground answers included (contact.cpp, CancelHeldImpulse).
REST_MEASURED_BOUND = 1e-8

args = harness.arguments()
checks = harness.Checks()
harness.crossings_checker(args)



def box(name, size, cells):
    path = os.path.join(args.work, name)
    subprocess.run([sys.executable, os.path.join(ROOT, "tools", "box_mesh.py"), path, "-box_size",
                    *map(str, size), "-box_cells", *map(str, cells)], check=True, capture_output=True)
    return path


# The scene's blocks with CELLS cells per edge (the scene's own 4 take 4 times longer).
block_mesh, column_mesh = box("block.mesh", (1, 1, 1), (CELLS,) * 3), box(
    "column.mesh", (1, 3, 1), (CELLS, 3 * CELLS, CELLS))
stack_scene = os.path.join(args.work, "stack-scene.txt")
with open(stack_scene, "w") as f:
    f.write("".join(line.replace("block.mesh", block_mesh) for line in open(STACK)))
column_scene = os.path.join(args.work, "column-scene.txt")
with open(column_scene, "w") as f:
    # The stack's blocks span y = 0.001 to 3.003 with 1 mm gaps; the column 0.002 to 3.002:
    # both fall 6 mm x 1000 kg in all before touching.
    f.write(f"1\n{column_mesh} 1000 1e6 0.3 0 0 1.502 0 1 0 0 0\n")


def simulate(label, scene, mode, ranks):
    out = harness.fresh_result(args.work, label)
    harness.run(args, ranks, ["-scene", scene, "-mode", mode, "-output", out] + OPTIONS)
    return harness.read_frames(out), out


for mode in ("linear", "corotational"):
    column, _ = simulate(f"column-{mode}", column_scene, mode, 1)
    stack, path = simulate(f"stack-{mode}", stack_scene, mode, 2)
    gravitational = stack["energy/gravitational"]
    rest = stack["energy/kinetic"][-1] / gravitational[0]
    checks.check(rest < KINETIC_BOUND, f"(a) {mode}: kinetic over initial gravitational energy at "
                 f"{STEPS * 0.01:.1f} s {rest:.1e} < {KINETIC_BOUND}")
    drop = gravitational[-1] - gravitational[0]
    column_drop = column["energy/gravitational"][-1] - column["energy/gravitational"][0]
    checks.check(abs(drop - column_drop) <= DROP_TOLERANCE * abs(column_drop),
                 f"(b) {mode}: the stack's gravitational energy drop {drop:.1f} J, the column's "
                 f"{column_drop:.1f} J (within {DROP_TOLERANCE:.0%})")
    report = harness.run_crossings(args, checks, path)
    if report:
        worst = max(sum(frame[k] for k in ("free_free", "free_fixed", "self", "below_ground"))
                    for frame in report["frames"])
        checks.check(worst == 0, f"(c) {mode}: largest crossing count in a frame {worst} (0)")

# (d) The scene as given for 10 s.
out = harness.fresh_result(args.work, "stack-as-given")
harness.run(args, 1, ["-scene", STACK, "-options_file", os.path.join(ROOT, "config", "practical3.opts"),
                      "-dt", "0.01", "-steps", "1000", "-output_every", "100", "-output", out])
given = harness.read_frames(out)
rest = given["energy/kinetic"][-1] / given["energy/gravitational"][0]
checks.check(rest < REST_GOAL, f"(d) as given, linear, 10 s: kinetic over initial gravitational energy "
             f"{rest:.2e} < {REST_GOAL:g}")
checks.check(rest < REST_MEASURED_BOUND, f"(d) as given: {rest:.2e} < {REST_MEASURED_BOUND:g} (the ground "
             f"answers the held vertices' impulse along its normal)")
report = harness.run_crossings(args, checks, out)
if report:
    worst = max(sum(frame[k] for k in ("free_free", "free_fixed", "self", "below_ground"))
                for frame in report["frames"])
    checks.check(worst == 0, f"(d) as given: largest crossing count in a frame {worst} (0)")
checks.exit()
