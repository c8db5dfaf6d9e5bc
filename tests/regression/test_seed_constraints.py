#!/usr/bin/env python3
"""Distance constraints on the seed data: the cylinder scene of cggs-cw2-2024.

Seed data only (../shared/seed-data/cggs-cw2-2024; skipped without it): the
constraints themselves are checked on the project's own meshes by
test_constraints.py, whose helpers this file uses.

(a) cylinder-scene.txt with cylinder-constraints.txt and config/practical3.opts,
    200 steps, 2 ranks: every constrained distance within [lo, hi] x rest at
    every frame (1e-6 relative) and every vertex above the ground; the seed
    bounds [0.8, 1.2] never bind there, so tests/data/constraints/cylinder-tight.txt
    asks [0.95, 1.02] of the same pairs, which the unconstrained run leaves
    (by more than 0.01) and the constrained run keeps (1e-6); the seed's
    emptyconstraints.txt loads (no constraint line in the summary) and gives the
    same frames as no -constraints, bit for bit.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402
from test_constraints import INPUTS, P3, TOL, bound_violation, constrained_ratios, read_constraints, simulate  # noqa: E402,E501


def main():
    args = harness.arguments()
    checks = harness.Checks()
    print("(a) seed cylinder scene with its constraints")
    scene = harness.seed(args, "cggs-cw2-2024", "cylinder-scene.txt")
    constraints_file = harness.seed(args, "cggs-cw2-2024", "cylinder-constraints.txt")
    empty = harness.seed(args, "cggs-cw2-2024", "emptyconstraints.txt")
    CYL = ["-options_file", P3, "-steps", "200"]
    a, out_a = simulate(args, "cylinders", scene, CYL + ["-constraints", constraints_file])
    constraints = read_constraints(constraints_file)
    ratio, bounds = constrained_ratios(a, constraints)
    excursion = bound_violation(ratio, bounds)
    checks.check(a["complete"] == 1 and excursion < TOL,
                 f"(a) {len(constraints)} constraints within [lo, hi] x rest at all {len(ratio)} frames: ratios "
                 f"{ratio.min(axis=0).round(4)}..{ratio.max(axis=0).round(4)} for bounds {bounds.tolist()}, excursion "
                 f"{excursion:.1e} (< {TOL})")
    checks.check(a["positions"][:, :, 1].min() >= -1e-9,
                 f"(a) above the ground throughout: min y {a['positions'][:, :, 1].min():.2e} m")
    none, out_none = simulate(args, "cylinders_none", scene, CYL)
    zero, out_zero = simulate(args, "cylinders_empty", scene, CYL + ["-constraints", empty])
    # The seed bounds [0.8, 1.2] never bind in this scene (see the ratios above);
    # tests/data/constraints/cylinder-tight.txt asks [0.95, 1.02] of the same pairs,
    # which the unconstrained run leaves: the check has teeth.
    tight_file = os.path.join(INPUTS, "cylinder-tight.txt")
    tight_constraints = read_constraints(tight_file)
    ratio_none, tight_bounds = constrained_ratios(none, tight_constraints)
    tight, _ = simulate(args, "cylinders_tight", scene, CYL + ["-constraints", tight_file])
    ratio_tight, _ = constrained_ratios(tight, tight_constraints)
    checks.check(bound_violation(ratio_none, tight_bounds) > 0.01 and bound_violation(ratio_tight, tight_bounds) < TOL,
                 f"(a) tight bounds [0.95, 1.02]: unconstrained ratios {ratio_none.min():.4f}..{ratio_none.max():.4f} "
                 f"(excursion {bound_violation(ratio_none, tight_bounds):.3f}); constrained "
                 f"{ratio_tight.min():.6f}..{ratio_tight.max():.6f} (excursion {bound_violation(ratio_tight, tight_bounds):.1e}"
                 f", < {TOL})")
    same = all(np.array_equal(zero[k], none[k]) for k in ("positions", "velocities", "energy/kinetic", "energy/elastic"))
    differs = not np.array_equal(a["positions"], none["positions"])
    checks.check(zero["complete"] == 1 and "distance constraints" not in out_zero and "constraint sweeps" not in out_zero,
                 f"(a) emptyconstraints.txt loads with 0 constraints: "
                 f"{[l.strip() for l in out_zero.splitlines() if l.strip().startswith('contact')]}")
    checks.check(same,
                 f"(a) emptyconstraints.txt gives the frames of a run without -constraints bit for bit "
                 f"(max |dx| {np.abs(zero['positions'] - none['positions']).max():.1e}); the constrained run differs: "
                 f"{differs}")
    checks.exit()


if __name__ == "__main__":
    main()
