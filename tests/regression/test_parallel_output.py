"""Output written by every rank (each its natural slab through MPI-IO) does not
depend on the number of ranks; restart reads slabs on any number of ranks.

Scene: a free bar struck sideways (8 x 2 x 2 cells) beside a fixed cube
(4 x 4 x 4 cells) that it never reaches, so that the natural vertex slabs of 3
ranks cut through both bodies and through vertices without unknowns.
(a) 1 rank vs 3 ranks (oversubscribed), direct solver, with checkpoints: the
    files hold the same datasets with the same shapes, dtypes and chunk shapes,
    the same attribute names (root, /mesh, checkpoint slots), the same mesh
    datasets exactly, and frames and checkpoints equal to 1e-10 relative
    (max |difference| / max |value| of each dataset).
(b) A checkpoint written at 3 ranks, continued at 1 and at 2 ranks (into new
    files): the last frame equals the uninterrupted 1-rank run's to 1e-10 of
    the largest displacement, and the frames copied from the 3-rank file equal
    its own exactly.
(c) Chunks stay bounded: a free box of 58 621 vertices falling under gravity,
    2 ranks (CG + Jacobi, one step), with a checkpoint: the chunks of
    /positions, /velocities and the checkpoint's positions hold at most 1 MiB
    and fewer rows than the mesh; frame 0 equals /mesh/rest_positions exactly;
    the fall is a translation (the same displacement at every vertex, to 1e-9
    of it), which it is only if every rank's rows landed at their offsets.
(d) Errors at 3 ranks end with one line naming the option, a non-zero exit and
    no hang: a restart file of another scene (another body count, other
    vertex counts, other rest positions), a missing restart file, output into
    a missing folder.
(e) A 2-rank run (MPI-IO) whose rank 1 is killed by SIGKILL: the file opens
    with complete = 0, the .xdmf lists its frames (all, or all but the last
    flush's), and their times and positions equal the file's.
"""
import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

VALUE_TOLERANCE = 1e-10  # direct solver: rank counts differ by round-off only
MAX_CHUNK_BYTES = 1 << 20  # src/io/parallel_hdf5.hpp, kMaxChunkBytes
MESH_DATASETS = ("mesh/tets", "mesh/boundary_triangles", "mesh/vertex_body", "mesh/rest_positions",
                 "mesh/body_fixed", "mesh/body_material")

args = harness.arguments()
checks = harness.Checks()
work = os.path.abspath(args.work)

harness.box_mesh(args, "bar.mesh", (1.0, 0.25, 0.25), (8, 2, 2))
harness.box_mesh(args, "cube.mesh", (0.5, 0.5, 0.5), (4, 4, 4))
# The bar (9 x 3 x 3 grid) struck sideways at its x = 0 end; the fixed cube 2 m away.
scene = harness.write_scene(os.path.join(work, "scene.txt"),
                            [("bar.mesh", 1000.0, 1e5, 0.3, 0, (0, 0, 0), (1, 0, 0, 0)),
                             ("cube.mesh", 1000.0, 1e6, 0.3, 1, (0, 0, 2.0), (1, 0, 0, 0))],
                            [(0, 9 * j + 27 * k, (0, 0, 2.0)) for j in range(3) for k in range(3)])


def datasets(path):
    """{name: (shape, dtype, chunks)} and {group or file: sorted attribute names}."""
    found, attributes = {}, {}
    with h5py.File(path, "r") as f:
        attributes["/"] = sorted(f.attrs)

        def visit(name, item):
            if isinstance(item, h5py.Dataset):
                found[name] = (item.shape, item.dtype.str, item.chunks)
            else:
                attributes[name] = sorted(item.attrs)
        f.visititems(visit)
    return found, attributes


def relative(a, b):
    if a.size == 0 and b.size == 0:  # e.g. a checkpoint's resting contacts when nothing rests
        return 0.0
    scale = np.abs(b).max()
    return float(np.abs(a - b).max() / scale) if scale > 0 else float(np.abs(a - b).max())


print("(a) 1 rank vs 3 ranks")
one, three = harness.fresh_result(work, "one"), harness.fresh_result(work, "three")
for ranks, out in ((1, one), (3, three)):
    harness.run(args, ranks, ["-scene", scene, "-steps", 30, "-checkpoint_every", 10, "-output", out, "-quiet"])
layout_one, attributes_one = datasets(one)
layout_three, attributes_three = datasets(three)
checks.check(layout_one == layout_three,
             f"(a) same {len(layout_one)} datasets, shapes, dtypes and chunks at 1 and 3 ranks"
             + ("" if layout_one == layout_three else f": {layout_one} vs {layout_three}"))
