"""Verification against physics: the first longitudinal mode of a free-free bar.

A free-free elastic bar of length L (x from 0 to L) has the longitudinal modes
u_x(x, t) = cos(k pi x / L) sin(omega_k t), omega_k = k pi c / L, c = sqrt(E / rho);
the first, k = 1, has

    f = (1 / 2L) sqrt(E / rho).

With nu = 0 there is no Poisson contraction, so the 3-D bar's longitudinal mode
is exactly this 1-D rod mode (u_x a function of x only, stress sigma_xx alone).
We start the mode with v_x(x) = V0 cos(pi x / L) on every vertex (no velocity
across, u = 0), no damping (-alpha 0 -beta 0), linear mode, standard elasticity
(-shear_scale 1), and measure the frequency from the zero crossings of the
end-to-end relative displacement s(t) = <u_x>(x = 0) - <u_x>(x = L) (mean over
each end face), located by linear interpolation between frames; a straight
line through the crossing times t_j = t_0 + j T / 2 gives the period.

Expected errors (both make the measured frequency LOWER than f, so they add):

* Space. The Kuhn tets interpolate a field u_x(x) linearly between the planes
  of vertices, so along the bar the mesh acts as 1-D linear elements; and the
  tets' lumped masses give each plane of vertices half of the neighbouring
  slabs' mass, as a 1-D lumped-mass rod. That rod's discrete mode is exactly
  cos(pi x_i / L) with omega_h = (2 c / h) sin(pi h / 2L), so
      f_h / f - 1 = -(pi h / L)^2 / 24 + O(h^4),
  second order and below f: the lumped mass softens the mode more than the
  linear interpolation stiffens it (a consistent mass would err upwards by
  +(pi h / L)^2 / 24 instead). N = 10, 20, 40 cells: -0.41 %, -0.10 %,
  -0.026 %. The cross-section couples a little: lumped masses and the
  forces of a field u_x(x) are not in the same ratio at every vertex of a
  plane, and the Kuhn split is not symmetric under y -> -y, so the sampled
  cosine is not exactly a discrete mode (torsion and others get 0.5 % of the
  energy at 10 cells, 1.3e-4 at 40) and the 3-D mode is a little stiffer than
  the 1-D rod at 10 cells. The semi-discrete frequency f_h and mode phi are
  therefore taken from the exported M and K (dense eigenproblem; the mode
  with the largest share of the initial kinetic energy).
* Time. Backward Euler on one mode, v1 = v0 - dt w^2 u1, u1 = u0 + dt v1,
  multiplies (u, v) by z = 1 / (1 - i w dt) per step (up to conjugation):
  phase atan(w dt) per step, modulus (1 + w^2 dt^2)^(-1/2). Started at u = 0,
  u_n is exactly proportional to |z|^n sin(n atan(w dt)), so the zero crossings
  of that mode's amplitude give the frequency atan(w dt) / (2 pi dt):
      f_dt / f_h - 1 = atan(w dt) / (w dt) - 1 = -(w dt)^2 / 3 + O(dt^4),
  also second order and below f_h (dt = T/200: -3.3e-4; T/1600: -5.1e-6). The
  damping is first order: the energy falls by (1 + w^2 dt^2)^(-n) after n
  steps, i.e. at the rate w^2 dt per unit time (18 % of the energy lost per
  period at T/200, 2.4 % at T/1600). That is why dt is small compared to the
  period and only ~3 periods are measured; the decay does not move the zero
  crossings.

The other modes' small part shifts the crossings of the end signal s(t) a
little (by at most 1.7e-4 relative at 10 cells, 8e-6 at 40, nearly the same at
every dt); the mode's own amplitude q(t) = phi^T M u(t) is free of them
(backward Euler keeps M-orthogonal modes apart exactly), which is what the
checks of the time integrator (f) use.

So the error against the analytic f falls monotonically with refinement of
either h (at a small dt) or dt (on any fixed mesh). The script runs the whole
grid (3 meshes x 4 time steps, 2 ranks each), prints the table and checks:

(a) on every mesh the error falls monotonically as dt shrinks;
(b) at every dt the error falls monotonically as the mesh is refined, with an
    observed order of about 2 (1.6 .. 2.4) between the meshes at the finest dt;
(c) every measured frequency lies below f (both errors are negative);
(d) the finest combination is within 1 % of f (it is within 0.03 %);
(e) the semi-discrete frequency f_h from the exported M and K agrees with the
    1-D lumped-mass rod formula (to 15 % of its error) and converges to f;
(f) the frequency of the modal amplitude q(t) equals backward Euler's
    atan(w_h dt) / (2 pi dt) on f_h to 2e-6 relative on every run; its time
    error q / f_h - 1 has the order 2 (1.9 .. 2.1) between consecutive dt; the
    end signal's frequency is within 3e-4 of the modal one;
(g) the energy lost over the run matches the predicted first-order damping
    (1 + w_h^2 dt^2)^(-n) to 1 % of the loss.
"""
import math
import os
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

