#!/usr/bin/python3
"""Momentum of a free body: backward Euler keeps it, the solver must not lose it.

With no external force and no contact, every equation of the step summed over a
body's vertices gives (internal forces have no net force; in linear mode no net
torque about the rest centre of mass either, since K annihilates infinitesimal
rotations about the rest shape):

    P(n) = sum_i m_i v_i(n) = P(0) / (1 + a dt)^n                 (both modes)
    L(n) = sum_i (X_i - c) x m_i v_i(n) = L(0) / (1 + a dt)^n      (linear mode)

Checked on a 1 m cube (E = 1e6 Pa, nu = 0.3) and on a stiff, nearly
incompressible plate of 2 x 2 x 0.001 m (E = 1e12 Pa, nu = 0.4999: A's mass part
is below the round-off of its stiffness part, so a factorisation alone returns
rigid-body velocities of noise; softbody takes them from the momentum), thrown
and struck, 2 ranks. Tolerances: 1e-10 relative (linear, direct solver); 1e-7
(corotational, cube only: CG at rtol 1e-10).
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ALPHA, DT, STEPS = 0.1, 0.01, 20


def momenta(frames, masses, angular):
    X = frames["mesh/rest_positions"]
    centre = (masses[:, None] * X).sum(0) / masses.sum()
    p = np.einsum("i,fij->fj", masses, frames["velocities"])
    L = np.einsum("i,fij->fj", masses, np.cross(X - centre, frames["velocities"])) if angular else None
    return p, L


def lumped_masses(frames, density):
    X, tets = frames["mesh/rest_positions"], frames["mesh/tets"]
    d = X[tets[:, 1:]] - X[tets[:, :1]]
    volumes = np.abs(np.linalg.det(d)) / 6.0
    masses = np.zeros(len(X))
    np.add.at(masses, tets.ravel(), np.repeat(density * volumes / 4.0, 4))
    return masses


def main():
    args = harness.arguments()
    checks = harness.Checks()
    bodies = {
        "cube": (harness.box_mesh(args, "cube.mesh", (1.0, 1.0, 1.0), (3, 3, 3)), 1e6, 0.3),
        "stiff-plate": (harness.box_mesh(args, "plate.mesh", (2.0, 2.0, 1e-3), (2, 2, 1)), 1e12, 0.4999),
    }
    for name, (mesh, young, nu) in bodies.items():
        # Thrown (every vertex) and struck (vertex 0 and 1 in opposite directions).
        count = int(open(mesh).read().split("Vertices")[1].split()[0])
        velocities = [(0, v, (1.0, 0.5, -0.2)) for v in range(count)]
        velocities[0] = (0, 0, (1.0, 0.5, 2.8))
        velocities[1] = (0, 1, (-2.0, 0.5, -0.2))
        scene = harness.write_scene(os.path.join(args.work, f"{name}.txt"),
                                    [(os.path.basename(mesh), 1000.0, young, nu, 0, (0, 0, 0), (1, 0, 0, 0))],
                                    velocities)
        # Corotational mode on the stiff plate loses the momentum to the same
        # round-off (README, known limitations): not checked.
        modes = (("linear", 1e-10),) if name == "stiff-plate" else (("linear", 1e-10), ("corotational", 1e-7))
        for mode, tolerance in modes:
            output = os.path.join(args.work, f"{name}-{mode}.h5")
            harness.run(args, 2, ["-scene", scene, "-mode", mode, "-steps", STEPS, "-dt", DT, "-alpha", ALPHA,
                                  "-output", output])
            frames = harness.read_frames(output)
            masses = lumped_masses(frames, 1000.0)
            p, L = momenta(frames, masses, mode == "linear")
            decay = (1 + ALPHA * DT) ** -np.arange(len(p))
            error_p = np.max(np.linalg.norm(p - decay[:, None] * p[0], axis=1)) / np.linalg.norm(p[0])
            checks.check(error_p <= tolerance,
                         f"{name}, {mode}: momentum kept to {error_p:.2g} of |P(0)| (limit {tolerance:g})")
            if L is not None:
                error_L = np.max(np.linalg.norm(L - decay[:, None] * L[0], axis=1)) / np.linalg.norm(L[0])
                checks.check(error_L <= tolerance,
                             f"{name}, {mode}: angular momentum about the rest centre kept to {error_L:.2g} "
                             f"of |L(0)| (limit {tolerance:g})")
    checks.exit()


if __name__ == "__main__":
    main()