checks.check(attributes_one == attributes_three,
             f"(a) same attribute names in {len(attributes_one)} groups"
             + ("" if attributes_one == attributes_three else f": {attributes_one} vs {attributes_three}"))
a, b = harness.read_all_datasets(one), harness.read_all_datasets(three)
checks.check(all(np.array_equal(a[k], b[k]) for k in MESH_DATASETS),
             f"(a) the mesh datasets are equal ({len(a['mesh/rest_positions'])} vertices, "
             f"{len(a['mesh/tets'])} tets, {len(a['mesh/boundary_triangles'])} boundary triangles)")
varying = sorted(k for k in a if k not in MESH_DATASETS and k in b and a[k].dtype.kind == "f")
worst = max(varying, key=lambda k: relative(b[k], a[k]))
checks.check(all(a[k].shape == b[k].shape for k in varying) and relative(b[worst], a[worst]) <= VALUE_TOLERANCE,
             f"(a) {len(varying)} frame and checkpoint datasets equal to {VALUE_TOLERANCE:g} relative "
             f"(largest: {worst}, {relative(b[worst], a[worst]):.2e})")
fixed = a["mesh/vertex_body"] == 1
checks.check(bool(np.all(b["positions"][:, fixed] == b["mesh/rest_positions"][fixed])) and
             bool(np.all(b["velocities"][:, fixed] == 0)) and
             np.abs(b["positions"][-1, ~fixed] - b["mesh/rest_positions"][~fixed]).max() > 1e-2,
             "(a) 3 ranks: the fixed cube's vertices stay at rest (every frame), the bar moves")
with h5py.File(one, "r") as f, h5py.File(three, "r") as g:
    same = all(f.attrs[k] == g.attrs[k] for k in ("complete", "interrupted", "steps")) and \
        int(g["checkpoint/0"].attrs["ranks"]) == 3
    checks.check(same, "(a) equal complete/interrupted/steps attributes; the 3-rank checkpoint says ranks = 3")

print("(b) checkpoint at 3 ranks, continued at 1 and 2")
part = harness.fresh_result(work, "part3")
harness.run(args, 3, ["-scene", scene, "-steps", 15, "-checkpoint_every", 15, "-output", part, "-quiet"])
reference = harness.read_frames(one)
written = harness.read_frames(part)
for ranks in (1, 2):
    out = harness.fresh_result(work, f"continued{ranks}")
    harness.run(args, ranks, ["-scene", scene, "-steps", 30, "-restart", part, "-output", out, "-quiet"])
    r = harness.read_frames(out)
    scale = np.abs(reference["positions"][-1] - reference["mesh/rest_positions"]).max()
    difference = np.abs(r["positions"][-1] - reference["positions"][-1]).max() / scale
    copied = len(written["time"])
    checks.check(np.array_equal(r["time"], reference["time"]) and difference <= VALUE_TOLERANCE and
                 r["complete"] == 1,
                 f"(b) 3 -> {ranks} rank{'s' if ranks > 1 else ''}: {len(r['time'])} frames, last positions "
                 f"differ by {difference:.2e} of the largest displacement (<= {VALUE_TOLERANCE:g})")
    checks.check(all(np.array_equal(r[k][:copied], written[k]) for k in ("positions", "velocities", "time")),
                 f"(b) 3 -> {ranks}: the {copied} frames copied from the 3-rank file are equal to it")

print("(c) bounded chunks on a bigger mesh")
harness.box_mesh(args, "box.mesh", (2.0, 1.0, 1.0), (60, 30, 30))
box = harness.write_scene(os.path.join(work, "box.txt"),
                          [("box.mesh", 1000.0, 1e6, 0.3, 0, (0, 0, 0), (1, 0, 0, 0))])
out = harness.fresh_result(work, "box")
harness.run(args, 2, ["-scene", box, "-steps", 1, "-gravity", "0,-9.81,0", "-checkpoint_every", 1,
                      "-ksp_type", "cg", "-pc_type", "jacobi", "-ksp_rtol", 1e-12, "-output", out, "-quiet"])
