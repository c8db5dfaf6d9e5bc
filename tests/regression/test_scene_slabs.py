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
- a scene of two bodies (contact between them) holds them in slabs too (contact is set up
  from the shares, fixed bodies' too);
- the block converted to a softbody .h5 mesh (softbody-convert) and placed off the
  origin (turned and moved): every rank reads its slabs of the file, and the result
  file equals the one from the text mesh bit for bit at 1, 3 and 4 ranks (the
  placement's centroid is summed in file order across the ranks);
- placed too far from the origin, the .h5 block fails on every rank with the one-line
  error of the text reader (tetrahedron 1 degenerate once placed), exit code 1;
- a scene of three blocks under gravity, two of them .h5 meshes (one free, one fixed
  beneath it) and one text mesh falling onto the free one: at 1, 2 and 3 ranks every
  rank reads its slabs of both files (the summary says 2 of 3), the result file equals
  the all-text scene's bit for bit, and the free .h5 block rests on the fixed one
  (whose tets contact fetched from the shares, src/contact/fixed_tets.hpp) instead
  of falling through it.
"""
import os
import subprocess
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
READ_IN_SLABS = "mesh read in slabs by every rank"
# The block placed off the origin: position and quaternion (w, x, y, z).
PLACED = ((0.3, -1.7, 2.9), (0.9, 0.2, -0.4, 0.1))
FAR = ((3e17, -1.7, 2.9), (0.9, 0.2, -0.4, 0.1))
WHOLE = "meshes whole on every rank"
MIXED = "2 of 3 meshes read in slabs by every rank, the rest on rank 0, then held in slabs"
STACK_STEPS = 30


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
    checks.check(scene_line(two_out).endswith(SLABS), f"two free bodies (no fixed mesh held): "
                                                      f"{scene_line(two_out)!r}")
    check_mesh_file(args, checks, simulate)
    checks.exit()


def placed_scene(args, name, mesh, placement):
    body = (mesh, 100.0, 5e4, 0.3, False) + placement
    return harness.write_scene(os.path.join(args.work, name), [body], VELOCITIES)


def check_mesh_file(args, checks, simulate):
    convert = os.path.join(os.path.dirname(os.path.abspath(args.softbody)), "softbody-convert")
    subprocess.run([args.mpiexec, "-n", "1", convert, os.path.join(args.work, "block.mesh"),
                    os.path.join(args.work, "block.h5")], check=True, capture_output=True,
                   env=harness.mpi_environment())
    text = placed_scene(args, "placed.txt", "block.mesh", PLACED)
    h5 = placed_scene(args, "placed-h5.txt", "block.h5", PLACED)
    for ranks in (1, 3, 4):
        from_text, _ = simulate(f"placed-text-{ranks}", ranks, ["-scene", text, "-steps", 10])
        from_h5, h5_out = simulate(f"placed-h5-{ranks}", ranks, ["-scene", h5, "-steps", 10])
        checks.check(READ_IN_SLABS in scene_line(h5_out), f".h5, {ranks} ranks: {scene_line(h5_out)!r}")
        differ = datasets_equal(from_text, from_h5)
        checks.check(not differ, f".h5 read in slabs on {ranks} ranks equals the text mesh's run "
                                 f"(differing datasets: {differ})")
    check_mixed_scene(args, checks, simulate)
    far = placed_scene(args, "far-h5.txt", "block.h5", FAR)
    result = harness.run(args, 3, ["-scene", far, "-steps", 1], check=False)
    errors = [l for l in (result.stdout + result.stderr).splitlines() if "error:" in l]
    checks.check(result.returncode == 1 and len(errors) == 1 and "tetrahedron 1 is degenerate once placed" in errors[0],
                 f".h5 placed too far: exit {result.returncode}, error lines {errors}")


def stacked_scene(args, name, free_h5, fixed_h5):
    """Three blocks: free `free_h5` above fixed `fixed_h5` (5 cm apart), and a free
    text block 40 cm above the first."""
    bodies = [(free_h5, 100.0, 5e4, 0.3, False, (0, 0.6, 0), (1, 0, 0, 0)),
              ("block.mesh", 100.0, 5e4, 0.3, False, (0, 2.0, 0), (1, 0, 0, 0)),
              (fixed_h5, 100.0, 5e4, 0.3, True, (0, -0.45, 0), (1, 0, 0, 0))]
    return harness.write_scene(os.path.join(args.work, name), bodies)


def check_mixed_scene(args, checks, simulate):
    text = stacked_scene(args, "stack-text.txt", "block.mesh", "block.mesh")
    h5 = stacked_scene(args, "stack-h5.txt", "block.h5", "block.h5")
    options = ["-steps", STACK_STEPS, "-gravity", "0,-9.81,0"]
    for ranks in (1, 2, 3):
        from_text, _ = simulate(f"stack-text-{ranks}", ranks, ["-scene", text] + options)
        from_h5, h5_out = simulate(f"stack-h5-{ranks}", ranks, ["-scene", h5] + options)
        checks.check(MIXED in scene_line(h5_out), f"mixed scene, {ranks} ranks: {scene_line(h5_out)!r}")
        differ = datasets_equal(from_text, from_h5)
        checks.check(not differ, f"two .h5 meshes in slabs and a text mesh on {ranks} ranks equal the "
                                 f"text scene's run (differing datasets: {differ})")
    frames = harness.read_frames(from_h5)
    body = np.asarray(frames["mesh/vertex_body"])
    lowest = frames["positions"][-1][body == 0, 1].min()
    # Falling freely for the run's 0.6 s it would end 1.77 m lower, below -1.6 m.
    checks.check(-0.1 < lowest < 0.1, f"the free .h5 block rests on the fixed one: lowest y {lowest:.3g} m "
                                      "(fixed block's top at 0.05 m)")


if __name__ == "__main__":
    main()
