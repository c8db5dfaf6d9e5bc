"""The time integrators of -integrator on one vibration mode of a free-free bar.

A bar (1 m x 0.1 m x 0.1 m, 10 x 2 x 2 cells, nu = 0) starts with the velocity
v_x = V0 cos(pi x / L). Its semi-discrete modes come from the exported M and K
(-export_matrices; dense generalized eigenproblem K phi = w^2 M phi, phi
M-orthonormal); with Rayleigh damping D = a M + b K every mode is a scalar
oscillator q'' + c q' + w^2 q = 0, c = a + b w^2, and in linear mode every
scheme advances each mode on its own. The amplitude q = phi^T M (x - X) and
velocity p = phi^T M v of the mode with most of the initial energy are
compared with independent references:

(a) each scheme's textbook recurrence on that scalar oscillator, written here
    from its usual form (backward Euler; BDF2 on x and v, started by one
    step of the theta method with theta = 2/3 in linear mode, of backward
    Euler in corotational mode; Newmark beta = 1/4, gamma = 1/2 in x, v, a;
    Chung-Hulbert's generalized-alpha in x, v, a with a_0 from the equation
    of motion), with damping, at dt = T/20: q_n and p_n agree to 1e-9 of the
    amplitude at every step, linear mode; corotational mode (the motion is a
    strain of 1e-6, so the nonlinearity is below 1e-5) to 1e-4;
(b) the order in dt of the error at t = T against the exact damped solution
    (no damping: cos / sin), dt = T/40 .. T/320: slope of log error against
    log dt (least squares) 1 +- 0.3 for be, 2 +- 0.3 for the others;
(c) newmark without damping: total energy (kinetic + elastic, from the
    result file) constant to 1e-10 relative over 1000 steps at dt = T/20;
    the mode's frequency (angle per step fitted to q_n) equals the trapezoidal
    rule's 2 atan(w dt / 2) / dt to 1e-8 relative; that is -0.81 % at T/20
    (so below 1 %) and -0.49 % at T/26 (below 0.5 %; be's amplitude loss per
    period at T/20 is printed for comparison);
(d) alpha's dissipation of unresolved modes: at dt = 1600 T (w dt = 1e4) the
    spectral radius of the step, from a least-squares fit of an order-3
    linear recurrence to the measured q_n, equals -alpha_rho_inf to 1 %
    for rho_inf = 0.5 and 0.9 (and the textbook recurrence's radius at this
    w dt, to 1e-3; the radius tends to rho_inf as 1 / sqrt(w dt): 2 % above
    it at w dt = 628).
(e) corotational orders on a smooth large motion: a 2 x 0.4 x 0.4 m beam
    (10 x 2 x 2 cells, E = 2.5e4 Pa, nu = 0.45) struck with the bending field
    v_z = 2 m/s cos(2 pi x / L) moves by up to 0.4 m in T = 0.2 s (no damping,
    -newton_rtol 1e-10); the error at T against a bdf2 run at dt = 3.125e-4 s
    for dt = 0.02 .. 0.0025 s: fitted order 1 +- 0.3 for be, 2 +- 0.3 for the
    others (measured 0.87, 1.83, 2.00, 2.00).
(f) bad values (-integrator foo, -alpha_rho_inf 2, -0.1, abc, -tol 0) stop both
    ranks before set-up with one line naming the option (-dt_adapt with
    contact: test_adaptive_contact.py).
(g) -dt_adapt on the bar's mode (no damping), steps of T/2 (frames at
    t = k T/2), 4 steps: for -tol 1e-2 .. 1e-5 (1e-6 takes 14 000 substeps
    since -tol is per unit time: left out for the suite's time) the error at 2T against the exact
    solution falls monotonically with -tol, every run rejects at least one
    substep (the first substeps of size T/2 miss any of these tolerances: the
    rejected path), the frames lie at k T/2 to 1e-12, the result file has
    accepted_steps, rejected_steps, min_dt and max_dt and the run summary says
    so; for bdf2 and newmark.
(h) -dt_adapt against a damped strike (linear mode, a = 0.5 1/s, b = 2e-3 s):
    the bar at rest, its x = L end vertices struck at 1 m/s along x (an impulse
    with most of its energy in stiff, overdamped modes); 5 steps of T/2; the
    exact solution at 5T/2 from every mode of the exported M and K (each a
    damped scalar oscillator, solved by the matrix exponential). For bdf2 and
    newmark at -tol 1e-2, 1e-3, 1e-4 the relative L2 error of x - X at the end
    falls monotonically and lies within [tol / 30, 3 tol]: -tol is about the
    error at the end (the estimate is filtered by the damping over the run and
    scaled per unit step to the run's length; a per-substep tolerance gave
    errors of tol^(2/3), above 3 tol at 1e-4).
(i) the factorisations kept per substep size (-dt_adapt_factors): the runs of
    (h) at -tol 1e-3 fill (and factorise) A fewer times than with
    -dt_adapt_factors 1, and their frames are equal bit for bit.
"""
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

