#!/usr/bin/env python3
"""-vertex_order: renumbering for cache locality changes the run by round-off only.

Mesh: tests/data/meshes/torus.off meshed by TetGen (softbody-convert, volume bound
0.002: about 2 000 vertices and 7 600 tets in TetGen's own order, unstructured),
struck on two vertices; 10 steps of 0.02 s.
(a) Linear mode (direct solver) and corotational mode (CG + warp), 1 and 2 ranks:
    with the default -vertex_order (hilbert) the positions equal those of
    -vertex_order natural (the files' order, the numbering of earlier versions) to
    a relative 1e-10 (max |dx| over max |x|, every frame), the velocities to a
    relative 1e-8 (max |dv| over max |v|: CG stops at a tolerance, which round-off
    moves), and the energies to a relative 1e-8. The summary names the order.
(b) The output is in the file's vertex order whatever the numbering: with the
    Hilbert order on 2 ranks, the result's mesh/tets are the .h5 mesh's tets, and
    its mesh/rest_positions the mesh's vertices (to a relative 1e-15: the scene's
    placement rounds them even for the identity) and, like frame 0, bit for bit
    those of the natural order's run.
(c) Checkpoints are in the file's order too: a Hilbert-ordered 2-rank run
    checkpointed at step 5 and continued on 1 rank in the natural order equals the
    uninterrupted natural 1-rank run at step 10 to the tolerances of (a).
(d) -vertex_order morton, another curve, agrees with natural likewise
    (corotational, 1 rank).
"""
import os
import subprocess
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

# Round-off: the renumbered sums differ in their last bits, and a direct solve or
# a few CG iterations amplify that by at most the condition number's share.
POSITION_TOLERANCE = 1e-10  # relative to the largest |x|
VELOCITY_TOLERANCE = 1e-8   # relative to the largest |v| (CG's stopping test moves with round-off)
ENERGY_TOLERANCE = 1e-8     # relative to the largest energy
# The scene's placement (rotation about the centroid, then the shift) rounds the
# file's coordinates in their last bit even for the identity.
PLACEMENT_ROUND_OFF = 1e-15
STEPS = 10
CHECKPOINT_STEP = 5
TETGEN_VOLUME = 0.002  # m^3: ~7 600 tets of the torus (centre radius 1 m, tube 0.4 m)

args = harness.arguments()
checks = harness.Checks()
work = os.path.abspath(args.work)
convert = os.path.join(os.path.dirname(os.path.abspath(args.softbody)), "softbody-convert")
torus_off = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "meshes", "torus.off")

mesh = os.path.join(work, "torus.h5")
if os.path.exists(mesh):
    os.remove(mesh)
subprocess.run([args.mpiexec, "-n", "1", convert, torus_off, mesh, "-tetgen_max_volume", str(TETGEN_VOLUME)],
               check=True, capture_output=True, env=harness.mpi_environment())
with h5py.File(mesh, "r") as f:
    file_vertices, file_tets = f["vertices"][()], f["tets"][()]
scene = harness.write_scene(os.path.join(work, "torus.txt"),
                            [("torus.h5", 1000.0, 1e5, 0.3, 0, (0, 0, 0), (1, 0, 0, 0))],
                            [(0, 0, (0, 0, 2.0)), (0, 100, (1.0, 0, 0))])


def run(name, ranks, mode, order, *extra):
    out = harness.fresh_result(work, name)
    result = harness.run(args, ranks, ["-scene", scene, "-mode", mode, "-steps", STEPS, "-vertex_order", order,
                                       "-output", out, *extra])
    return out, result.stdout


def relative(ours, reference):
    return float(np.abs(ours - reference).max() / max(np.abs(reference).max(), 1e-300))


def compare(label, ours, reference, frame=None):
    a, b = harness.read_frames(ours), harness.read_frames(reference)
    pick = (lambda x: x) if frame is None else (lambda x: x[frame])
    dx = relative(pick(a["positions"]), pick(b["positions"]))
    dv = relative(pick(a["velocities"]), pick(b["velocities"]))
    de = max(relative(pick(a[f"energy/{e}"]), pick(b[f"energy/{e}"])) for e in ("kinetic", "elastic"))
    checks.check(dx <= POSITION_TOLERANCE and dv <= VELOCITY_TOLERANCE and de <= ENERGY_TOLERANCE,
                 f"{label}: positions agree to {dx:.1e} (<= {POSITION_TOLERANCE:g}), velocities to {dv:.1e} "
                 f"(<= {VELOCITY_TOLERANCE:g}), energies to {de:.1e} (<= {ENERGY_TOLERANCE:g}), relative")


# (a) and (b)
for mode in ("linear", "corotational"):
    for ranks in (1, 2):
        natural, natural_log = run(f"{mode}_natural_{ranks}", ranks, mode, "natural")
        hilbert, hilbert_log = run(f"{mode}_hilbert_{ranks}", ranks, mode, "hilbert")
        compare(f"(a) {mode}, {ranks} rank(s), hilbert against natural", hilbert, natural)
        checks.check("; natural vertex order)" in natural_log and "; hilbert vertex order)" in hilbert_log,
                     f"(a) {mode}, {ranks} rank(s): the summary's unknowns line names the vertex order")
        if ranks == 2:
            ours, files = harness.read_frames(hilbert), harness.read_frames(natural)
            placed = relative(ours["mesh/rest_positions"], file_vertices)
            checks.check(placed <= PLACEMENT_ROUND_OFF and np.array_equal(ours["mesh/tets"], file_tets)
                         and np.array_equal(ours["mesh/rest_positions"], files["mesh/rest_positions"])
                         and np.array_equal(ours["positions"][0], files["positions"][0]),
                         f"(b) {mode}, hilbert, 2 ranks: mesh/tets are the mesh file's {len(file_tets)} tets; "
                         f"mesh/rest_positions its {len(file_vertices)} vertices in its order (relative "
                         f"{placed:.1e}, the placement's round-off) and, like frame 0, bit for bit the natural "
                         f"order's")
        if mode == "corotational" and ranks == 1:
            morton, _ = run(f"{mode}_morton_{ranks}", ranks, mode, "morton")
            compare(f"(d) {mode}, 1 rank, morton against natural", morton, natural)
            uninterrupted = natural

# (c) a Hilbert 2-rank checkpoint continued on 1 rank in the natural order
first, _ = run("checkpointed", 2, "corotational", "hilbert", "-checkpoint_every", CHECKPOINT_STEP,
               "-steps", CHECKPOINT_STEP)
continued = os.path.join(work, "continued.h5")
if os.path.exists(continued):
    os.remove(continued)
harness.run(args, 1, ["-scene", scene, "-mode", "corotational", "-steps", STEPS, "-vertex_order", "natural",
                      "-restart", first, "-output", continued])
with h5py.File(first, "r") as f:
    checkpoint = max((f[f"checkpoint/{slot}"] for slot in ("0", "1") if f"checkpoint/{slot}" in f),
                     key=lambda g: int(g.attrs["step"]))
    checkpoint_positions = checkpoint["positions"][()]
reference = harness.read_frames(uninterrupted)
dx = relative(checkpoint_positions, reference["positions"][CHECKPOINT_STEP])
checks.check(dx <= POSITION_TOLERANCE,
             f"(c) the Hilbert 2-rank checkpoint at step {CHECKPOINT_STEP} holds the natural 1-rank run's "
             f"positions in file order (relative {dx:.1e})")
compare(f"(c) continued on 1 rank (natural) from the Hilbert 2-rank checkpoint, step {STEPS}", continued,
        uninterrupted, frame=-1)
checks.exit()