with h5py.File(out, "r") as f:
    vertices = f["mesh/rest_positions"].shape[0]
    for name in ("positions", "velocities", "checkpoint/0/positions"):
        chunks = f[name].chunks
        rows = chunks[-2]
        nbytes = int(np.prod(chunks)) * 8
        checks.check(nbytes <= MAX_CHUNK_BYTES and rows < vertices,
                     f"(c) /{name}: chunks {chunks} of {nbytes} bytes (<= {MAX_CHUNK_BYTES}), "
                     f"{rows} of {vertices} rows")
    rest = f["mesh/rest_positions"][()]
    x = f["positions"][()]
    displacement = x[-1] - rest
    mean = displacement.mean(axis=0)
    spread = np.abs(displacement - mean).max() / np.abs(mean).max()
    checks.check(np.array_equal(x[0], rest) and np.abs(mean[1]) > 0 and spread <= 1e-9,
                 f"(c) frame 0 = rest positions; the fall moves all {vertices} vertices by {mean[1]:.3e} m "
                 f"in y (spread {spread:.1e} <= 1e-9)")

print("(d) errors at 3 ranks")
other = harness.write_scene(os.path.join(work, "other.txt"),
                            [("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, 0, 0), (1, 0, 0, 0))])
moved = harness.write_scene(os.path.join(work, "moved.txt"),
                            [("bar.mesh", 1000.0, 1e5, 0.3, 0, (0, 0, 0), (1, 0, 0, 0)),
                             ("cube.mesh", 1000.0, 1e6, 0.3, 1, (0, 0, 2.5), (1, 0, 0, 0))])
harness.box_mesh(args, "longer.mesh", (1.0, 0.25, 0.25), (9, 2, 2))
longer = harness.write_scene(os.path.join(work, "longer.txt"),
                             [("longer.mesh", 1000.0, 1e5, 0.3, 0, (0, 0, 0), (1, 0, 0, 0)),
                              ("cube.mesh", 1000.0, 1e6, 0.3, 1, (0, 0, 2.0), (1, 0, 0, 0))])
fresh = os.path.join(work, "must_not_exist.h5")
cases = [
    ("a restart file of another scene", ["-scene", other, "-steps", 30, "-restart", part, "-output", fresh],
     ["option -restart", "does not match the scene", "2 bodies, the scene 1"]),
    ("other vertex counts", ["-scene", longer, "-steps", 30, "-restart", part, "-output", fresh],
     ["option -restart", "does not match the scene", "body 0 has 81 vertices there, 90 in the scene"]),
    ("other rest positions", ["-scene", moved, "-steps", 30, "-restart", part, "-output", fresh],
     ["option -restart", "does not match the scene", "rest positions differ"]),
    ("a missing restart file", ["-scene", scene, "-steps", 30, "-restart", os.path.join(work, "none.h5"),
                                "-output", fresh], ["option -restart", "cannot open"]),
    ("output into a missing folder", ["-scene", scene, "-steps", 3, "-output",
                                      os.path.join(work, "no_folder", "x.h5")], ["option -output", "does not exist"]),
]
for label, options, keys in cases:
    r = harness.run(args, 3, options, check=False, timeout=120)
    errors = [line for line in r.stderr.splitlines() if line.startswith("softbody: error:")]
    ok = (r.returncode != 0 and len(errors) == 1 and all(k in errors[0] for k in keys)
          and "PETSC ERROR" not in r.stderr and not os.path.exists(fresh))
    checks.check(ok, f"(d) {label}: exit {r.returncode}, '{errors[0] if errors else r.stderr.strip()[:300]}'")

print("(e) SIGKILL of one rank of two")
out = harness.fresh_result(work, "killed")
process = subprocess.Popen([args.mpiexec, "-n", "2", args.softbody, "-scene", scene, "-steps", "1000000",
                            "-output", out, "-quiet"], env=harness.mpi_environment(),
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
xdmf, deadline = out[:-3] + ".xdmf", time.time() + 120
while time.time() < deadline and process.poll() is None and \
        not (os.path.exists(xdmf) and open(xdmf).read().count("<Time ") >= 6):
    time.sleep(0.02)
ranks = subprocess.run(["pgrep", "-P", str(process.pid)], capture_output=True, text=True).stdout.split()
if ranks:
    os.kill(int(ranks[-1]), signal.SIGKILL)
try:
    process.wait(timeout=60)
except subprocess.TimeoutExpired:
    process.kill()
    process.wait()
r = harness.read_frames(out)
times, positions, _ = harness.xdmf_frames(xdmf)
n = len(times)
checks.check(len(ranks) == 2 and r["complete"] == 0 and n >= 6 and len(r["time"]) - 1 <= n <= len(r["time"]) and
             np.array_equal(times, r["time"][:n]) and np.array_equal(positions, r["positions"][:n]),
             f"(e) rank {ranks[-1] if ranks else '?'} of {ranks} killed: the file opens with {len(r['time'])} frames, "
             f"complete = {r['complete']}, the .xdmf lists {n} of them, equal to the file's")
checks.exit()
