"""The collision guard: no surface crosses another or itself, counted by the exact checker.

Every frame of each run is checked by softbody-crossings (CGAL's exact
predicates, not the solver's geometry, src/crossings): intersecting triangle
pairs between free bodies, between free and fixed bodies, within a body (faces
sharing no vertex), and vertices below the ground.

(a) scenes/contact (docs/contact-crossings.md): two cubes thrown at each other
    at 3 x their wave speed (head-on), a cube dropped edge-first across a fixed
    wedge's ridge (edge against edge), a sheet folding over a fixed bar
    (self-contact), linear and corotational mode, 2 ranks: zero pairs of every
    kind in every frame, and the guard's summary line shows it acted (colliding
    pairs found), so the scenes test it. Control: head-on with -contact_guard 0
    crosses (the scene and the checker see crossings when there are some).
(b) Energy with restitution 0: in the wedge drop the total energy never rises
    from frame to frame by more than 1e-9 of the initial one, with the guard
    holding vertices.
(c) Rank invariance with the guard active (free body against a fixed one, the
    wedge, linear mode, direct solver), with -sharp_edges 0 (the guard alone
    meets the ridge) and with the ridge's sharp-edge points too: 2 and 3 ranks
    give the 1-rank positions and velocities to 1e-9 relative (measured 7e-15
    and 9e-15). Every rank tests its own pairs and merges the same sorted pairs;
    resting sharp-edge contacts are shared so that every rank re-aims them for
    its own vertices of the face (before, the wedge with them differed by
    0.18 m at 3 ranks).

Skipped when softbody-crossings was not built (no CGAL).
"""
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = os.path.join(ROOT, "scenes", "contact")
PRACTICAL3 = ["-options_file", os.path.join(ROOT, "config", "practical3.opts")]
CASES = {
    "head-on": ("head-on-scene.txt", ["-dt", "0.01", "-steps", "60"]),
    "wedge": ("wedge-scene.txt", PRACTICAL3 + ["-dt", "0.01", "-steps", "120"]),
    "sheet": ("sheet-scene.txt", PRACTICAL3 + ["-dt", "0.01", "-steps", "200"]),
}
KINDS = ("free_free", "free_fixed", "self", "below_ground")
RANK_TOLERANCE = 1e-9

args = harness.arguments()
checks = harness.Checks()
harness.crossings_checker(args)


def simulate(label, case, ranks, extra=()):
    """Runs a contact scene; returns (frames, stdout)."""
    scene, options = CASES[case]
    out = os.path.join(args.work, f"{label}.h5")
    result = harness.run(args, ranks, ["-scene", os.path.join(SCENES, scene), "-output", out]
                         + options + list(extra))
    return harness.read_frames(out), result.stdout, out


def crossings(path):
    """Per kind, the largest count over the frames (None when the checker failed)."""
    report = harness.run_crossings(args, checks, path)
    return {kind: max(frame[kind] for frame in report["frames"]) for kind in KINDS} if report else None


def guard_pairs(stdout):
    found = re.search(r"guard +\d+ passes with colliding surface pairs \((\d+) pairs", stdout)
    return int(found.group(1)) if found else None


print("(a) no crossing pair in any frame, linear and corotational, 2 ranks")
for case in CASES:
    for mode in ("linear", "corotational"):
        _, stdout, path = simulate(f"{case}-{mode}", case, 2, ["-mode", mode])
        counts = crossings(path)
        pairs = guard_pairs(stdout)
        checks.check(counts is not None and not any(counts.values()) and pairs,
                     f"(a) {case}, {mode}: largest counts per frame {counts} (all 0); the guard found "
                     f"{pairs} colliding pairs on the way")
_, _, control = simulate("head-on-unguarded", "head-on", 2, ["-contact_guard", "0"])
counts = crossings(control)
checks.check(counts is not None and counts["free_free"] > 0,
             f"(a) control: head-on with -contact_guard 0 crosses ({counts})")

print("(b) energy with restitution 0 (the wedge drop)")
wedge, _, _ = simulate("wedge-energy", "wedge", 2, ["-restitution", "0"])
total = wedge["energy/kinetic"] + wedge["energy/elastic"] + wedge["energy/gravitational"]
rise = np.diff(total).max() / abs(total[0])
checks.check(rise <= 1e-9, f"(b) wedge: largest frame-to-frame rise of the total energy {rise:+.1e} of the "
                           f"initial {total[0]:.4g} J (<= 1e-9); final {total[-1]:.4g} J")

print("(c) rank invariance with the guard active (the wedge, linear; without and with sharp edges)")
for label, extra in (("guard alone", ["-sharp_edges", "0"]), ("with sharp edges", [])):
    tag = label.replace(" ", "-")
    reference, stdout, _ = simulate(f"wedge-{tag}-1", "wedge", 1, extra)
    features = re.search(r"(\d+) sharp-edge contacts", stdout)
    checks.check(guard_pairs(stdout) and (features is not None) == bool(extra == []),
                 f"(c) {label}, 1 rank: the guard acted ({guard_pairs(stdout)} pairs), "
                 f"sharp-edge contacts: {features.group(1) if features else None}")
    for ranks in (2, 3):
        run, _, _ = simulate(f"wedge-{tag}-{ranks}", "wedge", ranks, extra)
        for key in ("positions", "velocities"):
            difference = harness.relative_difference(run[key], reference[key])
            checks.check(difference <= RANK_TOLERANCE,
                         f"(c) {label}, {ranks} ranks vs 1: {key} relative difference {difference:.1e} <= "
                         f"{RANK_TOLERANCE}")
checks.exit()
