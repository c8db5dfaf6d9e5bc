"""The "Practical 3" seed scenes: OFF bodies falling on the ground, and the stairway.

(a) ../shared/seed-data/infomgp-p3/{bunny,epcot,fertility}-scene.txt with
    -options_file config/practical3.opts (gravity, ground at y = 0), 2 ranks,
    -output_every 10: no NaN in positions, velocities or energies; every vertex
    at y >= -1e-6 at every frame after the initial one (and at the initial one
    too when the scene starts above the ground); the file complete; for the
    scenes that start clear of the ground, the total energy never increases.
    All three run 200 steps. fertility (below) went unstable after ~2 s
    (energy 1e52 J at t = 2.4 s): vertices held by two obstacles with nearly
    parallel normals (the ground and the other statue's face) were prescribed
    the least-norm velocity meeting both, (c_1 - c_2) / sin(angle), up to 1.2e3
    m/s; each vertex's constraints are now combined with bounded velocity
    (projected_solve.hpp, tests/test_contact_kernels.cpp). Its criteria: no
    NaN; total energy bounded, below 2 x its initial value at every frame
    (measured peak 1.61-1.67 x: the ground pushes the statues up by 6.2 m);
    lowest vertex after frame 0 above -1 % of the body height (measured -0.03
    to -0.2 m of 73 m, depending on the solver's round-off: two statues
    pressed into each other and the ground).
(b) ../shared/seed-data/cggs-cw2-2024/stairway-scene.txt as given (55 fixed
    6 m cubes, one free bunny) with practical3.opts -friction 0.5 -steps 600:
    the fixed cubes' vertices equal their rest positions bit for bit at every
    frame; no bunny vertex strictly inside a cube (|p - c| < 3 - 1e-6 on all
    three axes, c the scene position); the bunny ends at rest (KE < 1 % of
    peak). As placed (x = 25; the +x arm ends at x = 27) the bunny overhangs
    the end of the arm and slides off onto the ground.
    A copy with the bunny at x = 18 (over the middle of that arm), gravity,
    friction 0.5 and no ground, 800 steps: the bunny rests on the stairs (KE <
    1 % of peak, centroid y above the arm's top face y = 11), never inside a cube.

The fertility scene places its two statues overlapping each other (z from -85
to 60 and from -35 to 110) and 6.2 m into the ground, so frame 0 is below the
ground by construction: the ground pushes them out; the statues only stop
sinking further into each other (contact.hpp).
"""
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()
HERE = os.path.dirname(os.path.abspath(__file__))
P3 = os.path.join(HERE, "..", "config", "practical3.opts")


read = harness.read_frames


def simulate(name, scene, options, ranks=2):
    out = os.path.join(args.work, name + ".h5")
    if os.path.exists(out):
        os.remove(out)
    start = time.time()
    result = harness.run(args, ranks, ["-scene", scene, "-output", out, *options], timeout=600)
    seconds = time.time() - start
    summary = [l.strip() for l in result.stdout.splitlines() if l.strip().startswith(("contact", "time "))]
    print(f"  run {name}: {seconds:.1f} s wall; " + " | ".join(summary))
    return read(out), seconds


def scene_bodies(path):
    """(mesh, fixed, position) per body line of a scene file."""
    lines = [l.split("#")[0].split() for l in open(path)]
    lines = [l for l in lines if l]
    n = int(lines[0][0])
    return [(l[0], int(l[4]), np.array(l[5:8], float)) for l in lines[1:1 + n]]


# ---------------------------------------------------------------- (a) OFF scenes
for name in ("bunny", "epcot", "fertility"):
    scene = harness.seed(args, "infomgp-p3", f"{name}-scene.txt")
    steps = 200
    print(f"(a) {name}: {steps} steps")
    r, seconds = simulate(name, scene, ["-options_file", P3, "-steps", str(steps), "-output_every", "10"])
    finite = all(np.isfinite(r[k]).all() for k in ("positions", "velocities", "energy/kinetic", "energy/elastic",
                                                   "energy/gravitational"))
    checks.check(finite and r["complete"] == 1 and len(r["time"]) == steps // 10 + 1,
                 f"(a) {name}: no NaN/inf in positions, velocities, energies; complete, {len(r['time'])} frames "
                 f"to t = {r['time'][-1]:.2f} s ({seconds:.1f} s wall)")
    low = r["positions"][:, :, 1].min(axis=1)
    starts_above = low[0] >= -1e-6
    worst = int(np.argmin(low[1:])) + 1
    P0 = r["positions"][0]
    floor = -1e-6 if starts_above else -0.01 * (P0[:, 1].max() - P0[:, 1].min())
    checks.check(low[1:].min() >= floor,
                 f"(a) {name}: lowest vertex y {low[1:].min():.2e} m at t = {r['time'][worst]:.2f} s over the frames "
                 f"after the first (>= {floor:.2g}); frame 0: {low[0]:.3f} m"
                 + ("" if starts_above else " (the scene places it below the ground)"))
    total = r["energy/kinetic"] + r["energy/elastic"] + r["energy/gravitational"]
    rise = np.diff(total).max() / abs(total[0])
    if starts_above:
        checks.check(rise <= 1e-9,
                     f"(a) {name}: total energy never increases (largest frame-to-frame rise {rise:+.1e} of the "
                     f"initial {total[0]:.4g} J; final {total[-1]:.4g} J)")
    else:
        checks.check(total.max() <= 2 * total[0],
                     f"(a) {name}: total energy bounded: at most {total.max() / total[0]:.3f} x its initial "
                     f"{total[0]:.4g} J (<= 2; final {total[-1]:.4g} J at t = {r['time'][-1]:.2f} s; pushing the "
                     f"bodies out of the ground adds energy)")

