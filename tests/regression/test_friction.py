"""Coulomb friction (-friction mu) against closed forms: a block sliding to a
stop on the ground, and a block on a slope below and above the friction angle.

The body: a 0.5 m cube (tools/box_mesh.py, 4 x 4 x 4 cells, 125 vertices),
density 1000, E 1e6, nu 0.3, resting on the ground y = 0; mu = 0.5, dt = 0.01 s,
the default Rayleigh damping a = 0.1 1/s, b = 0.1 s. Mass damping acts on the
centroid's motion, dv/dt = F / M - a v; stiffness damping does not (b K has the
rigid translations in its null space), nor do the elastic forces (they sum to
zero). Every figure is recomputed here from the result file (the centroid from
the lumped masses of the mesh).

(a) Sliding to a stop, v0 = 2 m/s along x, linear mode on 1 and 2 ranks,
    corotational mode on 2. A rigid block obeys
    dv/dt = -mu g - a v, so v(t) = (v0 + mu g / a) exp(-a t) - mu g / a, it stops
    at t_s = ln(1 + a v0 / (mu g)) / a (0.3997 s) after x_s = (v0 - mu g t_s) / a
    (0.3970 m; without damping v0 / (mu g) = 0.4077 s and v0^2 / (2 mu g) =
    0.4077 m). Asserted: the distance slid within 5 % of x_s; the first frame
    with the centroid slower than 1 % of v0 within 5 % of the time the closed
    form takes to get there, and slower from then on; while sliding (0.02 to
    0.35 s), the friction force recomputed from the centroid's momentum balance
    M dv/dt = -F - a M v (backward Euler: F = -M ((v1 - v0) / dt + a v1)) is
    mu M g within 1 % on every step. Without friction the speed decays only by
    the mass damping, v0 / (1 + a dt)^n (1e-6).
(b) A slope of angle theta, made by tilting gravity, g = 9.81 (sin theta,
    -cos theta, 0), on the horizontal ground. (Only the angle between gravity
    and the surface matters; the ground is an exact plane with an exact normal,
    while a fixed tilted body would bring its own facets, sampled sharp edges and
    moving-obstacle grids into a test that is about friction alone.) The block
    starts at rest, undeformed.
    - tan theta = 0.4 and 0.45 (below mu): it stays. The elastic block settles
      (its base may slip locally while the contact pressure forms); asserted:
      every base vertex within 1 mm of its start (sliding freely it would go
      about 1.8 m in the second), the centroid within 2 mm, and at rest after
      0.6 s (centroid moves less than 1e-5 m from 0.6 s to the end, speed
      below 1e-4 m/s at the end).
    - tan theta = 0.55 and 0.8 (above mu): it slides with A = g (sin theta - mu
      cos theta) less the mass damping, v(t) = A / a (1 - exp(-a t)). The start
      from an undeformed body gives the block a small velocity offset in its
      first steps (the contact pressure forms), so the acceleration is measured
      after it: A_measured = a (v(1) - v(0.2) e^{-a 0.8}) / (1 - e^{-a 0.8}),
      asserted within 5 % of A (measured -0.2 % and -0.07 %); the distance in
      1 s within 5 % of A / a (t - (1 - e^{-a t}) / a) for tan theta = 0.8.
"""
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()

SIZE = 0.5                      # cube edge (m)
RHO, YOUNG, NU = 1000.0, 1e6, 0.3
G = 9.81
MU = 0.5
ALPHA = 0.1                     # default Rayleigh mass damping (1/s)
DT, STEPS = 0.01, 100
V0 = 2.0                        # sliding start speed (m/s)
TOLERANCE = 0.05                # the closed forms' tolerance (5 %)
FORCE_TOLERANCE = 0.01          # friction force while sliding, per step (1 %)

harness.box_mesh(args, "cube.mesh", (SIZE, SIZE, SIZE), (4, 4, 4))
NV = 125


