#!/usr/bin/python3
"""The direct fallback after a solver breakdown (-fallback_direct, integrator.hpp).

A single sliver tet 1 x 1 x 1e-5 m with E = 1e12 Pa, nu = 0.4999, struck
(z velocities -1, +1, +1, -1): the mass part of A is about 1e-19 of its stiffness
part, so A is not numerically positive definite. CHOLMOD's factorisation (PC
supernodal) and the warp preconditioner then break down on every rank at once,
and the step's system is solved again by the distributed fallback, SuperLU_dist
LU (column order by ParMETIS, no equilibration). Checked, 20 steps of 0.01 s:
(a) linear mode, direct preset, 1 and 2 ranks: exit 0, every solve repeated
    (attribute fallback_solves = 20), the positions equal those of a run with
    the fallback's factorisation as the solver to 1e-12 of the largest
    displacement and those of a run with MUMPS Cholesky (config/direct-mumps.opts,
    an independent factorisation of this matrix of condition ~1e19) to 1e-7 of
    it, and the angular momentum about the rest centre of mass decays as
    L(0) / (1 + a dt)^n (backward Euler, no external force) to 1e-10;
(b) corotational mode with the default (warp) and the direct preset, 2 ranks
    (the latter used to leave one rank waiting in the factorisation): exit 0,
    some solves repeated, finite, and kinetic + elastic energy never above the
    initial kinetic energy (backward Euler with damping dissipates);
(c) -fallback_direct 0: one error line naming DIVERGED_PC_FAILED, exit 1 on 2
    ranks within the time limit (no hang).
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()
HERE = os.path.dirname(os.path.abspath(__file__))
CONFIG = os.path.join(HERE, "..", "..", "config")
ALPHA, DT, STEPS, DENSITY = 0.1, 0.01, 20, 1000.0

mesh = os.path.join(args.work, "sliver.mesh")
with open(mesh, "w") as f:
    f.write("MeshVersionFormatted 1\nDimension 3\nVertices\n4\n0 0 0 0\n1 1 0 0\n1 0 1e-5 0\n0 1 1e-5 0\n"
            "Tetrahedra\n1\n1 3 2 4 0\nEnd\n")
scene = harness.write_scene(os.path.join(args.work, "sliver.txt"),
                            [("sliver.mesh", DENSITY, 1e12, 0.4999, 0, (0, 0, 0), (1, 0, 0, 0))],
                            [(0, 0, (0, 0, -1.0)), (0, 1, (0, 0, 1.0)), (0, 2, (0, 0, 1.0)), (0, 3, (0, 0, -1.0))])
common = ["-scene", scene, "-steps", STEPS, "-dt", DT, "-alpha", ALPHA, "-output_every", 1]


def simulate(label, ranks, options):
    output = os.path.join(args.work, f"{label}.h5")
    r = harness.run(args, ranks, common + options + ["-output", output], check=False)
    checks.check(r.returncode == 0, f"{label}: exit {r.returncode} {r.stderr.strip()[:200]}")
    if r.returncode != 0:
        return None
    import h5py
    frames = harness.read_frames(output)
    with h5py.File(output, "r") as f:
        frames["fallback_solves"] = float(f.attrs["fallback_solves"])
    return frames


def masses(frames):
    X, tets = frames["mesh/rest_positions"], frames["mesh/tets"]
    volume = abs(np.linalg.det(X[tets[0, 1:]] - X[tets[0, 0]])) / 6.0
    return np.full(len(X), DENSITY * volume / 4.0)


# The fallback's own settings (integrator.cpp) as the solver of a run.
SUPERLU_DIST = ["-ksp_type", "preonly", "-pc_type", "lu", "-pc_factor_mat_solver_type", "superlu_dist",
                "-mat_superlu_dist_colperm", "PARMETIS", "-mat_superlu_dist_equil", "false", "-fallback_direct", "0"]

for ranks in (1, 2):
    label = f"linear-{ranks}"
    r = simulate(label, ranks, ["-mode", "linear", "-options_file", os.path.join(CONFIG, "direct.opts")])
    reference = simulate(f"{label}-superlu_dist", ranks, ["-mode", "linear"] + SUPERLU_DIST)
    mumps = simulate(f"{label}-mumps", ranks,
                     ["-mode", "linear", "-options_file", os.path.join(CONFIG, "direct-mumps.opts")])
    if r is None or reference is None or mumps is None:
        continue
    checks.check(r["fallback_solves"] == STEPS, f"{label}: {r['fallback_solves']:g} of {STEPS} solves repeated")
    X = r["mesh/rest_positions"]
    scale = np.abs(r["positions"] - X).max()
    for name, other, limit in (("SuperLU_dist", reference, 1e-12), ("MUMPS", mumps, 1e-7)):
        difference = np.abs(r["positions"] - other["positions"]).max()
        checks.check(difference <= limit * scale, f"{label}: positions equal the {name} run's to {difference:.2g} m "
                     f"(limit {limit:g} x displacement {scale:.3g} m)")
    m = masses(r)
    centre = (m[:, None] * X).sum(0) / m.sum()
    L = np.einsum("i,fij->fj", m, np.cross(X - centre, r["velocities"]))
    decay = (1 + ALPHA * DT) ** -np.arange(len(L))
    error = np.abs(L - decay[:, None] * L[0]).max() / np.linalg.norm(L[0])
    checks.check(error <= 1e-10, f"{label}: angular momentum L(0) / (1 + a dt)^n kept to {error:.2g} (limit 1e-10)")

for preset in ("cg-warp", "direct"):
    label = f"corotational-{preset}"
    r = simulate(label, 2, ["-mode", "corotational", "-options_file", os.path.join(CONFIG, f"{preset}.opts")])
    if r is None:
        continue
    energy = r["energy/kinetic"] + r["energy/elastic"]
    finite = all(np.isfinite(r[k]).all() for k in ("positions", "velocities", "energy/kinetic", "energy/elastic"))
    checks.check(r["fallback_solves"] > 0 and finite,
                 f"{label}: {r['fallback_solves']:g} solves repeated, all values finite: {finite}")
    checks.check(energy.max() <= energy[0] * (1 + 1e-9),
                 f"{label}: energy never above the initial {energy[0]:.4g} J (largest {energy.max():.4g} J)")

r = harness.run(args, 2, common + ["-mode", "linear", "-fallback_direct", "0"], timeout=120, check=False)
lines = [line for line in r.stderr.splitlines() if line.startswith("softbody: error")]
checks.check(r.returncode != 0 and len(lines) == 1 and "DIVERGED_PC_FAILED" in lines[0],
             f"-fallback_direct 0: exit {r.returncode}, {lines}")
checks.exit()