TOOLS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools")

LENGTH = 1.0           # m, along x
WIDTH = 0.1            # m, square cross-section
YOUNG = 1e6            # Pa
DENSITY = 1000.0       # kg/m^3
V0 = 1e-3              # m/s, amplitude of the initial velocity (linear mode: any value)
CELLS = (10, 20, 40)   # cells along x; 2 x 2 across
ACROSS = 2
DIVISIONS = (200, 400, 800, 1600)  # dt = T / division
PERIODS = 3.25         # simulated time, in analytic periods (6 zero crossings after t = 0)
FRAMES_PER_PERIOD = 100
RANKS = 2

SPEED = math.sqrt(YOUNG / DENSITY)       # 31.6 m/s
FREQUENCY = SPEED / (2.0 * LENGTH)       # 15.81 Hz
PERIOD = 1.0 / FREQUENCY                 # 63.2 ms


def box_mesh(path, cells):
    subprocess.run([sys.executable, os.path.join(TOOLS, "box_mesh.py"), path,
                    "-box_size", str(LENGTH), str(WIDTH), str(WIDTH),
                    "-box_cells", str(cells), str(ACROSS), str(ACROSS)], check=True, capture_output=True)


def rest_vertices(mesh):
    tokens = open(mesh).read().split()
    i = tokens.index("Vertices")
    n = int(tokens[i + 1])
    return np.array(tokens[i + 2:i + 2 + 4 * n], float).reshape(n, 4)[:, :3]


def crossing_frequency(times, signal):
    """Frequency from the zero crossings of signal (after frame 0, where it is 0):
    each crossing by linear interpolation between the two frames around it, then
    a least-squares line t_j = t_0 + j T / 2."""
    crossings = []
    for i in range(1, len(signal) - 1):
        a, b = signal[i], signal[i + 1]
        if a == 0.0:
            crossings.append(times[i])
        elif a * b < 0.0:
            crossings.append(times[i] - a * (times[i + 1] - times[i]) / (b - a))
    if len(crossings) < 3:
        return float("nan"), len(crossings)
    half_period = np.polyfit(np.arange(len(crossings)), crossings, 1)[0]
    return 1.0 / (2.0 * half_period), len(crossings)


