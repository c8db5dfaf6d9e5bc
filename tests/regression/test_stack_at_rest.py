"""Three blocks stacked on the ground (scenes/contact/stack-scene.txt) settle as one column would.

The independent reference: a single 1 x 3 x 1 m column of the same material and
mesh size (tools/box_mesh.py, 4 x 12 x 4 cells), standing on the ground like the
stack. Resting on each other, the blocks must carry each other's weight as the
column's layers do, so the stack's potential energy drop (its compression, and
the 1 to 3 mm gaps of the scene closing) equals the column's.

With -friction 0.5, dt = 0.01 s, 100 steps (1 s), 2 ranks, linear and
corotational mode:
(a) the stack's gravitational energy drop at 1 s is the column's within 5 %
    (measured 1.9 % and 0.9 %; before free-free contacts took the face facing
    the vertex and handed their reactions over to the face, both stacks dropped
    about 4 times as much by 1 s, and the corotational one toppled at 4 s);
(b) softbody-crossings (exact predicates): no crossing pair in any frame;
(c) the kinetic energy at 1 s is below 1e-3 of the initial gravitational energy
    (a bound against falling apart, not the rest the issue asks for: the stack
    still jitters at 1e-5 to 1e-4 of it, docs/contact.md).
Skipped when softbody-crossings was not built (no CGAL).
"""
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STACK = os.path.join(ROOT, "scenes", "contact", "stack-scene.txt")
OPTIONS = ["-options_file", os.path.join(ROOT, "config", "practical3.opts"), "-friction", "0.5",
           "-dt", "0.01", "-steps", "100", "-output_every", "10"]
DROP_TOLERANCE = 0.05  # relative to the column's drop
KINETIC_BOUND = 1e-3   # of the initial gravitational energy

args = harness.arguments()
checks = harness.Checks()
harness.crossings_checker(args)

column_mesh = os.path.join(args.work, "column.mesh")
subprocess.run([sys.executable, os.path.join(ROOT, "tools", "box_mesh.py"), column_mesh,
                "-box_size", "1", "3", "1", "-box_cells", "4", "12", "4"], check=True, capture_output=True)
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
    print(f"{mode} mode")
    column, _ = simulate(f"column-{mode}", column_scene, mode, 1)
    stack, path = simulate(f"stack-{mode}", STACK, mode, 2)
    gravitational = stack["energy/gravitational"]
    drop = gravitational[-1] - gravitational[0]
    column_drop = column["energy/gravitational"][-1] - column["energy/gravitational"][0]
    checks.check(abs(drop - column_drop) <= DROP_TOLERANCE * abs(column_drop),
                 f"(a) {mode}: the stack's gravitational energy drop {drop:.1f} J, the column's "
                 f"{column_drop:.1f} J (within {DROP_TOLERANCE:.0%})")
    report = harness.run_crossings(args, checks, path)
    if report:
        worst = max(sum(frame[k] for k in ("free_free", "free_fixed", "self", "below_ground"))
                    for frame in report["frames"])
        checks.check(worst == 0, f"(b) {mode}: largest crossing count in a frame {worst} (0)")
    rest = stack["energy/kinetic"][-1] / gravitational[0]
    checks.check(rest < KINETIC_BOUND, f"(c) {mode}: kinetic over initial gravitational energy at 1 s "
                                       f"{rest:.1e} < {KINETIC_BOUND}")
checks.exit()
