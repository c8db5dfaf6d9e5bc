"""The run summary prints numbers plainly: "shear scale 1", "t = 2 s",
"gravity (0, -9.81, 0)", never PETSc's "1." with a bare trailing dot.

Runs the beam scene for 100 steps of 0.02 s with gravity on one and two ranks
and checks the summary's model and energy lines, and that no number in the
summary ends with a bare '.'.
"""
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()
scene = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scenes", "beam-scene.txt")
BARE_DOT = re.compile(r"(?<![\w.])[-+]?\d+\.(?!\d)")  # "1." or "2." but not "0.02" or "e.g."

for ranks in (1, 2):
    result = harness.run(args, ranks, ["-scene", scene, "-steps", 100, "-dt", 0.02, "-gravity", "0,-9.81,0",
                                       "-shear_scale", 1])
    summary = result.stdout[result.stdout.find("softbody run summary"):]
    model = next((line for line in summary.splitlines() if line.strip().startswith("model")), "")
    energy = next((line for line in summary.splitlines() if line.strip().startswith("energy")), "")
    checks.check("shear scale 1;" in model and "dt = 0.02 s" in model and "gravity (0, -9.81, 0) m/s^2" in model,
                 f"{ranks} rank(s): model line '{model.strip()}'")
    checks.check("at t = 2 s:" in energy, f"{ranks} rank(s): energy line '{energy.strip()}'")
    bare = [(line.strip(), m.group(0)) for line in summary.splitlines() for m in BARE_DOT.finditer(line)]
    checks.check(not bare, f"{ranks} rank(s): no number with a bare trailing dot {bare[:3]}")
checks.exit()