LENGTH, WIDTH, CELLS, ACROSS = 1.0, 0.1, 10, 2
YOUNG, DENSITY, V0 = 1e6, 1000.0, 1e-3
RANKS = 2
SCHEMES = ("be", "bdf2", "newmark", "alpha")
RHO_INF = 0.9  # the default of -alpha_rho_inf


# ----------------------------------------------------------------------------- references
def alpha_parameters(rho):
    """Chung & Hulbert (1993), eqs. (25) and (17), (20)."""
    am = (2 * rho - 1) / (rho + 1)
    af = rho / (rho + 1)
    gamma = 0.5 - am + af
    beta = 0.25 * (1 - am + af) ** 2
    return am, af, gamma, beta


def reference(scheme, w, c, dt, steps, q0, p0, rho=RHO_INF, start="theta"):
    """(q_n, p_n), n = 0..steps, of `scheme` on q'' + c q' + w^2 q = 0 (bdf2's
    first step: `start`, theta or be)."""
    q, p = [q0], [p0]
    if scheme == "be":  # (v1 - v0)/dt = -c v1 - w^2 x1, x1 = x0 + dt v1
        for _ in range(steps):
            v = (p[-1] - dt * w * w * q[-1]) / (1 + dt * c + dt * dt * w * w)
            p.append(v)
            q.append(q[-1] + dt * v)
    elif scheme == "bdf2":  # 3/2 y1 - 2 y0 + 1/2 y_-1 = dt y1', first step the theta method, theta = 2/3
        q1, p1 = reference(start, w, c, dt, 1, q0, p0)
        q, p = list(q1), list(p1)
        for _ in range(steps - 1):
            # 1.5 x - dt v = 2 q0 - 0.5 q_-1;  dt w^2 x + (1.5 + dt c) v = 2 p0 - 0.5 p_-1
            matrix = np.array([[1.5, -dt], [dt * w * w, 1.5 + dt * c]])
            rhs = np.array([2 * q[-1] - 0.5 * q[-2], 2 * p[-1] - 0.5 * p[-2]])
            x, v = np.linalg.solve(matrix, rhs)
            q.append(x)
            p.append(v)
    elif scheme == "theta":  # y1 = y0 + dt (theta y1' + (1 - theta) y0') for y = x, v; theta = 2/3
        theta = 2.0 / 3.0
        for _ in range(steps):
            x0, v0 = q[-1], p[-1]
            a0 = -c * v0 - w * w * x0
            # x - theta dt v = x0 + (1-theta) dt v0;  theta dt w^2 x + (1 + theta dt c) v = v0 + (1-theta) dt a0
            matrix = np.array([[1.0, -theta * dt], [theta * dt * w * w, 1.0 + theta * dt * c]])
            rhs = np.array([x0 + (1 - theta) * dt * v0, v0 + (1 - theta) * dt * a0])
            x, v = np.linalg.solve(matrix, rhs)
            q.append(x)
            p.append(v)
    else:  # Newmark (beta 1/4, gamma 1/2) is generalized-alpha with am = af = 0
        am, af, gamma, beta = alpha_parameters(rho) if scheme == "alpha" else (0.0, 0.0, 0.5, 0.25)
        a = -c * p0 - w * w * q0
        for _ in range(steps):
            x0, v0 = q[-1], p[-1]
            # x1 = xp + beta dt^2 a1, v1 = vp + gamma dt a1
            xp = x0 + dt * v0 + dt * dt * (0.5 - beta) * a
            vp = v0 + dt * (1 - gamma) * a
            # (1-am) a1 + am a + c ((1-af) v1 + af v0) + w^2 ((1-af) x1 + af x0) = 0
            lhs = (1 - am) + c * (1 - af) * gamma * dt + w * w * (1 - af) * beta * dt * dt
            rhs = -(am * a + c * ((1 - af) * vp + af * v0) + w * w * ((1 - af) * xp + af * x0))
            a1 = rhs / lhs
            q.append(xp + beta * dt * dt * a1)
            p.append(vp + gamma * dt * a1)
            a = a1
    return np.array(q), np.array(p)


