"""Determinism: the same command twice gives byte-identical
datasets (every dataset of the result file, the checkpoints included, compared
byte for byte; of the root attributes all but the measured times).

(a) linear mode, the default direct solver, 2 ranks, with checkpoints;
(b) 1 rank, the same;
(c) corotational mode, CG + GAMG, 2 ranks, a struck bar;
(d) contact: two cubes thrown at each other onto the ground (gravity,
    restitution, friction, impulse spreading), 2 ranks, corotational;
(e) 4 ranks, the wedge's TetGen mesh (tets of unequal volumes), four runs:
    the lumped mass summed a vertex's contributions from other ranks in the
    order their messages arrived (VecAssembly), and 4 of 5 reruns differed
    from the first by up to 1e-20 m/s after 2 steps; now it sums them in the
    order of the senders' ranks (assembly.cpp).
For information (not checked): MUMPS spread over 2 ranks
(-pc_type cholesky -pc_factor_mat_solver_type mumps) adds contributions in
message arrival order and is not bitwise reproducible, which is why the direct
preset factorises the whole matrix on every rank (config/direct.opts).
"""
import os
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()
work = os.path.abspath(args.work)
beam = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scenes", "beam-scene.txt")
TIMINGS = {"setup_seconds", "loop_seconds", "output_seconds", "contact_seconds"}

harness.box_mesh(args, "bar.mesh", (1.0, 0.25, 0.25), (8, 2, 2))
bar = harness.write_scene(os.path.join(work, "bar.txt"),
                          [("bar.mesh", 1000.0, 1e5, 0.3, 0, (0, 0, 0), (1, 0, 0, 0))],
                          [(0, 9 * j + 27 * k, (0, 0, 2.0)) for j in range(3) for k in range(3)])
harness.box_mesh(args, "cube.mesh", (0.5, 0.5, 0.5), (4, 4, 4))
pair = harness.write_scene(os.path.join(work, "pair.txt"),
                           [("cube.mesh", 1000.0, 1e6, 0.3, 0, (-0.6, 0.3, 0), (1, 0, 0, 0)),
                            ("cube.mesh", 1000.0, 1e6, 0.3, 0, (0.6, 0.4, 0), (1, 0, 0, 0))],
                           [(0, k, (3.0, 0, 0)) for k in range(125)] + [(1, k, (-3.0, 0, 0)) for k in range(125)])


def repeated(name, ranks, options, runs):
    outputs = []
    for run in range(1, runs + 1):
        out = os.path.join(work, f"{name}_{run}.h5")
        if os.path.exists(out):
            os.remove(out)
        harness.run(args, ranks, options + ["-output", out, "-quiet"])
        outputs.append(out)
    return outputs


def attributes(path):
    with h5py.File(path, "r") as f:
        return {k: np.asarray(v).tolist() for k, v in f.attrs.items() if k not in TIMINGS}


def check_identical(label, ranks, options, runs=2):
    first, *others = repeated(label.split()[0].strip("()"), ranks, options, runs)
    for second in others:
        check_same_files(label, first, second)


def check_same_files(label, first, second):
    a, b = harness.read_all_datasets(first), harness.read_all_datasets(second)
    different = sorted(name for name in set(a) | set(b)
                       if name not in a or name not in b or a[name].dtype != b[name].dtype
                       or a[name].shape != b[name].shape or a[name].tobytes() != b[name].tobytes())
    checks.check(not different and len(a) > 0,
                 f"{label}: {len(a)} datasets ({', '.join(sorted(a)[:4])}, ...) byte-identical to the first run"
                 + (f"; differing: {different}" if different else ""))
    checks.check(attributes(first) == attributes(second),
                 f"{label}: root attributes other than the timings identical ({len(attributes(first))})")


check_identical("(a) linear, direct, 2 ranks", 2, ["-scene", beam, "-steps", 40, "-checkpoint_every", 15])
check_identical("(b) linear, direct, 1 rank", 1, ["-scene", beam, "-steps", 40, "-checkpoint_every", 15])
check_identical("(c) corotational, CG + GAMG, 2 ranks", 2,
                ["-scene", bar, "-steps", 40, "-mode", "corotational", "-checkpoint_every", 15])
check_identical("(d) contact, corotational, 2 ranks", 2,
                ["-scene", pair, "-steps", 60, "-mode", "corotational", "-gravity", "0,-9.81,0", "-ground", "0",
                 "-dt", "0.01", "-restitution", "0.3", "-friction", "0.3", "-impulse_spreading"])

wedge = harness.write_scene(os.path.join(work, "wedge.txt"),
                            [(os.path.join(os.path.dirname(beam), "contact", "wedge.off"), 1000.0, 1e6, 0.4, 0,
                              (0, 0, 0), (1, 0, 0, 0))], [(0, 0, (0, 0, 1.0))])
check_identical("(e) 4 ranks, unequal tets", 4, ["-scene", wedge, "-steps", 2, "-tetgen_max_volume", 5e-4],
                runs=4)

first, second = repeated("mumps_parallel", 2, ["-scene", beam, "-steps", 40, "-pc_type", "cholesky",
                                            "-pc_factor_mat_solver_type", "mumps"], 2)
a, b = harness.read_frames(first), harness.read_frames(second)
print(f"(info) MUMPS across 2 ranks, the same run twice: velocities differ by up to "
      f"{np.abs(a['velocities'] - b['velocities']).max():.2e} m/s (0 when the messages happened to arrive "
      f"in the same order)")
checks.exit()
