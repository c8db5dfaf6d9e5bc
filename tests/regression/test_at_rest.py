#!/usr/bin/env python3
"""Bodies that nothing can set in motion add no unknowns (partition.hpp, MarkBodiesAtRest).

A free body with no initial velocity, in a scene without gravity, ground,
constraints or -deform of it, whose bounding box meets no other body's and with
no other body moving, is treated like a fixed one: the run has no unknowns for
it, says so in its summary, and its positions stay the rest positions. Each of
the things that could move it keeps its unknowns: a struck body elsewhere in
the scene (it could hit it), gravity, a ground plane, a -deform, a fixed body
whose box meets it (contact would push them apart).
"""
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

BODY = (1000.0, 1e5, 0.3)


def dofs(output):
    match = re.search(r"unknowns\s+(\d+) DOFs", output)
    return int(match.group(1)) if match else -1


def main():
    args = harness.arguments()
    checks = harness.Checks()
    mesh = harness.box_mesh(args, "cube.mesh", (1, 1, 1), (2, 2, 2))  # 27 vertices
    name = os.path.basename(mesh)

    def scene(file, placements, velocities=None):
        bodies = [(name, *BODY, fixed, p, (1, 0, 0, 0)) for fixed, p in placements]
        return harness.write_scene(os.path.join(args.work, file), bodies, velocities)

    def run(scene_path, *options, ranks=2):
        out = os.path.join(args.work, os.path.basename(scene_path).replace(".txt", ".h5"))
        result = harness.run(args, ranks, ["-scene", scene_path, "-steps", 3, "-dt", 0.01, "-output", out,
                                           *options])
        return result.stdout, out

    # One still body: nothing can move it.
    still = scene("still.txt", [(False, (0, 0, 0))])
    for ranks in (1, 2):
        output, out = run(still, ranks=ranks)
        frames = harness.read_frames(out)
        checks.check(dofs(output) == 0 and "1 bodies at rest" in output,
                     f"{ranks} rank(s): a still body adds no unknowns and the summary says so")
        checks.check(np.array_equal(frames["positions"][-1], frames["mesh/rest_positions"])
                     and frames["complete"] == 1 and list(frames["mesh/body_fixed"]) == [0],
                     f"{ranks} rank(s): its positions stay the rest positions; the file lists it as not fixed")

    # Two still bodies apart: both at rest.
    apart = scene("apart.txt", [(False, (0, 0, 0)), (False, (5, 0, 0))])
    output, _ = run(apart)
    checks.check(dofs(output) == 0 and "2 bodies at rest" in output, "two still bodies apart: no unknowns")

    # Whatever could move it keeps its unknowns.
    struck = scene("struck.txt", [(False, (0, 0, 0)), (False, (5, 0, 0))], [(1, 0, (-1.0, 0.0, 0.0))])
    output, _ = run(struck)
    checks.check(dofs(output) == 2 * 27 * 3 and "at rest" not in output,
                 f"a struck body elsewhere: both bodies keep their unknowns ({dofs(output)} DOFs)")
    output, _ = run(still, "-gravity", "0,-9.81,0")
    checks.check(dofs(output) == 81, f"gravity: the body keeps its unknowns ({dofs(output)} DOFs)")
    output, _ = run(still, "-ground", "-1")
    checks.check(dofs(output) == 81, f"a ground plane: the body keeps its unknowns ({dofs(output)} DOFs)")
    output, _ = run(still, "-deform", "0:0.01:1.1,1,1")
    checks.check(dofs(output) == 81, f"-deform of it: the body keeps its unknowns ({dofs(output)} DOFs)")
    touching = scene("touching.txt", [(False, (0, 0, 0)), (True, (0.9, 0, 0))])
    output, _ = run(touching)
    checks.check(dofs(output) == 81, f"a fixed body meeting its box: it keeps its unknowns ({dofs(output)} DOFs)")
    far = scene("far.txt", [(False, (0, 0, 0)), (True, (3, 0, 0))])
    output, _ = run(far)
    checks.check(dofs(output) == 0 and "1 fixed bodies" in output and "1 bodies at rest" in output,
                 "a fixed body far away: the still body adds no unknowns")
    checks.exit()


if __name__ == "__main__":
    main()