def exact(w, c, t, p0):
    """q, p of q'' + c q' + w^2 q = 0, q(0) = 0, q'(0) = p0 (underdamped)."""
    zeta_w = 0.5 * c
    wd = math.sqrt(w * w - zeta_w * zeta_w)
    decay = math.exp(-zeta_w * t)
    q = p0 / wd * decay * math.sin(wd * t)
    p = p0 * decay * (math.cos(wd * t) - zeta_w / wd * math.sin(wd * t))
    return q, p


def recurrence_radius(q):
    """Spectral radius of the order-3 linear recurrence fitted to q (least squares)."""
    rows = np.array([q[n:n + 3][::-1] for n in range(len(q) - 3)])
    coefficients = np.linalg.lstsq(rows, q[3:], rcond=None)[0]
    return max(abs(np.roots(np.concatenate(([1.0], -coefficients)))))


# ----------------------------------------------------------------------------- runs
class Bar:
    def __init__(self, args):
        self.args = args
        mesh = harness.box_mesh(args, "bar.mesh", (LENGTH, WIDTH, WIDTH), (CELLS, ACROSS, ACROSS))
        vertices = harness.read_medit(mesh)[0]
        x = vertices[:, 0] - vertices[:, 0].min()
        velocities = [(0, k, (V0 * math.cos(math.pi * x[k] / LENGTH), 0.0, 0.0)) for k in range(len(x))]
        self.scene = harness.write_scene(os.path.join(args.work, "bar.txt"),
                                         [("bar.mesh", DENSITY, YOUNG, 0.0, 0, (0, 0, 0), (1, 0, 0, 0))],
                                         velocities)
        matrices = os.path.join(args.work, "matrices")
        out = harness.fresh_result(args.work, "setup")
        harness.run(args, RANKS, ["-scene", self.scene, "-steps", 0, "-output", out, "-export_matrices", matrices])
        r = harness.read_frames(out)
        self.rest = r["mesh/rest_positions"].ravel()
        v0 = r["velocities"][0].ravel()
        self.mode_mass, self.w = self.mode(matrices, v0)
        self.period = 2 * math.pi / self.w
        self.p0 = float(self.mode_mass @ v0)

    @staticmethod
    def mode(matrices, v0):
        """(M phi, w) of the mode with the largest share of M-weighted v0."""
        m_rows, m_cols, m_values, shape = harness.read_petsc_aij(os.path.join(matrices, "M.bin"))
        k_rows, k_cols, k_values, _ = harness.read_petsc_aij(os.path.join(matrices, "K.bin"))
        n = shape[0]
        mass = np.bincount(m_rows, weights=np.where(m_rows == m_cols, m_values, 0.0), minlength=n)
        stiffness = np.zeros((n, n))
        np.add.at(stiffness, (k_rows, k_cols), k_values)
        scale = 1.0 / np.sqrt(mass)
        values, vectors = np.linalg.eigh(stiffness * scale[:, None] * scale[None, :])
        j = int(np.argmax(np.abs(vectors.T @ (np.sqrt(mass) * v0))))
        return np.sqrt(mass) * vectors[:, j], math.sqrt(values[j])

    def run(self, name, scheme, dt, steps, extra=()):
        """(q_n, p_n, total energy_n) of a run, every step a frame."""
        out = harness.fresh_result(self.args.work, name)
        harness.run(self.args, RANKS, ["-scene", self.scene, "-output", out, "-integrator", scheme,
                                       "-dt", repr(dt), "-steps", steps, "-shear_scale", 1, *extra])
        r = harness.read_frames(out)
        frames = len(r["time"])
        q = (r["positions"].reshape(frames, -1) - self.rest[None]) @ self.mode_mass
        p = r["velocities"].reshape(frames, -1) @ self.mode_mass
        return q, p, r["energy/kinetic"] + r["energy/elastic"]