def semi_discrete_mode(matrices, v0):
    """(f_h, share, M phi): the eigenfrequency of K phi = w^2 M phi (exported
    matrices, natural order, M diagonal) whose mode carries the largest part of
    the initial kinetic energy, that part, and M phi (phi^T M phi = 1), so that
    (M phi) . u is the mode's amplitude in a displacement u."""
    m_rows, m_cols, m_values, shape = harness.read_petsc_aij(os.path.join(matrices, "M.bin"))
    k_rows, k_cols, k_values, _ = harness.read_petsc_aij(os.path.join(matrices, "K.bin"))
    n = shape[0]
    mass = np.bincount(m_rows, weights=np.where(m_rows == m_cols, m_values, 0.0), minlength=n)
    scale = 1.0 / np.sqrt(mass)
    stiffness = np.zeros((n, n))
    np.add.at(stiffness, (k_rows, k_cols), k_values)
    eigenvalues, vectors = np.linalg.eigh(stiffness * scale[:, None] * scale[None, :])
    coefficients = vectors.T @ (np.sqrt(mass) * v0)  # modal velocities, M-orthonormal modes
    j = int(np.argmax(np.abs(coefficients)))
    share = coefficients[j] ** 2 / np.sum(coefficients ** 2)
    return math.sqrt(eigenvalues[j]) / (2.0 * math.pi), float(share), np.sqrt(mass) * vectors[:, j]


