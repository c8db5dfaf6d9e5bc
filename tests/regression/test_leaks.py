#!/usr/bin/env python3
"""Leak check of softbody's MPI runs in the sanitizer build (./run test --sanitize).

The sanitizer build's softbody skips LeakSanitizer's check at exit unless
SOFTBODY_LSAN=1 (tests/sanitize/lsan_ranks.cpp says why). Here a few runs that
together reach every module (linear and corotational, direct and CG + GAMG,
gravity, ground contact, distance constraints, OFF meshing with TetGen, HDF5
output, an input error, a bad option) run with it set, with the full unwinder
(fast_unwind_on_malloc=0) so that tests/sanitize/lsan.supp can name Open MPI's
own leaks, at 1 and 2 ranks. A run must exit as expected with no sanitizer report.
Skipped (77) for a build without AddressSanitizer.
"""
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))

args = harness.arguments()
libraries = subprocess.run(["ldd", args.softbody], capture_output=True, text=True).stdout
if "libasan" not in libraries and "libclang_rt.asan" not in libraries:
    print("SKIP: softbody is not built with AddressSanitizer (-DSOFTBODY_SANITIZE=ON)")
    sys.exit(harness.SKIP)

env_options = os.environ.get("ASAN_OPTIONS", "")
os.environ["ASAN_OPTIONS"] = (env_options + ":" if env_options else "") + \
    "detect_leaks=1:fast_unwind_on_malloc=0"
suppressions = os.path.join(HERE, "..", "sanitize", "lsan.supp")
os.environ["LSAN_OPTIONS"] = f"suppressions={suppressions}:print_suppressions=0"
os.environ["SOFTBODY_LSAN"] = "1"

mixed = os.path.join(HERE, "..", "data", "meshes", "mixed-scene.txt")
valid = os.path.join(HERE, "..", "data", "bad_input", "valid.txt")
bad = os.path.join(HERE, "..", "data", "bad_input", "mesh_degenerate.txt")
practical3 = os.path.join(ROOT, "config", "practical3.opts")
cg_gamg = os.path.join(ROOT, "config", "cg-gamg.opts")
out = os.path.join(args.work, "out.h5")

# (name, ranks, options, expected exit code 0 / non-zero)
cases = [
    ("linear, direct, HDF5 output", 1, ["-scene", mixed, "-steps", "3", "-output", out], True),
    ("corotational, CG + GAMG", 2, ["-scene", mixed, "-steps", "3", "-mode", "corotational",
                                    "-options_file", cg_gamg], True),
    ("gravity, ground, friction", 2, ["-scene", valid, "-steps", "20", "-options_file", practical3,
                                      "-friction", "0.5", "-output", out], True),
    ("input error", 2, ["-scene", bad], False),
    ("bad option", 1, ["-scene", valid, "-mode", "bogus"], False),
]
# Distance constraints: tests/data/constraints/hang.txt (two cubes hanging from a
# fixed one, as in test_constraints.py (b)), on cubes of tools/box_mesh.py.
harness.box_mesh(args, "cube.mesh", (0.5, 0.5, 0.5), (4, 4, 4))
hang = harness.write_scene(os.path.join(args.work, "hang.txt"),
                           [("cube.mesh", 1000.0, 1e6, 0.3, 1, (0, 0, 0), (1, 0, 0, 0)),
                            ("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, -0.75, 0), (1, 0, 0, 0)),
                            ("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, -1.5, 0), (1, 0, 0, 0))])
cases.append(("distance constraints", 2,
              ["-scene", hang, "-constraints", os.path.join(HERE, "..", "data", "constraints", "hang.txt"),
               "-gravity", "0,-9.81,0", "-steps", "5"], True))

failed = 0
for name, ranks, options, succeeds in cases:
    result = harness.run(args, ranks, options, timeout=300, check=False)
    report = [line for line in result.stderr.splitlines()
              if "Sanitizer" in line or "runtime error" in line]
    ok = (result.returncode == 0) == succeeds and not report
    failed += not ok
    print(f"{'PASS' if ok else 'FAIL'} {name} ({ranks} rank{'s' if ranks > 1 else ''}): "
          f"exit {result.returncode}{'; ' + report[0] if report else ''}")
    if not ok:
        print(result.stderr[-6000:])
sys.exit(1 if failed else 0)