def corotational_orders(args, checks):
    """(e): the orders of every scheme in corotational mode on the struck beam."""
    cells = (10, 2, 2)
    mesh = harness.box_mesh(args, "beam.mesh", (2.0, 0.4, 0.4), cells)
    velocities = []
    for k in range(cells[2] + 1):
        for j in range(cells[1] + 1):
            for i in range(cells[0] + 1):
                index = i + (cells[0] + 1) * (j + (cells[1] + 1) * k)
                velocities.append((0, index, (0.0, 0.0, 2.0 * math.cos(2 * math.pi * i / cells[0]))))
    scene = harness.write_scene(os.path.join(args.work, "beam.txt"),
                                [(os.path.basename(mesh), 1000.0, 2.5e4, 0.45, 0, (0, 0, 0), (1, 0, 0, 0))],
                                velocities)

    def final(name, scheme, steps):
        out = harness.fresh_result(args.work, name)
        harness.run(args, 1, ["-scene", scene, "-output", out, "-mode", "corotational", "-alpha", 0, "-beta", 0,
                              "-newton_rtol", 1e-10, "-newton_max_it", 500, "-integrator", scheme,
                              "-dt", repr(0.2 / steps), "-steps", steps, "-output_every", steps])
        r = harness.read_frames(out)
        return r["positions"][-1], r["mesh/rest_positions"]

    reference, rest = final("beam_reference", "bdf2", 640)
    scale = np.linalg.norm(reference - rest)
    for scheme in SCHEMES:
        errors = [np.linalg.norm(final(f"beam_{scheme}_{n}", scheme, n)[0] - reference) / scale
                  for n in (10, 20, 40, 80)]
        slope = np.polyfit(np.log([0.2 / n for n in (10, 20, 40, 80)]), np.log(errors), 1)[0]
        expected = 1.0 if scheme == "be" else 2.0
        checks.check(abs(slope - expected) <= 0.3,
                     f"(e) corotational {scheme}, struck beam (largest displacement "
                     f"{np.abs(reference - rest).max():.2f} m): error at T for dt = 0.02 .. 0.0025 s: "
                     + ", ".join(f"{e:.3e}" for e in errors) + f"; order {slope:.3f} ({expected:g} +- 0.3)")


def bad_values(args, checks, scene):
    """(f): one error line naming the option, non-zero exit, no run summary."""
    for option, value, keys in (("-integrator", "foo", ["not one of", "foo"]),
                                ("-alpha_rho_inf", "2", ["[0, 1]"]),
                                ("-alpha_rho_inf", "-0.1", ["[0, 1]"]),
                                ("-alpha_rho_inf", "abc", ["not a number", "abc"]),
                                ("-tol", "0", ["(0, 1)"])):
        r = harness.run(args, RANKS, ["-scene", scene, "-steps", 1, option, value], check=False, timeout=120)
        errors = [line for line in r.stderr.splitlines() if line.startswith("softbody: error:")]
        ok = (r.returncode != 0 and len(errors) == 1 and f"option {option}" in errors[0]
              and any(k in errors[0] for k in keys) and "run summary" not in r.stdout)
        checks.check(ok, f"(f) {option} {value}: exit {r.returncode}, "
                         f"'{errors[0] if errors else r.stderr.strip()[:200]}'")