def main():
    args = harness.arguments()
    checks = harness.Checks()
    started = time.time()

    rows = []  # (cells, division, dt, f, error, f_h, predicted, energy ratio, predicted ratio)
    semi = {}
    for cells in CELLS:
        name = f"bar{cells}"
        mesh = os.path.join(args.work, name + ".mesh")
        box_mesh(mesh, cells)
        X = rest_vertices(mesh)
        x = X[:, 0] - X[:, 0].min()
        velocities = [(0, k, (V0 * math.cos(math.pi * x[k] / LENGTH), 0.0, 0.0)) for k in range(len(X))]
        scene = harness.write_scene(os.path.join(args.work, name + ".txt"),
                                    [(name + ".mesh", DENSITY, YOUNG, 0.0, 0, (0, 0, 0), (1, 0, 0, 0))],
                                    velocities)
        first = end = ends = None
        for division in DIVISIONS:
            dt = PERIOD / division
            every = max(1, division // FRAMES_PER_PERIOD)
            steps = int(round(PERIODS * division))
            out = os.path.join(args.work, f"{name}_T{division}.h5")
            options = ["-scene", scene, "-output", out, "-mode", "linear", "-alpha", 0, "-beta", 0,
                       "-shear_scale", 1, "-dt", repr(dt), "-steps", steps, "-output_every", every]
            matrices = os.path.join(args.work, name + "_matrices")
            if first is None:
                options += ["-export_matrices", matrices]
            harness.run(args, RANKS, options)
            r = harness.read_frames(out)
            rest = r["mesh/rest_positions"]
            if first is None:
                first = r
                start = np.isclose(rest[:, 0], rest[:, 0].min())
                end = np.isclose(rest[:, 0], rest[:, 0].max())
                ends = (int(start.sum()), int(end.sum()))
                v_initial = r["velocities"][0].ravel()
                semi[cells] = semi_discrete_mode(matrices, v_initial)
            u = r["positions"][:, :, 0] - rest[None, :, 0]
            signal = u[:, start].mean(axis=1) - u[:, end].mean(axis=1)
            f, count = crossing_frequency(r["time"], signal)
            displacement = (r["positions"] - rest[None]).reshape(len(r["time"]), -1)
            f_modal, _ = crossing_frequency(r["time"], displacement @ semi[cells][2])
            f_h = semi[cells][0]
            w_h = 2.0 * math.pi * f_h
            predicted = math.atan(w_h * dt) / (2.0 * math.pi * dt)
            energy = r["energy/kinetic"] + r["energy/elastic"]
            n = int(round(r["time"][-1] / dt))
            rows.append(dict(cells=cells, division=division, dt=dt, f=f, crossings=count, f_modal=f_modal,
                             error=f / FREQUENCY - 1.0, f_h=f_h, predicted=predicted,
                             energy_ratio=energy[-1] / energy[0],
                             energy_predicted=(1.0 + (w_h * dt) ** 2) ** (-n),
                             vertices=len(rest), frames=len(r["time"]), steps=n))
        print(f"mesh {cells} x {ACROSS} x {ACROSS} cells: {rows[-1]['vertices']} vertices, "
              f"end faces {ends[0]} + {ends[1]} vertices, initial kinetic energy "
              f"{first['energy/kinetic'][0]:.6e} J")

    print(f"\nfree-free bar L = {LENGTH} m, {WIDTH} x {WIDTH} m, E = {YOUNG:g} Pa, rho = {DENSITY:g} kg/m^3, "
          f"nu = 0: c = {SPEED:.6f} m/s, analytic f = {FREQUENCY:.6f} Hz, T = {1e3 * PERIOD:.6f} ms")
    print(f"{'cells':>5} {'dt':>10} {'T/dt':>5} {'steps':>5} {'xings':>5} {'measured f':>12} "
          f"{'analytic f':>11} {'rel. error':>11} {'f_h (M,K)':>11} {'f/f_h-1':>10} {'q: f/f_h-1':>10} "
          f"{'BE pred.':>10} "
          f"{'E_end/E_0':>9} {'predicted':>9}")
    for row in rows:
        print(f"{row['cells']:>5} {row['dt']:10.4e} {row['division']:>5} {row['steps']:>5} "
              f"{row['crossings']:>5} {row['f']:12.6f} {FREQUENCY:11.6f} {row['error']:+11.3e} "
              f"{row['f_h']:11.6f} {row['f'] / row['f_h'] - 1:+10.3e} {row['f_modal'] / row['f_h'] - 1:+10.3e} "
              f"{row['predicted'] / row['f_h'] - 1:+10.3e} {row['energy_ratio']:9.5f} "
              f"{row['energy_predicted']:9.5f}")
    table = {(row["cells"], row["division"]): row for row in rows}
    print("\nrelative frequency error (measured / analytic - 1):")
    print("| cells along x (h) | " + " | ".join(f"dt = T/{d}" for d in DIVISIONS) + " |")
    print("|---|" + "---|" * len(DIVISIONS))
    for cells in CELLS:
        print(f"| {cells} ({LENGTH / cells:g} m) | "
              + " | ".join(f"{100 * table[(cells, d)]['error']:+.4f} %" for d in DIVISIONS) + " |")

    ok = all(row["crossings"] >= 6 and math.isfinite(row["f"]) for row in rows)
    checks.check(ok, f"every run has at least 6 zero crossings "
                     f"({min(row['crossings'] for row in rows)} .. {max(row['crossings'] for row in rows)})")

    # (a) time step: monotone on every mesh
    for cells in CELLS:
        errors = [abs(table[(cells, d)]["error"]) for d in DIVISIONS]
        checks.check(all(b < a for a, b in zip(errors, errors[1:])),
                     f"(a) {cells} cells: |error| falls with dt: "
                     + " > ".join(f"{e:.3e}" for e in errors))

    # (b) mesh: monotone at every dt, order ~2 at the finest dt
    for d in DIVISIONS:
        errors = [abs(table[(cells, d)]["error"]) for cells in CELLS]
        checks.check(all(b < a for a, b in zip(errors, errors[1:])),
                     f"(b) dt = T/{d}: |error| falls with h: " + " > ".join(f"{e:.3e}" for e in errors))
    finest = DIVISIONS[-1]
    for coarse, fine in zip(CELLS, CELLS[1:]):
        order = math.log(table[(coarse, finest)]["error"] / table[(fine, finest)]["error"]) / \
            math.log(fine / coarse)
        checks.check(1.6 <= order <= 2.4, f"(b) observed order in h, {coarse} -> {fine} cells at "
                                          f"T/{finest}: {order:.3f} (1.6 .. 2.4)")

    # (c) both errors lower the frequency
    highest = max(row["error"] for row in rows)
    checks.check(highest < 0, f"(c) every measured f is below the analytic f (largest error {highest:+.3e})")

    # (d) the finest combination
    best = table[(CELLS[-1], finest)]
    checks.check(abs(best["error"]) < 0.01,
                 f"(d) finest ({CELLS[-1]} cells, dt = T/{finest}): f = {best['f']:.6f} Hz vs "
                 f"{FREQUENCY:.6f} Hz, error {100 * best['error']:+.4f} % (< 1 %)")

    # (e) the semi-discrete frequency against the 1-D lumped-mass rod
    for cells in CELLS:
        f_h, share, _ = semi[cells]
        h = LENGTH / cells
        rod = (2.0 * SPEED / h) * math.sin(math.pi * h / (2.0 * LENGTH)) / (2.0 * math.pi)
        e_h, e_rod = f_h / FREQUENCY - 1.0, rod / FREQUENCY - 1.0
        checks.check(abs(e_h - e_rod) <= 0.15 * abs(e_rod),
                     f"(e) {cells} cells: f_h = {f_h:.6f} Hz (error {e_h:+.3e}, mode holds {share:.6f} of "
                     f"the initial energy) vs 1-D lumped rod {rod:.6f} Hz (error {e_rod:+.3e})")
    e_semi = [abs(semi[cells][0] / FREQUENCY - 1.0) for cells in CELLS]
    checks.check(all(b < a for a, b in zip(e_semi, e_semi[1:])),
                 "(e) |f_h / f - 1| falls with h: " + " > ".join(f"{e:.3e}" for e in e_semi))

    # (f) backward Euler's phase on the semi-discrete mode
    worst = max(rows, key=lambda row: abs(row["f_modal"] / row["predicted"] - 1.0))
    deviation = worst["f_modal"] / worst["predicted"] - 1.0
    checks.check(abs(deviation) < 2e-6,
                 f"(f) modal amplitude: f = atan(w_h dt) / (2 pi dt) on every run to {abs(deviation):.2e} "
                 f"(worst: {worst['cells']} cells, T/{worst['division']}) < 2e-6")
    for cells in CELLS:
        errors = [table[(cells, d)]["f_modal"] / semi[cells][0] - 1.0 for d in DIVISIONS]
        orders = [math.log(a / b) / math.log(d2 / d1) if a * b > 0 else float("nan")
                  for a, b, d1, d2 in zip(errors, errors[1:], DIVISIONS, DIVISIONS[1:])]
        checks.check(all(1.9 <= o <= 2.1 for o in orders),
                     f"(f) {cells} cells: time error of the modal frequency "
                     + ", ".join(f"{e:+.3e}" for e in errors) + ": orders "
                     + ", ".join(f"{o:.3f}" for o in orders) + " (1.9 .. 2.1)")
    worst = max(rows, key=lambda row: abs(row["f"] / row["f_modal"] - 1.0))
    shift = worst["f"] / worst["f_modal"] - 1.0
    checks.check(abs(shift) < 3e-4,
                 f"(f) the other modes shift the end signal's frequency by at most {shift:+.2e} "
                 f"({worst['cells']} cells, T/{worst['division']}) < 3e-4")

    # (g) first-order damping
    worst = max(rows, key=lambda row: abs((1 - row["energy_ratio"]) / (1 - row["energy_predicted"]) - 1))
    mismatch = (1 - worst["energy_ratio"]) / (1 - worst["energy_predicted"]) - 1
    checks.check(abs(mismatch) < 0.01,
                 f"(g) energy lost matches (1 + w_h^2 dt^2)^-n to {100 * abs(mismatch):.2f} % of the loss "
                 f"(worst: {worst['cells']} cells, T/{worst['division']}: lost {1 - worst['energy_ratio']:.5f}, "
                 f"predicted {1 - worst['energy_predicted']:.5f})")

    print(f"{len(rows)} runs on {RANKS} ranks in {time.time() - started:.1f} s")
    checks.exit()


if __name__ == "__main__":
    main()
