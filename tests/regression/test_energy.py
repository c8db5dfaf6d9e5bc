#!/usr/bin/env python3
"""Energy behaviour and bookkeeping of the implicit Euler integrator.

Scene (written into the work dir with meshes of tools/box_mesh.py): two free
2 x 1 x 1 m blocks (6 x 3 x 3 cells, 112 vertices each) of different density
and stiffness, turned by 90 degrees about y, struck on three vertices each, and
a fixed 1 m cube between them in the file (so the free vertices are not
contiguous) and in space (2 m from each, out of their way).

(a) -alpha 0 -beta 0, 100 steps: the total energy (kinetic + elastic) never
    increases between frames (round-off allowance 1e-12 of the initial energy)
    and has decreased in total (backward Euler is dissipative).
(b) default damping: strictly decreasing, ending below the undamped run.
(c) bookkeeping, recomputed in python: lumped masses rho V / 4 from /mesh/tets,
    /mesh/rest_positions and the scene's densities (also against the exported
    M); kinetic energy 0.5 sum m |v|^2 and elastic energy 0.5 u^T K u (K from
    -export_matrices of the same run, u over the free vertices) on every frame;
    elastic energy 0 at frame 0.
(d) one free tetrahedron (the unit corner tet, written here) with a uniform
    velocity, no damping, 1 rank: rigid translation x(t) = X + v t, v constant,
    energies constant (1e-12).
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

STEPS = 100
ROUNDOFF = 1e-12
BOOKKEEPING = 1e-10
RIGID = 1e-12

# Meshes: name -> (size in m, cells); block vertex (i, j, k) has index i + 7 (j + 4 k).
MESHES = {"block.mesh": ((2.0, 1.0, 1.0), (6, 3, 3)), "cube.mesh": ((1.0, 1.0, 1.0), (3, 3, 3))}
# (mesh, density, young, poisson, fixed, position, quaternion)
BODIES = [
    ("block.mesh", 100.0, 50000.0, 0.3, False, (0, 2, 0), (1, 0, 1, 0)),
    ("cube.mesh", 300.0, 2000.0, 0.1, True, (0, 0, 0), (1, 0, 0, 0)),
    ("block.mesh", 250.0, 5000.0, 0.45, False, (0, -2, 0), (1, 0, 1, 0)),
]
# A corner (0, 0, 0), a vertex inside an end face (6, 2, 2), the middle of a long edge (3, 3, 0),
# struck away from the fixed cube and across (m/s).
VELOCITIES = [(0, 0, (0, 1, 0)), (2, 0, (0, -1, 0)), (0, 76, (0, 0, 1)),
              (2, 76, (0, 0, 1)), (0, 24, (-0.5, 0, 1)), (2, 24, (-0.5, 0, 1))]
TETRAHEDRON = "MeshVersionFormatted 1\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n" \
              "Tetrahedra\n1\n1 2 3 4 0\nEnd\n"


def matvec(matrix, x):
    rows, cols, values, shape = matrix
    return np.bincount(rows, weights=values * x[cols], minlength=shape[0])


def main():
    args = harness.arguments()
    checks = harness.Checks()
    for name, (size, cells) in MESHES.items():
        harness.box_mesh(args, name, size, cells)
    scene = harness.write_scene(os.path.join(args.work, "scene.txt"), BODIES, VELOCITIES)

    def simulate(label, ranks, scene_path, extra, steps=STEPS):
        out = os.path.join(args.work, f"{label}.h5")
        harness.run(args, ranks, ["-scene", scene_path, "-steps", steps, "-output", out] + list(extra))
        return harness.read_frames(out)

    # (a) No damping: backward Euler alone dissipates, never creates energy.
    matrices = os.path.join(args.work, "matrices")
    undamped = simulate("undamped", 2, scene, ["-alpha", 0, "-beta", 0, "-export_matrices", matrices])
    total = undamped["energy/kinetic"] + undamped["energy/elastic"]
    e0 = total[0]
    checks.check(len(total) == STEPS + 1 and e0 > 0,
                 f"(a) {len(total)} frames, initial energy {e0:.6g} J")
    rise = float(np.max(np.diff(total)))
    checks.check(rise <= ROUNDOFF * e0,
                 f"(a) undamped: largest change between frames {rise:.3e} J "
                 f"= {rise / e0:.3e} of E0 (allowed {ROUNDOFF:g})")
    checks.check(total[-1] < e0 * (1 - 1e-6),
                 f"(a) undamped: final/initial energy {total[-1] / e0:.6f} < 1 "
                 f"(E0 {e0:.6g} J, E_end {total[-1]:.6g} J, "
                 f"max elastic {undamped['energy/elastic'].max():.6g} J)")

    # (b) Rayleigh damping (defaults a = b = 0.1): strictly decreasing, below (a).
    damped = simulate("damped", 2, scene, [])
    total_d = damped["energy/kinetic"] + damped["energy/elastic"]
    steps_d = np.diff(total_d)
    checks.check(abs(total_d[0] - e0) <= ROUNDOFF * e0,
                 f"(b) damped: same initial energy {total_d[0]:.6g} J")
    checks.check(len(steps_d) == STEPS and bool(np.all(steps_d < 0)),
                 f"(b) damped: strictly decreasing ({int(np.sum(steps_d < 0))}/{len(steps_d)} steps; "
                 f"smallest decrease {-steps_d.max():.3e} J)")
    checks.check(total_d[-1] < total[-1],
                 f"(b) damped final energy {total_d[-1]:.6g} J < undamped {total[-1]:.6g} J "
                 f"(ratio {total_d[-1] / total[-1]:.4f})")

    # (c) Bookkeeping recomputed from the file and the exported K.
    tets = undamped["mesh/tets"].astype(np.int64)
    rest = undamped["mesh/rest_positions"]
    vertex_body = undamped["mesh/vertex_body"].astype(np.int64)
    masses = harness.lumped_masses(tets, rest, vertex_body, [b[1] for b in BODIES])
    fixed = np.array([b[4] for b in BODIES])[vertex_body]
    free = ~fixed
    m_export = harness.read_petsc_aij(os.path.join(matrices, "M.bin"))
    k_export = harness.read_petsc_aij(os.path.join(matrices, "K.bin"))
    n_free = 3 * int(free.sum())
    checks.check(m_export[3] == (n_free, n_free) and k_export[3] == (n_free, n_free),
                 f"(c) exported M, K are {k_export[3]} = 3 x {int(free.sum())} free vertices "
                 f"({int(fixed.sum())} fixed)")
    m_diag = np.bincount(m_export[0], weights=np.where(m_export[0] == m_export[1], m_export[2], 0.0),
                         minlength=n_free)
    m_off = np.abs(m_export[2][m_export[0] != m_export[1]]).max(initial=0.0)
    m_python = np.repeat(masses[free], 3)
    mass_error = np.abs(m_diag - m_python).max() / m_python.max() if m_diag.shape == m_python.shape else np.inf
    checks.check(mass_error <= 1e-12 and m_off == 0.0,
                 f"(c) exported M = python lumped masses rho V/4: relative difference {mass_error:.3e}, "
                 f"off-diagonal max {m_off:g} (total free mass {masses[free].sum():.6g} kg)")

    v0 = undamped["velocities"][0]
    listed = np.zeros(len(rest), dtype=bool)
    for body, vertex, _ in VELOCITIES:
        listed[np.flatnonzero(vertex_body == body)[vertex]] = True
    checks.check(bool(np.all(np.abs(v0[~listed]) == 0) and np.all(np.abs(v0[listed]).max(axis=1) > 0)),
                 f"(c) frame 0: velocity non-zero exactly on the {int(listed.sum())} listed vertices")
    checks.check(np.array_equal(undamped["positions"][0], rest),
                 "(c) frame 0: positions equal /mesh/rest_positions")
    kinetic_python = 0.5 * np.einsum("v,fvi,fvi->f", masses, undamped["velocities"], undamped["velocities"])
    error_k = np.abs(kinetic_python - undamped["energy/kinetic"]).max() / e0
    checks.check(abs(kinetic_python[0] - undamped["energy/kinetic"][0]) <= BOOKKEEPING * e0,
                 f"(c) frame 0 kinetic: python {kinetic_python[0]:.10g} J, file "
                 f"{undamped['energy/kinetic'][0]:.10g} J")
    checks.check(error_k <= BOOKKEEPING,
                 f"(c) kinetic energy = 0.5 sum m|v|^2 on all {len(kinetic_python)} frames: "
                 f"max difference {error_k:.3e} of E0 (<= {BOOKKEEPING:g})")
    checks.check(abs(undamped["energy/elastic"][0]) <= ROUNDOFF * e0,
                 f"(c) frame 0 elastic energy {undamped['energy/elastic'][0]:.3e} J = 0")
    elastic_python = np.array([0.5 * u @ matvec(k_export, u) for u in
                               ((x - rest)[free].reshape(-1) for x in undamped["positions"])]) \
        if k_export[3] == (n_free, n_free) else np.full(len(total), np.inf)
    error_e = np.abs(elastic_python - undamped["energy/elastic"]).max() / e0
    last = len(elastic_python) - 1
    checks.check(error_e <= BOOKKEEPING and undamped["energy/elastic"][1:].min() > 0,
                 f"(c) elastic energy = 0.5 u^T K u on all frames: max difference {error_e:.3e} of E0 "
                 f"(frame {last}: python {elastic_python[last]:.10g} J, file "
                 f"{undamped['energy/elastic'][last]:.10g} J)")
    still = np.abs(undamped["positions"][:, fixed] - rest[fixed]).max()
    checks.check(still == 0.0 and np.abs(undamped["velocities"][:, fixed]).max() == 0.0,
                 f"(c) fixed body: never moves (max displacement {still:g})")

    # (d) A single free tetrahedron in uniform motion translates rigidly.
    velocity = np.array([0.3, -1.2, 0.7])
    with open(os.path.join(args.work, "tetrahedron.mesh"), "w") as f:
        f.write(TETRAHEDRON)
    tet_scene = harness.write_scene(
        os.path.join(args.work, "tet-scene.txt"),
        [("tetrahedron.mesh", 2.5, 10000.0, 0.3, False, (1, 2, 3), (1, 0, 0, 0))],
        [(0, i, velocity) for i in range(4)])
    rigid = simulate("tet", 1, tet_scene, ["-alpha", 0, "-beta", 0], steps=50)
    times = rigid["time"]
    expected = rigid["mesh/rest_positions"][None] + times[:, None, None] * velocity
    scale = np.abs(expected).max()
    error_x = np.abs(rigid["positions"] - expected).max()
    error_v = np.abs(rigid["velocities"] - velocity).max()
    checks.check(len(times) == 51 and abs(times[-1] - 1.0) < 1e-12 and error_x <= RIGID * scale,
                 f"(d) tet: positions = X + v t over {len(times)} frames to t = {times[-1]:.6g} s: "
                 f"max abs diff {error_x:.3e} m = {error_x / scale:.3e} of max |x| {scale:.4g} m")
    checks.check(error_v <= RIGID * np.abs(velocity).max(),
                 f"(d) tet: velocity stays v: max abs diff {error_v:.3e} m/s")
    tet_mass = harness.lumped_masses(rigid["mesh/tets"].astype(np.int64), rigid["mesh/rest_positions"],
                             rigid["mesh/vertex_body"].astype(np.int64), [2.5]).sum()
    kinetic_exact = 0.5 * tet_mass * velocity @ velocity
    drift_k = np.abs(rigid["energy/kinetic"] - kinetic_exact).max() / kinetic_exact
    elastic_max = np.abs(rigid["energy/elastic"]).max()
    checks.check(drift_k <= RIGID and elastic_max <= RIGID * kinetic_exact,
                 f"(d) tet: kinetic energy constant = 0.5 m |v|^2 = {kinetic_exact:.10g} J "
                 f"(relative deviation {drift_k:.3e}), max elastic {elastic_max:.3e} J")
    checks.exit()


if __name__ == "__main__":
    main()