def adaptive(bar, checks):
    """(g): -dt_adapt's error against -tol, its rejections and its frames."""
    import h5py
    w, T, p0 = bar.w, bar.period, bar.p0
    amplitude = abs(p0) / w
    q_exact, p_exact = exact(w, 0.0, 2 * T, p0)
    for scheme in ("bdf2", "newmark"):
        errors, rows = [], []
        for tol in (1e-2, 1e-3, 1e-4, 1e-5):
            name = f"adapt_{scheme}_{tol:g}"
            out = harness.fresh_result(bar.args.work, name)
            r = harness.run(bar.args, RANKS, ["-scene", bar.scene, "-output", out, "-integrator", scheme,
                                              "-dt", repr(T / 2), "-steps", 4, "-shear_scale", 1, "-alpha", 0,
                                              "-beta", 0, "-dt_adapt", "-tol", tol])
            frames = harness.read_frames(out)
            q = float((frames["positions"][-1].ravel() - bar.rest) @ bar.mode_mass)
            p = float(frames["velocities"][-1].ravel() @ bar.mode_mass)
            errors.append(math.hypot(q - q_exact, (p - p_exact) / w) / amplitude)
            with h5py.File(out, "r") as f:
                attributes = {k: float(f.attrs[k]) for k in ("accepted_steps", "rejected_steps", "min_dt", "max_dt")}
            times_ok = np.abs(frames["time"] - T / 2 * np.arange(5)).max() < 1e-12 * T
            summary_ok = "-dt_adapt" in r.stdout and "rejected" in r.stdout
            rows.append((tol, attributes, times_ok and summary_ok))
        falling = all(b < a for a, b in zip(errors, errors[1:]))
        checks.check(falling, f"(g) {scheme} -dt_adapt: error at 2T for -tol 1e-2 .. 1e-5: "
                              + ", ".join(f"{e:.2e}" for e in errors) + " (falls monotonically)")
        checks.check(all(row[1]["rejected_steps"] >= 1 and row[2] for row in rows),
                     f"(g) {scheme} -dt_adapt: accepted / rejected substeps per -tol: "
                     + ", ".join(f"{row[0]:g}: {row[1]['accepted_steps']:.0f}/{row[1]['rejected_steps']:.0f} "
                                 f"(dt {row[1]['min_dt']:.2e} .. {row[1]['max_dt']:.2e} s)" for row in rows)
                     + "; frames at k T/2, summary line")