def simulate(name, scene, gravity, friction, ranks=1, extra=()):
    out = harness.fresh_result(args.work, name)
    harness.run(args, ranks, ["-scene", scene, "-output", out, "-gravity", gravity, "-ground", "0",
                              "-restitution", "0", "-dt", str(DT), "-steps", str(STEPS),
                              "-friction", str(friction), *extra])
    frames = harness.read_frames(out)
    masses = harness.lumped_masses(frames["mesh/tets"], frames["mesh/rest_positions"],
                                   frames["mesh/vertex_body"], [RHO])
    centroid = np.einsum("fvc,v->fc", frames["positions"], masses) / masses.sum()  # per frame
    velocity = np.einsum("fvc,v->fc", frames["velocities"], masses) / masses.sum()
    return frames, masses, centroid, velocity


# ---------------------------------------------------------------- (a) sliding
print("(a) a block sliding to a stop, mu = 0.5, v0 = 2 m/s")
slide_scene = harness.write_scene(os.path.join(args.work, "slide.txt"),
                                  [("cube.mesh", RHO, YOUNG, NU, 0, (0, SIZE / 2, 0), (1, 0, 0, 0))],
                                  [(0, k, (V0, 0.0, 0.0)) for k in range(NV)])
t_stop = math.log(1 + ALPHA * V0 / (MU * G)) / ALPHA
x_stop = (V0 - MU * G * t_stop) / ALPHA
# Time at which the closed form's speed falls to 1 % of v0.
t_slow = math.log((V0 + MU * G / ALPHA) / (0.01 * V0 + MU * G / ALPHA)) / ALPHA
print(f"  closed form with mass damping: stops at t_s = {t_stop:.4f} s after x_s = {x_stop:.4f} m; "
      f"1 % of v0 at {t_slow:.4f} s")
for ranks, mode in ((1, "linear"), (2, "linear"), (2, "corotational")):
    frames, masses, centroid, velocity = simulate(f"slide_{ranks}_{mode}", slide_scene, "0,-9.81,0", MU, ranks,
                                                  ["-mode", mode])
    ranks = f"{ranks} ({mode})"
    t, vx = frames["time"], velocity[:, 0]
    slid = centroid[-1, 0] - centroid[0, 0]
    checks.check(abs(slid / x_stop - 1) < TOLERANCE,
                 f"(a) ranks {ranks}: distance slid {slid:.4f} m vs x_s = {x_stop:.4f} m "
                 f"({100 * (slid / x_stop - 1):+.2f} %, within {100 * TOLERANCE:g} %)")
    slow = np.abs(vx) < 0.01 * V0
    first = int(np.argmax(slow)) if slow.any() else None
    if first is None:
        checks.check(False, f"(a) ranks {ranks}: never slower than 1 % of v0 (final {vx[-1]:.3f} m/s)")
    else:
        checks.check(abs(t[first] / t_slow - 1) < TOLERANCE and slow[first:].all(),
                     f"(a) ranks {ranks}: slower than 1 % of v0 from t = {t[first]:.2f} s on vs "
                     f"{t_slow:.4f} s ({100 * (t[first] / t_slow - 1):+.2f} %, within {100 * TOLERANCE:g} %; "
                     f"final speed {abs(vx[-1]):.1e} m/s)")
    friction = -((vx[1:] - vx[:-1]) / DT + ALPHA * vx[1:]) / (MU * G)  # F / (mu M g), step n -> n+1
    sliding = [n for n in range(len(friction)) if 0.02 - 1e-9 <= t[n + 1] <= 0.35 + 1e-9]
    worst = max(sliding, key=lambda n: abs(friction[n] - 1))
    checks.check(abs(friction[worst] - 1) < FORCE_TOLERANCE,
                 f"(a) ranks {ranks}: friction force while sliding (0.02 to 0.35 s, {len(sliding)} steps) = "
                 f"mu M g within {100 * abs(friction[worst] - 1):.2f} % (worst at t = {t[worst + 1]:.2f} s; "
                 f"within {100 * FORCE_TOLERANCE:g} %)")