# ---------------------------------------------------------------- (b) stairway
stairway = harness.seed(args, "cggs-cw2-2024", "stairway-scene.txt")
bodies = scene_bodies(stairway)
cubes = [i for i, b in enumerate(bodies) if b[1] == 1]
bunny = [i for i, b in enumerate(bodies) if b[1] == 0]
assert len(cubes) == 55 and len(bunny) == 1, "stairway: expected 55 fixed cubes and one free body"
bunny = bunny[0]
centres = np.array([bodies[i][2] for i in cubes])


def judge_stairway(label, r, on_stairs):
    body, P, X = r["mesh/vertex_body"], r["positions"], r["mesh/rest_positions"]
    fixed = np.isin(body, cubes)
    # The cubes are 6 m boxes at the scene positions (checked on the rest positions).
    boxes = np.array([[X[body == i].min(axis=0), X[body == i].max(axis=0)] for i in cubes])
    placement = max(np.abs(boxes[:, 0] - (centres - 3)).max(), np.abs(boxes[:, 1] - (centres + 3)).max())
    checks.check(placement < 1e-9 and np.all(r["mesh/body_fixed"][cubes] == 1),
                 f"(b) {label}: the 55 fixed cubes are the boxes scene position +- 3 m (to {placement:.1e} m)")
    still = bool(np.array_equal(P[:, fixed], np.broadcast_to(X[fixed], P[:, fixed].shape)))
    checks.check(still, f"(b) {label}: the cubes' {fixed.sum()} vertices equal their rest positions bit for bit "
                        f"in all {len(P)} frames")
    b = body == bunny
    depth = np.full(len(P), -np.inf)
    count = np.zeros(len(P), int)
    for f in range(len(P)):
        inside = 3.0 - np.abs(P[f, b][:, None, :] - centres[None, :, :]).max(axis=2)  # > 0: strictly inside
        depth[f] = inside.max()
        count[f] = int((inside.max(axis=1) > 1e-6).sum())
    bad = np.where(count > 0)[0]
    checks.check(len(bad) == 0,
                 f"(b) {label}: no bunny vertex strictly inside a cube (|p - c| < 3 - 1e-6 on all axes): deepest "
                 f"{depth.max():+.3f} m" + (f"; inside at t = {[round(float(r['time'][f]), 2) for f in bad]} s, "
                                            f"{count[bad].tolist()} vertices" if len(bad) else ""))
    ke = r["energy/kinetic"]
    # (Fixed bodies carry no velocity: the file's kinetic energy is the bunny's.)
    checks.check(r["complete"] == 1 and ke[-1] < 0.01 * ke.max(),
                 f"(b) {label}: at rest at the end: KE {ke[-1]:.3e} J = {ke[-1] / ke.max():.1e} of its peak "
                 f"{ke.max():.3e} J (t = {r['time'][ke.argmax()]:.1f} s)")
    centroid = P[-1, b].mean(axis=0)
    print(f"  {label}: bunny at t = {r['time'][-1]:.1f} s: centroid {centroid.round(2)}, "
          f"y from {P[-1, b, 1].min():.2f} to {P[-1, b, 1].max():.2f} m")
    if on_stairs:
        checks.check(centroid[1] > 11.0 and P[-1, b, 1].min() > 5.0,
                     f"(b) {label}: the bunny rests on the stairs: centroid y {centroid[1]:.2f} m above the arm's "
                     f"top face y = 11, lowest vertex {P[-1, b, 1].min():.2f} m (not on the ground)")
    return centroid


print("(b) stairway as given, -friction 0.5, 600 steps")
r, _ = simulate("stairway", stairway, ["-options_file", P3, "-friction", "0.5", "-steps", "600",
                                        "-output_every", "10"])
centroid = judge_stairway("as given", r, on_stairs=False)
print(f"  as given the bunny ends {'on the ground' if r['positions'][-1, r['mesh/vertex_body'] == bunny, 1].min() < 1e-6 else 'off the ground'}"
      f" (overhangs the end of the +x arm at x = 27)")

print("(b) stairway with the bunny over the middle of the +x arm (x = 18), no ground, 800 steps")
folder = os.path.dirname(stairway)
moved = os.path.join(args.work, "stairway-x18.txt")
with open(stairway) as src, open(moved, "w") as dst:
    for line in src:
        fields = line.split()
        if len(fields) >= 12:
            fields[0] = os.path.join(folder, fields[0])
            if not int(fields[4]):
                fields[5] = "18.0"
            line = " ".join(fields) + "\n"
        dst.write(line)
r, _ = simulate("stairway_x18", moved, ["-gravity", "0,-9.81,0", "-friction", "0.5", "-steps", "800",
                                         "-output_every", "10"])
judge_stairway("bunny at x = 18", r, on_stairs=True)
checks.exit()