def damped_strike(bar, checks):
    """(h), (i): -dt_adapt's error at the end against -tol with damping and an impulsive start."""
    import h5py
    import scipy.linalg
    args, T, a, b = bar.args, bar.period, 0.5, 2e-3
    mesh = harness.box_mesh(args, "bar.mesh", (LENGTH, WIDTH, WIDTH), (CELLS, ACROSS, ACROSS))
    vertices = harness.read_medit(mesh)[0]
    struck = [k for k in range(len(vertices)) if vertices[k, 0] >= vertices[:, 0].max() - 1e-12]
    scene = harness.write_scene(os.path.join(args.work, "struck.txt"),
                                [("bar.mesh", DENSITY, YOUNG, 0.0, 0, (0, 0, 0), (1, 0, 0, 0))],
                                [(0, k, (1.0, 0.0, 0.0)) for k in struck])
    matrices = os.path.join(args.work, "matrices_struck")
    out = harness.fresh_result(args.work, "struck_setup")
    harness.run(args, RANKS, ["-scene", scene, "-steps", 0, "-output", out, "-export_matrices", matrices,
                              "-shear_scale", 1])
    r = harness.read_frames(out)
    rest, v0 = r["mesh/rest_positions"].ravel(), r["velocities"][0].ravel()
    m_rows, m_cols, m_values, shape = harness.read_petsc_aij(os.path.join(matrices, "M.bin"))
    k_rows, k_cols, k_values, _ = harness.read_petsc_aij(os.path.join(matrices, "K.bin"))
    n, end = shape[0], 2.5 * T
    mass = np.bincount(m_rows, weights=np.where(m_rows == m_cols, m_values, 0.0), minlength=n)
    stiffness = np.zeros((n, n))
    np.add.at(stiffness, (k_rows, k_cols), k_values)
    # First-order form y = (x - X, v): y' = [[0, I], [-M^-1 K, -a I - b M^-1 K]] y.
    mk = stiffness / mass[:, None]
    system = np.block([[np.zeros((n, n)), np.eye(n)], [-mk, -a * np.eye(n) - b * mk]])
    exact = (scipy.linalg.expm(end * system) @ np.concatenate([np.zeros(n), v0]))[:n]
    for scheme in ("bdf2", "newmark"):
        errors = []
        for tol in (1e-2, 1e-3, 1e-4):
            out = harness.fresh_result(args.work, f"struck_{scheme}_{tol:g}")
            harness.run(args, RANKS, ["-scene", scene, "-output", out, "-integrator", scheme, "-dt", repr(T / 2),
                                      "-steps", 5, "-shear_scale", 1, "-alpha", a, "-beta", b, "-dt_adapt",
                                      "-tol", tol])
            x = harness.read_frames(out)["positions"][-1].ravel()
            errors.append((tol, float(np.linalg.norm(x - rest - exact) / np.linalg.norm(exact))))
            if tol == 1e-3:  # (i) the same run keeping one factorisation only
                single = harness.fresh_result(args.work, f"struck_{scheme}_single")
                harness.run(args, RANKS, ["-scene", scene, "-output", single, "-integrator", scheme, "-dt",
                                          repr(T / 2), "-steps", 5, "-shear_scale", 1, "-alpha", a, "-beta", b,
                                          "-dt_adapt", "-tol", tol, "-dt_adapt_factors", 1])
                cached, uncached = harness.read_frames(out), harness.read_frames(single)
                with h5py.File(out, "r") as f, h5py.File(single, "r") as g:
                    fills = (int(f.attrs["system_fills"]), int(g.attrs["system_fills"]))
                same = all(np.array_equal(cached[k], uncached[k]) for k in ("positions", "velocities"))
                checks.check(same and fills[0] < fills[1],
                             f"(i) {scheme} -dt_adapt -tol 1e-3, damped strike: {fills[0]} fills of A with the "
                             f"default -dt_adapt_factors, {fills[1]} with 1 (fewer), results bit for bit equal")
        falling = all(e2 < e1 for (_, e1), (_, e2) in zip(errors, errors[1:]))
        calibrated = all(tol / 30 <= e <= 3 * tol for tol, e in errors)
        checks.check(falling and calibrated, f"(h) {scheme} -dt_adapt, damped strike: error at 5T/2 per -tol "
                     + ", ".join(f"{tol:g}: {e:.2e}" for tol, e in errors)
                     + " (falls monotonically, within [tol / 30, 3 tol])")