frames, masses, centroid, velocity = simulate("slide_mu0", slide_scene, "0,-9.81,0", 0)
discrete = V0 / (1 + ALPHA * DT) ** np.arange(len(velocity))
rel = np.abs(velocity[:, 0] - discrete).max() / V0
checks.check(rel < 1e-6,
             f"(a) mu = 0: the speed decays only by the mass damping, v0 / (1 + a dt)^n, to {rel:.1e} (< 1e-6)")

# ---------------------------------------------------------------- (b) slope
print("(b) a block on a slope (gravity tilted by theta), mu = 0.5")
rest_scene = harness.write_scene(os.path.join(args.work, "rest.txt"),
                                 [("cube.mesh", RHO, YOUNG, NU, 0, (0, SIZE / 2, 0), (1, 0, 0, 0))])
for tan in (0.4, 0.45, 0.55, 0.8):
    theta = math.atan(tan)
    gravity = f"{G * math.sin(theta):.17g},{-G * math.cos(theta):.17g},0"
    frames, masses, centroid, velocity = simulate(f"slope_{tan}", rest_scene, gravity, MU)
    t, X, P = frames["time"], frames["mesh/rest_positions"], frames["positions"]
    moved = centroid[:, 0] - centroid[0, 0]
    A = G * (math.sin(theta) - MU * math.cos(theta))
    if A < 0:
        base = np.isclose(X[:, 1], X[:, 1].min())
        base_moved = np.abs(P[:, base, 0] - P[0, base, 0]).max()
        late = t >= 0.6 - 1e-9
        creep = np.abs(moved[late] - moved[late][0]).max()
        free_slide = 0.5 * G * math.sin(theta)
        checks.check(base_moved < 1e-3 and np.abs(moved).max() < 2e-3,
                     f"(b) tan theta = {tan} < mu: stays; base vertices within {base_moved:.2e} m of their start "
                     f"(< 1e-3 m), centroid within {np.abs(moved).max():.2e} m (< 2e-3 m; frictionless it "
                     f"would slide {free_slide:.2f} m in 1 s)")
        checks.check(creep < 1e-5 and abs(velocity[-1, 0]) < 1e-4,
                     f"(b) tan theta = {tan}: at rest after 0.6 s: centroid moves {creep:.1e} m from then "
                     f"(< 1e-5 m), final speed {abs(velocity[-1, 0]):.1e} m/s (< 1e-4)")
        continue
    i1 = int(np.argmin(np.abs(t - 0.2)))
    span = t[-1] - t[i1]
    measured = ALPHA * (velocity[-1, 0] - velocity[i1, 0] * math.exp(-ALPHA * span)) / (1 - math.exp(-ALPHA * span))
    checks.check(abs(measured / A - 1) < TOLERANCE,
                 f"(b) tan theta = {tan} > mu: slides with acceleration {measured:.4f} m/s^2 (from v at "
                 f"{t[i1]:.1f} and {t[-1]:.1f} s, mass damping taken out) vs g (sin theta - mu cos theta) = "
                 f"{A:.4f} m/s^2 ({100 * (measured / A - 1):+.2f} %, within {100 * TOLERANCE:g} %)")
    expected = A / ALPHA * (t[-1] - (1 - math.exp(-ALPHA * t[-1])) / ALPHA)
    message = (f"distance in {t[-1]:.0f} s {moved[-1]:.4f} m vs A / a (t - (1 - e^(-a t)) / a) = {expected:.4f} m "
               f"({100 * (moved[-1] / expected - 1):+.2f} %")
    if tan == 0.8:
        checks.check(abs(moved[-1] / expected - 1) < TOLERANCE,
                     f"(b) tan theta = {tan}: {message}, within {100 * TOLERANCE:g} %)")
    else:
        print(f"  tan theta = {tan}: {message}: the start's offset, relative to the small A near the "
              f"friction angle)")
checks.exit()
