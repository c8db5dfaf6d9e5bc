#!/usr/bin/env python3
"""Meshes held in slabs give the same run as meshes held whole on every rank.

When contact cannot need the bodies' whole meshes (one body, no ground, no
constraints), rank 0 reads the scene and sends every rank only its slabs of the
vertices and tets; -scene_replicate holds every mesh whole on every rank instead.
Scene (written into the work dir): one 3 x 1 x 1 m block (tools/box_mesh.py,
12 x 4 x 4 cells), struck on three vertices.
- 2 and 3 ranks, linear and corotational mode, 20 steps: every dataset of the result
  file (mesh, boundary triangles, frames, energies) is equal bit for bit with and
  without -scene_replicate; the run summary says which way the meshes were held;
- restart in slabs: 3 ranks, 10 steps with a checkpoint, continued to 20 steps on 3
  ranks, equals the uninterrupted 3-rank run bit for bit;
- a scene of two bodies (contact between them may need the meshes) holds them whole.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

STEPS = 20
BLOCK = ((3.0, 1.0, 1.0), (12, 4, 4))
ONE_BODY = [("block.mesh", 100.0, 5e4, 0.3, False, (0, 0, 0), (1, 0, 0, 0))]
TWO_BODIES = ONE_BODY + [("block.mesh", 100.0, 5e4, 0.3, False, (0, 3, 0), (1, 0, 0, 0))]
# Block vertex (i, j, k), 0 <= i <= 12, 0 <= j, k <= 4, has index i + 13 (j + 5 k).
VELOCITIES = [(0, 0, (0, 10, 0)), (0, 168, (0, 0, 10)), (0, 58, (-5, 0, 10))]
SLABS = "meshes read on rank 0, then held in slabs"
WHOLE = "meshes whole on every rank"


def scene_line(stdout):
    return next((l.strip() for l in stdout.splitlines() if l.strip().startswith("scene")), "")


def datasets_equal(a_path, b_path):
    """Names of the datasets that differ between two result files (shape or value)."""
    a, b = harness.read_all_datasets(a_path), harness.read_all_datasets(b_path)
    differ = [name for name in a if name not in b or np.asarray(a[name]).shape != np.asarray(b[name]).shape
              or not np.array_equal(a[name], b[name])]
    return differ + [name for name in b if name not in a]


def main():
    args = harness.arguments()
    checks = harness.Checks()
    harness.box_mesh(args, "block.mesh", *BLOCK)
    one = harness.write_scene(os.path.join(args.work, "one.txt"), ONE_BODY, VELOCITIES)
    two = harness.write_scene(os.path.join(args.work, "two.txt"), TWO_BODIES, VELOCITIES)

    def simulate(label, ranks, options):
        out = harness.fresh_result(args.work, label)
        stdout = harness.run(args, ranks, ["-output", out] + options).stdout
        return out, stdout

    for mode in ("linear", "corotational"):
        for ranks in (2, 3):
            common = ["-scene", one, "-steps", STEPS, "-mode", mode]
            slabs, slabs_out = simulate(f"slabs-{mode}-{ranks}", ranks, common)
            whole, whole_out = simulate(f"whole-{mode}-{ranks}", ranks, common + ["-scene_replicate"])
            checks.check(SLABS in scene_line(slabs_out), f"{mode}, {ranks} ranks: {scene_line(slabs_out)!r}")
            checks.check(WHOLE in scene_line(whole_out),
                         f"{mode}, {ranks} ranks, -scene_replicate: {scene_line(whole_out)!r}")
            differ = datasets_equal(slabs, whole)
            checks.check(not differ, f"{mode}, {ranks} ranks: slabs and whole meshes give equal files "
                                     f"(differing datasets: {differ})")
    moved = np.abs(harness.read_frames(slabs)["positions"][-1] - harness.read_frames(slabs)["positions"][0]).max()
    checks.check(moved > 1e-2, f"the block moves ({moved:.3g} m)")

    full, _ = simulate("restart-full", 3, ["-scene", one, "-steps", STEPS])
    part, _ = simulate("restart-part", 3, ["-scene", one, "-steps", STEPS // 2,
                                           "-checkpoint_every", STEPS // 2])
    cont, cont_out = simulate("restart-cont", 3, ["-scene", one, "-steps", STEPS, "-restart", part])
    differ = datasets_equal(full, cont)
    checks.check(SLABS in scene_line(cont_out) and not differ,
                 f"restart in slabs on 3 ranks equals the uninterrupted run (differing datasets: {differ})")

    _, two_out = simulate("two-bodies", 2, ["-scene", two, "-steps", 2])
    checks.check(WHOLE in scene_line(two_out), f"two bodies: {scene_line(two_out)!r}")
    checks.exit()


if __name__ == "__main__":
    main()