def main():
    args = harness.arguments()
    checks = harness.Checks()
    started = time.time()
    bar = Bar(args)
    w, T, p0 = bar.w, bar.period, bar.p0
    amplitude = abs(p0) / w
    print(f"mode: w = {w:.6f} rad/s (f = {w / 2 / math.pi:.6f} Hz), T = {T:.6e} s, p0 = {p0:.6e}")

    # (a) every step against the scheme's textbook recurrence, with damping
    a_damping, b_damping = 0.5, 2e-4
    c = a_damping + b_damping * w * w
    damping = ["-alpha", a_damping, "-beta", b_damping]
    for mode, tolerance in (("linear", 1e-9), ("corotational", 1e-4)):
        for scheme in SCHEMES:
            extra = damping + ["-mode", mode] + (["-newton_rtol", 1e-10] if mode == "corotational" else [])
            q, p, _ = bar.run(f"recurrence_{mode}_{scheme}", scheme, T / 20, 40, extra)
            q_ref, p_ref = reference(scheme, w, c, T / 20, 40, 0.0, p0,
                                     start="theta" if mode == "linear" else "be")
            deviation = max(np.abs(q - q_ref).max(), np.abs(p - p_ref).max() / w) / amplitude
            checks.check(deviation < tolerance, f"(a) {mode} {scheme}: q_n, p_n follow the textbook recurrence "
                                                f"(a = {a_damping}, b = {b_damping}, dt = T/20, 40 steps): "
                                                f"deviation {deviation:.2e} of the amplitude (< {tolerance:g})")

    # (b) orders in dt, no damping
    divisions = (40, 80, 160, 320)
    for scheme in SCHEMES:
        errors = []
        for division in divisions:
            q, p, _ = bar.run(f"order_{scheme}_{division}", scheme, T / division, division,
                              ["-alpha", 0, "-beta", 0, "-output_every", division])
            q_exact, p_exact = exact(w, 0.0, T, p0)
            errors.append(math.hypot(q[-1] - q_exact, (p[-1] - p_exact) / w) / amplitude)
        slope = np.polyfit(np.log([T / d for d in divisions]), np.log(errors), 1)[0]
        expected = 1.0 if scheme == "be" else 2.0
        checks.check(abs(slope - expected) <= 0.3,
                     f"(b) {scheme}: error at T for dt = T/40 .. T/320: "
                     + ", ".join(f"{e:.3e}" for e in errors) + f"; order {slope:.3f} ({expected:g} +- 0.3)")

    # (c) newmark conserves energy; its frequency at T/20
    q, p, energy = bar.run("energy_newmark", "newmark", T / 20, 1000, ["-alpha", 0, "-beta", 0])
    drift = np.abs(energy - energy[0]).max() / energy[0]
    checks.check(drift < 1e-10, f"(c) newmark, no damping, 1000 steps of T/20: total energy constant to "
                                f"{drift:.2e} relative (< 1e-10)")
    # the angle per step: q_{n+1} + q_{n-1} = 2 cos(theta) q_n (modulus 1), fitted
    for division in (20, 26):
        q, _, _ = bar.run(f"frequency_newmark_{division}", "newmark", T / division, 2 * division,
                          ["-alpha", 0, "-beta", 0])
        theta = math.acos(np.dot(q[2:] + q[:-2], q[1:-1]) / (2 * np.dot(q[1:-1], q[1:-1])))
        error = theta / (w * T / division) - 1
        trapezoidal = 2 * math.atan(0.5 * w * T / division) / (w * T / division) - 1
        limit = 5e-3 if division == 26 else 1e-2
        checks.check(abs(error - trapezoidal) < 1e-8 and abs(error) < limit,
                     f"(c) newmark at dt = T/{division}: frequency {error:+.4e} relative to the semi-discrete "
                     f"one (the trapezoidal rule's 2 atan(w dt / 2) / (w dt) - 1 = {trapezoidal:+.4e}; "
                     f"|error| < {100 * limit:g} %)")
    q_be, p_be, energy_be = bar.run("energy_be", "be", T / 20, 20, ["-alpha", 0, "-beta", 0])
    print(f"backward Euler at dt = T/20, no damping: energy after one period {energy_be[-1] / energy_be[0]:.4f} "
          f"of the start, amplitude {math.sqrt(energy_be[-1] / energy_be[0]):.4f}; newmark "
          f"{energy[20] / energy[0]:.12f}")

    # (d) alpha's dissipation at w dt = 628
    for rho in (0.5, 0.9):
        dt = 1600 * T
        q, _, _ = bar.run(f"rho_inf_{rho}", "alpha", dt, 40, ["-alpha", 0, "-beta", 0, "-alpha_rho_inf", rho])
        measured = recurrence_radius(q[1:30])
        q_ref, _ = reference("alpha", w, 0.0, dt, 40, 0.0, p0, rho)
        expected = recurrence_radius(q_ref[1:30])
        checks.check(abs(measured / rho - 1) < 0.01 and abs(measured / expected - 1) < 1e-3,
                     f"(d) alpha, -alpha_rho_inf {rho}, w dt = {w * dt:.0f}: spectral radius of the "
                     f"step {measured:.5f} (rho_inf {rho} to 1 %, textbook recurrence {expected:.5f} to 1e-3)")

    corotational_orders(args, checks)
    bad_values(args, checks, bar.scene)
    adaptive(bar, checks)
    damped_strike(bar, checks)
    print(f"{time.time() - started:.1f} s")
    checks.exit()


if __name__ == "__main__":
    main()
