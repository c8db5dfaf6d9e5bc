#!/usr/bin/python3
"""Stability matrix of softbody: stiff, extreme and degenerate cases in both modes.

Runs a FIXED matrix of short simulations (tens of steps on meshes of at most a
few hundred tets, generated into the work folder), in linear and corotational
mode, each with its default solver preset (CHOLMOD Cholesky for linear, CG + warp
for corotational), and gives every case a verdict:

  group      what varies (everything else at the baseline)
  E          Young's modulus 1e2 .. 1e12 Pa, every decade
  nu         Poisson ratio 0.45, 0.49, 0.499, 0.4999
  dt         time step 1e-4 .. 1 s, every decade
  speed      initial speed 1, 1e2, 1e4 body sizes per second; three patterns:
             strike (opposite ends pushed apart across the body: deforms),
             spin (omega x r: rigid rotation), translate (uniform: rigid)
  sliver     aspect ratio ~1e3: a sliver tet (four nearly coplanar vertices),
             a cap tet (one vertex 1e-3 above the opposite face), a plate meshed
             with 1 x 1 x 1e-3 cells, a needle box meshed with 1 x 1e-3 x 1e-3 cells
  inverted   -deform 0:0:1,1,-1: the body mirrored (every tet inverted) at t = 0
  damping    -alpha 0 -beta 0 and -alpha 100 -beta 10, on a strike and a spin
  fixed      every mesh fixed (no unknowns)
  tet        a single free tet
  extreme    combinations: stiff + incompressible + large step, soft + fast, ...
  reject     impossible parameters (nu = 0.5, 0.6, -1, -1.5; E = 0, -1e6;
             dt = 0, -0.01): EXPECTED REJECTIONS

Baseline: a 1 m cube of 3 x 3 x 3 cells (162 tets), density 1000 kg/m^3,
E = 1e6 Pa, nu = 0.3, dt = 0.01 s, 20 steps, the default damping (a = b = 0.1),
struck at 1 body size per second.

Criteria of a case that must run (all must hold):
  run        exit status 0, result file complete, all steps done, one
             converged solve per step (a solve that does not converge stops the
             run with "did not converge (REASON ...)": that reason is reported)
  finite     no NaN or Inf in positions, velocities or energies
  energy     growth = max over steps of E(n+1) - E(n), relative to
             max(E(0), max E), is at most 1e-6 (E = kinetic + elastic +
             gravitational). Backward Euler satisfies exactly
             E(n+1) - E(n) = v1 . r - (|v1 - v0|_M^2 + dt^2 |v1|_K^2)/2 - dt |v1|_D^2
             with r the residual of the linear solve (linear mode; corotational
             mode with the rotations of the step), so a consistent implicit step
             can raise E only by solver error: 1e-6 is 100 x the CG tolerance
             (rtol 1e-8) and far above the round-off of the healthy cases (1e-8).
  bounded    no vertex ever holds more kinetic energy than the whole body had at
             t = 0: m_i |v_i(t)|^2 / 2 <= (1 + 1e-6) E(0) for every vertex and frame
             (recomputed from the positions, velocities and lumped masses, not
             from the reported energies), and no vertex moves faster than that
             allows: |x_i(t) - x_i(0)| <= t sqrt(2 E(0) / m_i) (1 + 1e-6).
             A fixed bound on displacement / body size would be ill-posed: a
             body translating at 1e4 sizes per second legitimately travels
             2000 sizes in 0.2 s, and linear elasticity legitimately grows a
             spinning body (rotations are not strain-free in that model).
  fixed      (no unknowns) positions never change, velocities and energies stay 0
An expected rejection passes when the program exits non-zero with exactly one
line "softbody: error: ..." naming the parameter, and no PETSc traceback.

Writes STUDY_DIR/stability.md and STUDY_DIR/stability.csv (one row per case,
with the command that reproduces it); meshes, scenes and (with -stability_keep) result
files go to STUDY_DIR/work. Exit status 0 when every case passes, 1 otherwise.

  ./run stability                      # the whole matrix, both modes (a few minutes)
  ./run stability -stability_quick     # the representative fast subset (~40 s)
  /usr/bin/python3 tools/stability.py -softbody build/softbody -stability_modes corotational -stability_only 'nu='
"""
import argparse
import csv
import math
import os
import re
import shlex
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import box_mesh  # noqa: E402
from softbody_tools import ToolParser, add_option, error_lines, lumped_masses, mpi_environment, read_medit  # noqa: E402

MODES = ("linear", "corotational")
PRESET = {"linear": "CHOLMOD Cholesky (config/direct.opts)", "corotational": "CG + warp (config/cg-warp.opts)"}
ENERGY_TOLERANCE = 1e-6
DENSITY = 1000.0
BASE = dict(young=1e6, poisson=0.3, dt=0.01, alpha=None, beta=None)  # None: the program's default
SLIVER_HEIGHT = 1e-3


# ----------------------------------------------------------------------------- meshes

def write_tet_mesh(path, vertices, tets):
    vertices = np.asarray(vertices, float)
    tets = np.asarray(tets, np.int64)
    # Positive orientation, as every reader expects of a well-formed mesh.
    for t in tets:
        a, b, c, d = vertices[t]
        if np.dot(np.cross(b - a, c - a), d - a) < 0:
            t[1], t[2] = t[2], t[1]
    faces = box_mesh.boundary_faces(tets, len(vertices))
    box_mesh.write_medit(path, vertices, tets, faces, np.zeros(len(faces), np.int64))


def write_box(path, size, cells):
    vertices, tets = box_mesh.box_mesh(size, cells)
    faces = box_mesh.boundary_faces(tets, len(vertices))
    box_mesh.write_medit(path, vertices, tets, faces, box_mesh.side_of_faces(vertices, faces, size))


def aspect_ratio(vertices, tets):
    """Largest over the tets of longest edge / shortest altitude."""
    worst = 0.0
    for t in tets:
        p = vertices[t]
        volume = abs(np.linalg.det(p[1:] - p[0])) / 6.0
        edges = max(np.linalg.norm(p[a] - p[b]) for a in range(4) for b in range(a + 1, 4))
        altitudes = []
        for k in range(4):
            f = np.delete(p, k, axis=0)
            area = 0.5 * np.linalg.norm(np.cross(f[1] - f[0], f[2] - f[0]))
            altitudes.append(3.0 * volume / area)
        worst = max(worst, edges / min(altitudes))
    return worst


MESHES = {
    # name: (description, writer(path))
    "cube": ("1 m cube, 3 x 3 x 3 cells, 162 tets",
             lambda p: write_box(p, (1.0, 1.0, 1.0), (3, 3, 3))),
    "tet": ("unit right tet",
            lambda p: write_tet_mesh(p, [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)], [[0, 1, 2, 3]])),
    "sliver": ("sliver tet: four nearly coplanar vertices, height 1e-3",
               lambda p: write_tet_mesh(p, [(0, 0, 0), (1, 1, 0), (1, 0, SLIVER_HEIGHT),
                                            (0, 1, SLIVER_HEIGHT)], [[0, 1, 2, 3]])),
    "cap": ("cap tet: one vertex 1e-3 above the opposite face",
            lambda p: write_tet_mesh(p, [(0, 0, 0), (1, 0, 0), (0.5, math.sqrt(3) / 2, 0),
                                         (0.5, math.sqrt(3) / 6, SLIVER_HEIGHT)], [[0, 1, 2, 3]])),
    "plate": ("2 x 2 x 0.001 m plate, 2 x 2 x 1 cells, 24 flat tets",
              lambda p: write_box(p, (2.0, 2.0, SLIVER_HEIGHT), (2, 2, 1))),
    "needle": ("2 x 0.001 x 0.001 m needle, 2 x 1 x 1 cells, 12 needle tets",
               lambda p: write_box(p, (2.0, SLIVER_HEIGHT, SLIVER_HEIGHT), (2, 1, 1))),
}


# ----------------------------------------------------------------------------- cases

class Case:
    """One scene + options, run in each mode. kind: 'run' or 'reject'."""

    def __init__(self, key, group, description, mesh="cube", young=None, poisson=None,
                 pattern="strike", speed=1.0, dt=None, alpha=None, beta=None, deform=None,
                 fixed=False, quick=False, reject=None):
        self.key, self.group, self.description = key, group, description
        self.mesh = mesh
        self.young = BASE["young"] if young is None else young
        self.poisson = BASE["poisson"] if poisson is None else poisson
        self.pattern, self.speed = pattern, speed
        self.dt = BASE["dt"] if dt is None else dt
        self.alpha, self.beta = alpha, beta
        self.deform, self.fixed = deform, fixed
        self.quick = quick
        self.reject = reject  # None, or a regular expression the error line must match

    def options(self, steps):
        o = ["-steps", str(steps), "-dt", repr(self.dt)]
        if self.alpha is not None:
            o += ["-alpha", repr(self.alpha)]
        if self.beta is not None:
            o += ["-beta", repr(self.beta)]
        if self.deform:
            o += ["-deform", self.deform]
        return o


def matrix():
    cases = []
    add = cases.append
    for k in range(2, 13):
        add(Case(f"E=1e{k}", "E", f"E = 1e{k} Pa", young=10.0 ** k, quick=k in (2, 12)))
    for nu in (0.45, 0.49, 0.499, 0.4999):
        add(Case(f"nu={nu}", "nu", f"nu = {nu}", poisson=nu, quick=nu == 0.4999))
    for k in range(-4, 1):
        add(Case(f"dt=1e{k}", "dt", f"dt = 1e{k} s", dt=10.0 ** k, quick=k in (-4, 0)))
    for pattern in ("strike", "spin", "translate"):
        for k in (0, 2, 4):
            add(Case(f"{pattern}@1e{k}", "speed", f"{pattern} at 1e{k} body sizes/s", pattern=pattern,
                     speed=10.0 ** k, quick=k == 4 and pattern != "translate"))
    for mesh in ("sliver", "cap", "plate", "needle"):
        add(Case(f"{mesh}", "sliver", MESHES[mesh][0], mesh=mesh, quick=mesh in ("sliver", "plate")))
    add(Case("inverted-tet", "inverted", "single tet mirrored through z at t = 0", mesh="tet",
             deform="0:0:1,1,-1", quick=True))
    add(Case("inverted-cube", "inverted", "cube mirrored through z at t = 0 (162 inverted tets)",
             deform="0:0:1,1,-1"))
    add(Case("inverted-cube@1e2", "inverted", "cube mirrored at t = 0 and struck at 1e2 sizes/s",
             deform="0:0:1,1,-1", speed=1e2))
    add(Case("inverted-sliver", "inverted", "sliver tet mirrored through z at t = 0", mesh="sliver",
             deform="0:0:1,1,-1"))
    for pattern, speed in (("strike", 1.0), ("spin", 1e2)):
        add(Case(f"undamped-{pattern}@{speed:g}", "damping", f"-alpha 0 -beta 0, {pattern} at {speed:g} sizes/s",
                 pattern=pattern, speed=speed, alpha=0.0, beta=0.0, quick=pattern == "strike"))
        add(Case(f"heavy-{pattern}@{speed:g}", "damping", f"-alpha 100 -beta 10, {pattern} at {speed:g} sizes/s",
                 pattern=pattern, speed=speed, alpha=100.0, beta=10.0))
    add(Case("all-fixed", "fixed", "a fixed cube and a fixed tet, nothing free", mesh="cube+tet",
             fixed=True, quick=True))
    add(Case("single-tet", "tet", "one free tet, struck", mesh="tet", quick=True))
    add(Case("single-tet-undamped@1e4", "tet", "one free tet, no damping, struck at 1e4 sizes/s", mesh="tet",
             speed=1e4, alpha=0.0, beta=0.0))
    add(Case("stiff-incompressible-dt1", "extreme", "E = 1e12, nu = 0.4999, dt = 1", young=1e12,
             poisson=0.4999, dt=1.0, quick=True))
    add(Case("stiff-incompressible-dt1e-4", "extreme", "E = 1e12, nu = 0.4999, dt = 1e-4", young=1e12,
             poisson=0.4999, dt=1e-4))
    add(Case("soft-fast-dt1", "extreme", "E = 1e2, strike at 1e4 sizes/s, dt = 1", young=1e2, speed=1e4,
             dt=1.0))
    add(Case("stiff-fast-undamped", "extreme", "E = 1e12, strike at 1e4 sizes/s, no damping", young=1e12,
             speed=1e4, alpha=0.0, beta=0.0))
    add(Case("sliver-stiff-incompressible", "extreme", "sliver tet, E = 1e12, nu = 0.4999", mesh="sliver",
             young=1e12, poisson=0.4999, quick=True))
    rejections = [
        ("reject-nu=0.5", dict(poisson=0.5), r"Poisson ratio must lie in \(-1, 0\.5\)", True),
        ("reject-nu=0.6", dict(poisson=0.6), r"Poisson ratio must lie in \(-1, 0\.5\)", False),
        ("reject-nu=-1", dict(poisson=-1.0), r"Poisson ratio must lie in \(-1, 0\.5\)", True),
        ("reject-nu=-1.5", dict(poisson=-1.5), r"Poisson ratio must lie in \(-1, 0\.5\)", False),
        ("reject-E=0", dict(young=0.0), r"Young's modulus must be > 0", True),
        ("reject-E=-1e6", dict(young=-1e6), r"Young's modulus must be > 0", False),
        ("reject-dt=0", dict(dt=0.0), r"option -dt: must be > 0", True),
        ("reject-dt=-0.01", dict(dt=-0.01), r"option -dt: must be > 0", False),
    ]
    for key, change, pattern, quick in rejections:
        what = ", ".join(f"{'E' if k == 'young' else 'nu' if k == 'poisson' else k} = {v:g}" for k, v in change.items())
        add(Case(key, "reject", f"{what}: expected rejection", reject=pattern, quick=quick, **change))
    return cases


# ----------------------------------------------------------------------------- scenes

def body_size(vertices):
    return float((vertices.max(axis=0) - vertices.min(axis=0)).max())


def volume_centroid(vertices, tets):
    p = vertices[tets]
    volumes = np.abs(np.linalg.det(p[:, 1:] - p[:, :1])) / 6.0
    return (volumes[:, None] * p.mean(axis=1)).sum(axis=0) / volumes.sum()


def initial_velocities(vertices, tets, pattern, speed_factor):
    """Per-vertex velocities (m/s) whose largest magnitude is speed_factor x body size / s."""
    size = body_size(vertices)
    speed = speed_factor * size
    extent = vertices.max(axis=0) - vertices.min(axis=0)
    long_axis, thin_axis = int(np.argmax(extent)), int(np.argmin(extent))
    if thin_axis == long_axis:
        thin_axis = (long_axis + 2) % 3
    v = np.zeros_like(vertices)
    if pattern == "strike":  # the two ends across the long axis pushed apart along the thin axis
        lo, hi = vertices[:, long_axis].min(), vertices[:, long_axis].max()
        tol = 1e-9 * size
        v[vertices[:, long_axis] >= hi - tol, thin_axis] = speed
        v[vertices[:, long_axis] <= lo + tol, thin_axis] = -speed
    elif pattern == "spin":  # rigid rotation about the thin axis through the centroid
        r = vertices - volume_centroid(vertices, tets)
        axis = np.zeros(3)
        axis[thin_axis] = 1.0
        v = np.cross(axis, r)
        v *= speed / np.linalg.norm(v, axis=1).max()
    elif pattern == "translate":
        v[:, long_axis] = speed
    else:
        raise ValueError(pattern)
    return v


class Prepared:
    """Scene file and what the checks need to know about it."""

    def __init__(self, scene, bodies, densities, size, note):
        self.scene, self.bodies, self.densities, self.size, self.note = scene, bodies, densities, size, note


def prepare(case, work, mesh_cache):
    meshes = case.mesh.split("+")
    for name in meshes:
        if name not in mesh_cache:
            path = os.path.join(work, name + ".mesh")
            MESHES[name][1](path)
            vertices, _, _, tets = read_medit(path)
            mesh_cache[name] = (vertices, tets)
    scene = os.path.join(work, re.sub(r"[^A-Za-z0-9_.@=+-]", "_", case.key) + ".txt")
    lines = [f"{len(meshes)}"]
    for i, name in enumerate(meshes):
        # Bodies side by side along x, 2 m apart, so that none overlaps another.
        lines.append(f"{name}.mesh {DENSITY!r} {case.young!r} {case.poisson!r} {int(case.fixed)} "
                     f"{2.0 * i!r} 0.0 0.0 1 0 0 0")
    vertices, tets = mesh_cache[meshes[0]]
    size = body_size(vertices)
    if not case.fixed:
        v = initial_velocities(vertices, tets, case.pattern, case.speed)
        moving = np.nonzero(np.linalg.norm(v, axis=1) > 0)[0]
        lines.append(f"{len(moving)}")
        lines += ["0 %d %r %r %r" % (k, *map(float, v[k])) for k in moving]
    with open(scene, "w") as f:
        f.write(f"# stability case {case.key}: {case.description}\n" + "\n".join(lines) + "\n")
    note = ""
    if case.group == "sliver" or "sliver" in case.mesh:
        note = f"aspect ratio {aspect_ratio(vertices, tets):.3g}"
    return Prepared(scene, meshes, [DENSITY] * len(meshes), size, note)


# ----------------------------------------------------------------------------- running and judging

def first_message(stderr):
    """The first stderr line that is not part of mpirun's boxed banners."""
    for line in stderr.splitlines():
        text = line.strip()
        if text and not set(text) <= set("-") and "Primary job" not in text and "mpirun" not in text:
            return text
    return "(no message)"


def judge_rejection(case, result):
    lines = error_lines(result["stderr"])
    problems = []
    if result["timeout"]:
        problems.append("timed out")
    elif result["exit"] == 0:
        problems.append("accepted (exit 0): an impossible parameter was not rejected")
    if len(lines) != 1:
        problems.append(f"{len(lines)} 'softbody: error:' lines (expected exactly 1)")
    elif not re.search(case.reject, lines[0]):
        problems.append(f"message does not name the problem (expected /{case.reject}/)")
    if "PETSC ERROR" in result["stderr"] or "Traceback" in result["stderr"]:
        problems.append("PETSc traceback on stderr")
    if os.path.exists(result["output"]):
        problems.append("an output file was left behind")
    return problems


def judge_run(case, mode, prepared, steps, result, metrics):
    """Fills metrics; returns the list of failed criteria (empty: pass)."""
    import h5py
    problems = []
    stderr = result["stderr"]
    lines = error_lines(stderr)
    if result["timeout"]:
        return [f"timed out after {result['seconds']:.0f} s"]
    if result["exit"] != 0:
        match = re.search(r"did not converge \((\w+)", stderr)
        if match:
            step = re.search(r"step (\d+):", stderr)
            problems.append(f"solver: {match.group(1)} at step {step.group(1) if step else '?'}")
        signal = f" (signal {result['exit'] - 128})" if result["exit"] > 128 else ""
        problems.append(f"exit {result['exit']}{signal}: " + (lines[0] if lines else first_message(stderr)))
        metrics["error"] = lines[0] if lines else ""
    if not os.path.exists(result["output"]):
        problems.append("no result file")
        return problems
    with h5py.File(result["output"], "r") as f:
        attrs = dict(f.attrs)
        P = f["positions"][()]
        V = f["velocities"][()]
        t = f["time"][()]
        energy = {k: f["energy/" + k][()] for k in ("kinetic", "elastic", "gravitational") if "energy/" + k in f}
        tets, rest, vertex_body = f["mesh/tets"][()], f["mesh/rest_positions"][()], f["mesh/vertex_body"][()]
        body_fixed = f["mesh/body_fixed"][()] if "mesh/body_fixed" in f else np.zeros(vertex_body.max() + 1, int)
    done = int(attrs.get("steps", -1))
    metrics["steps"] = done
    metrics["solves"] = int(attrs.get("solves", 0))
    metrics["iterations"] = int(attrs.get("solver_iterations", 0))
    all_fixed = bool(len(body_fixed) and np.all(body_fixed != 0))
    if result["exit"] == 0:
        if int(attrs.get("complete", 0)) != 1:
            problems.append("result file not marked complete")
        if done != steps or len(P) != steps + 1:
            problems.append(f"{done} of {steps} steps, {len(P)} frames")
        # Linear mode: one solve per step. Corotational mode: a step that would
        # gain energy iterates (the program stops with an error if it does not converge).
        if not all_fixed and (metrics["solves"] < steps or (mode == "linear" and metrics["solves"] != steps)):
            problems.append(f"{metrics['solves']} solves for {steps} steps")
    E = sum(energy.values())
    finite = bool(np.isfinite(P).all() and np.isfinite(V).all() and np.isfinite(E).all())
    metrics["finite"] = finite
    if not finite:
        bad = [name for name, a in (("positions", P), ("velocities", V), ("energy", E)) if not np.isfinite(a).all()]
        first = min(int(np.argmax(~np.isfinite(a).reshape(len(a), -1).all(axis=1))) for a in (P, V, E.reshape(-1, 1))
                    if not np.isfinite(a).all())
        problems.append(f"NaN/Inf in {', '.join(bad)} from frame {first}")
    Ef = np.where(np.isfinite(E), E, np.inf)
    metrics["E0"] = float(E[0]) if len(E) else float("nan")
    metrics["Emax"] = float(np.nanmax(E)) if len(E) else float("nan")
    metrics["Efinal"] = float(E[-1]) if len(E) else float("nan")
    size = prepared.size
    metrics["max_displacement"] = float(np.nanmax(np.linalg.norm(P - rest, axis=2)) / size)
    metrics["max_speed"] = float(np.nanmax(np.linalg.norm(V, axis=2)) / size)
    if all_fixed:  # no unknowns
        moved = float(np.abs(P - P[0]).max())
        if moved != 0 or np.abs(V).max() != 0 or np.abs(E).max() != 0:
            problems.append(f"fixed scene changed: moved {moved:.3g} m, max |v| {np.abs(V).max():.3g}, "
                            f"max E {np.abs(E).max():.3g}")
        metrics["growth"] = 0.0
        return problems
    scale = max(abs(E[0]), float(np.max(np.abs(Ef[np.isfinite(Ef)]))) if np.isfinite(Ef).any() else 0.0)
    growth = float(np.max(np.diff(Ef))) / scale if len(E) > 1 and scale > 0 else 0.0
    if not np.isfinite(growth):
        growth = float("inf")
    metrics["growth"] = growth
    if growth > ENERGY_TOLERANCE:
        n = int(np.argmax(np.diff(Ef)))
        problems.append(f"energy growth {growth:.3g} of max(E(0), peak) (step {n + 1}: "
                        f"{E[n]:.4g} -> {E[n + 1]:.4g} J; peak {metrics['Emax'] / E[0] if E[0] > 0 else float('inf'):.3g} x E(0))")
    # Bounded: per-vertex kinetic energy <= E(0); distance travelled <= t x that speed.
    masses = lumped_masses(tets, rest, vertex_body, prepared.densities)
    free = (masses > 0) & (body_fixed[vertex_body] == 0)
    E0 = float(E[0])
    if E0 > 0 and free.any():
        with np.errstate(invalid="ignore", over="ignore"):
            vertex_ke = 0.5 * masses[None, :] * (V ** 2).sum(axis=2)
            ratio = float(np.nanmax(vertex_ke[:, free]) / E0) if finite else float("inf")
            cap = np.sqrt(2.0 * E0 / masses[free])  # m/s, per vertex
            travelled = np.linalg.norm(P[:, free] - P[0][None, free], axis=2)
            allowed = t[:, None] * cap[None, :] * (1 + ENERGY_TOLERANCE) + 1e-12 * size
            over = float(np.nanmax(travelled / allowed)) if finite else float("inf")
        metrics["vertex_ke_ratio"] = ratio
        if not ratio <= 1 + ENERGY_TOLERANCE:
            problems.append(f"unbounded: a vertex holds {ratio:.3g} x the initial total energy")
        if not over <= 1.0:
            problems.append(f"unbounded: a vertex travelled {over:.3g} x the distance E(0) allows")
    return problems


def run_case(case, mode, prepared, args, work):
    stem = re.sub(r"[^A-Za-z0-9_.@=+-]", "_", case.key) + "-" + mode
    output = os.path.join(work, stem + ".h5")
    for suffix in (".h5", ".xdmf"):
        if os.path.exists(os.path.join(work, stem + suffix)):
            os.remove(os.path.join(work, stem + suffix))
    command = [args.mpiexec, "-n", str(args.ranks), os.path.abspath(args.softbody), "-scene", prepared.scene,
               "-mode", mode] + case.options(args.steps) + shlex.split(args.options or "") + ["-output", output]
    env = mpi_environment()
    start = time.monotonic()
    try:
        p = subprocess.run(command, capture_output=True, text=True, timeout=args.timeout, env=env)
        exit_code, stderr, timeout = p.returncode, p.stderr, False
    except subprocess.TimeoutExpired as e:
        exit_code, stderr, timeout = None, (e.stderr or b"").decode() if isinstance(e.stderr, bytes) else (e.stderr or ""), True
    seconds = time.monotonic() - start
    result = dict(exit=exit_code, stderr=stderr, timeout=timeout, seconds=seconds, output=output)
    metrics = dict(steps="", solves="", iterations="", growth="", E0="", Emax="", Efinal="",
                   max_displacement="", max_speed="", finite="", error="", vertex_ke_ratio="")
    if case.reject:
        problems = judge_rejection(case, result)
        lines = error_lines(stderr)
        metrics["error"] = lines[0] if lines else ""
    else:
        problems = judge_run(case, mode, prepared, args.steps, result, metrics)
    if not args.keep:
        for suffix in (".h5", ".xdmf"):
            path = os.path.join(work, stem + suffix)
            if os.path.exists(path):
                os.remove(path)
    shown = ["mpirun" if c == args.mpiexec else c for c in command]
    if not args.keep:
        shown = shown[:-2]  # the output file was temporary
    row = dict(case=case.key, group=case.group, mode=mode, description=case.description + (
        f" ({prepared.note})" if prepared.note else ""), expected="rejection" if case.reject else "run",
        verdict="pass" if not problems else "FAIL", reason="; ".join(problems), exit=exit_code,
        seconds=f"{seconds:.2f}", command=" ".join(shown))
    row.update(metrics)
    return row


# ----------------------------------------------------------------------------- report

COLUMNS = ["case", "group", "mode", "description", "expected", "verdict", "reason", "exit", "steps", "solves",
           "iterations", "growth", "E0", "Emax", "Efinal", "max_displacement", "max_speed", "vertex_ke_ratio",
           "finite", "error", "seconds", "command"]
GROUPS = [("E", "Young's modulus 1e2 .. 1e12 Pa"), ("nu", "Poisson ratio 0.45 .. 0.4999"),
          ("dt", "time step 1e-4 .. 1 s"), ("speed", "strike / spin / translate at 1, 1e2, 1e4 sizes/s"),
          ("sliver", "aspect ratio ~1e3 (sliver, cap, plate, needle)"), ("inverted", "inverted at t = 0"),
          ("damping", "no damping, heavy damping"), ("fixed", "all meshes fixed"), ("tet", "single tet"),
          ("extreme", "combined extremes"), ("reject", "impossible parameters (expected rejections)")]


def fmt(value, spec=".3g"):
    if value == "" or value is None:
        return ""
    if isinstance(value, float):
        return format(value, spec)
    return str(value)


def summary_table(rows, modes):
    lines = ["| group | cases | " + " | ".join(modes) + " |", "|---|---|" + "---|" * len(modes)]
    for group, text in GROUPS:
        cells = []
        count = 0
        for mode in modes:
            r = [row for row in rows if row["group"] == group and row["mode"] == mode]
            count = max(count, len(r))
            passed = sum(row["verdict"] == "pass" for row in r)
            cells.append(f"{passed}/{len(r)} pass" if r else "")
        if count:
            lines.append(f"| {group} | {text} | " + " | ".join(cells) + " |")
    cells = []
    for mode in modes:
        r = [row for row in rows if row["mode"] == mode]
        cells.append(f"**{sum(row['verdict'] == 'pass' for row in r)}/{len(r)} pass**")
    lines.append("| **all** | | " + " | ".join(cells) + " |")
    return lines


def write_reports(rows, args, elapsed):
    os.makedirs(args.study_dir, exist_ok=True)
    csv_path = os.path.join(args.study_dir, "stability.csv")
    with open(csv_path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: fmt(row.get(k, "")) if k not in ("command", "reason", "error", "description")
                             else row.get(k, "") for k in COLUMNS})
    md_path = os.path.join(args.study_dir, "stability.md")
    failed = [row for row in rows if row["verdict"] != "pass"]
    modes = [m for m in MODES if m in args.modes]
    with open(md_path, "w") as f:
        f.write("# softbody stability matrix\n\n")
        f.write(f"{'Quick subset' if args.quick else 'Full matrix'}: {len(rows)} runs "
                f"({len(rows) // max(len(modes), 1)} cases x {len(modes)} modes), {args.steps} steps each, "
                f"{args.ranks} ranks, {elapsed:.0f} s in total. Solvers: "
                + "; ".join(f"{m}: {PRESET[m]}" for m in modes) + ". Written by `tools/stability.py"
                + (" -stability_quick" if args.quick else "") + f"` on {time.strftime('%Y-%m-%d %H:%M')}."
                + (f" Extra options on every run: `{args.options}`." if args.options else "") + "\n\n")
        f.write("\n".join(summary_table(rows, modes)) + "\n\n")
        f.write("Baseline: 1 m cube (162 tets), density 1000 kg/m^3, E = 1e6 Pa, nu = 0.3, dt = 0.01 s, "
                "default damping (a = b = 0.1), struck at 1 body size per second.\n\n")
        f.write("Criteria: **run** (exit 0, complete file, every step solved and converged), **finite** "
                "(no NaN/Inf), **energy** (max step-to-step growth of kinetic + elastic + gravitational "
                f"energy <= {ENERGY_TOLERANCE:g} of max(E(0), peak)), **bounded** (no vertex ever holds more "
                "kinetic energy than the body had at t = 0, nor travels farther than that speed allows). "
                "Expected rejections: non-zero exit with exactly one `softbody: error:` line naming the "
                "parameter.\n\n")
        if failed:
            f.write(f"## Failures ({len(failed)})\n\n")
            for row in failed:
                f.write(f"- **{row['case']}** ({row['mode']}): {row['reason']}\n  `{row['command']}`\n")
            f.write("\n")
        f.write("## Cases\n\n")
        f.write("| case | mode | description | verdict | growth | E0 (J) | max disp/L | max speed (L/s) | "
                "solves | iterations | s | reason / message |\n")
        f.write("|---|---|---|---|---|---|---|---|---|---|---|---|\n")
        for row in rows:
            note = row["reason"] if row["verdict"] != "pass" else row.get("error", "")
            f.write(f"| {row['case']} | {row['mode']} | {row['description']} | {row['verdict']} | "
                    f"{fmt(row.get('growth'), '.2g')} | {fmt(row.get('E0'))} | {fmt(row.get('max_displacement'))} | "
                    f"{fmt(row.get('max_speed'))} | {row.get('solves', '')} | {row.get('iterations', '')} | "
                    f"{row['seconds']} | {note.replace('|', '/')} |\n")
    return csv_path, md_path


# ----------------------------------------------------------------------------- main

def parse_modes(text):
    modes = [m for m in re.split(r"[,\s]+", text) if m]
    for m in modes:
        if m not in MODES:
            raise argparse.ArgumentTypeError(f"unknown mode '{m}' (choose from {', '.join(MODES)})")
    return modes


def main(argv=None):
    parser = ToolParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                     allow_abbrev=False)
    add_option(parser, "softbody", default="build/softbody", help="the softbody executable (default build/softbody)")
    add_option(parser, "mpiexec", default="mpirun", help="MPI launcher (default mpirun)")
    add_option(parser, "stability_ranks", "--ranks", dest="ranks", type=int, default=2,
               help="MPI ranks per run (default 2)")
    add_option(parser, "stability_quick", "--quick", dest="quick", action="store_true",
               help="only the representative fast subset (E/nu/dt extremes, fast strike and spin, sliver, plate, "
                    "inverted tet, all fixed, single tet, no damping, combined extreme, four expected rejections)")
    add_option(parser, "stability_modes", "--modes", dest="modes", type=parse_modes, action="extend", nargs="+",
               metavar="MODE", help="modes to run: linear, corotational, or both (default both; "
                                    "'-stability_modes linear corotational' or '-stability_modes linear,corotational')")
    add_option(parser, "study_dir", "--study_dir", default="study",
               help="folder for stability.md, stability.csv and work/ (default study/)")
    add_option(parser, "stability_work", "--work", dest="work",
               help="folder for meshes, scenes and result files (default STUDY_DIR/work)")
    add_option(parser, "stability_keep", "--keep", dest="keep", action="store_true",
               help="keep the result files (.h5/.xdmf) in the work folder")
    add_option(parser, "stability_steps", "--steps", dest="steps", type=int, default=20,
               help="time steps per run (default 20)")
    add_option(parser, "stability_only", "--only", dest="only", metavar="REGEX",
               help="only the cases whose name matches REGEX (re.search)")
    add_option(parser, "stability_timeout", "--timeout", dest="timeout", type=float, default=120.0,
               help="seconds before a run counts as hung (default 120)")
    add_option(parser, "stability_options", "--options", dest="options", metavar="'OPTS'",
               help="extra softbody/PETSc options appended to every run, e.g. to try a fix: "
                    "-stability_options '-pc_gamg_reuse_interpolation false' (the reports record them)")
    add_option(parser, "stability_list", "--list", dest="list", action="store_true",
               help="list the cases and exit")
    args = parser.parse_args(argv)
    modes = []
    for group in args.modes or [list(MODES)]:
        modes += [m for m in group if m not in modes]
    args.modes = modes
    if args.steps < 1 or args.ranks < 1:
        parser.error("-stability_steps and -stability_ranks must be >= 1")

    cases = [c for c in matrix() if (c.quick or not args.quick) and (not args.only or re.search(args.only, c.key))]
    if args.list:
        for c in cases:
            print(f"{c.key:32s} {c.group:9s} {'quick ' if c.quick else '      '}{c.description}")
        return 0
    if not cases:
        parser.error("no case selected")
    if not os.path.isfile(args.softbody):
        parser.error(f"-softbody {args.softbody}: no such file (build first: ./run build)")
    work = os.path.abspath(args.work or os.path.join(args.study_dir, "work"))
    os.makedirs(work, exist_ok=True)

    print(f"stability: {len(cases)} cases x {len(modes)} modes, {args.steps} steps, {args.ranks} ranks; "
          f"work folder {work}", flush=True)
    start = time.monotonic()
    rows, cache = [], {}
    for case in cases:
        prepared = prepare(case, work, cache)
        for mode in modes:
            row = run_case(case, mode, prepared, args, work)
            rows.append(row)
            detail = row["reason"] if row["verdict"] != "pass" else (
                row["error"] if case.reject else
                f"growth {fmt(row['growth'], '.2g')}, max disp {fmt(row['max_displacement'])} L, "
                f"{row['solves']} solves, {row['iterations']} its")
            print(f"{row['verdict'].upper():4s}  {case.key:30s} {mode:12s} {row['seconds']:>6s} s  {detail}", flush=True)
    elapsed = time.monotonic() - start
    csv_path, md_path = write_reports(rows, args, elapsed)
    print()
    print("\n".join(summary_table(rows, modes)))
    failed = [row for row in rows if row["verdict"] != "pass"]
    for row in failed:
        print(f"FAIL {row['case']} ({row['mode']}): {row['reason']}\n     {row['command']}")
    print(f"\n{len(rows) - len(failed)}/{len(rows)} pass in {elapsed:.1f} s; wrote {md_path} and {csv_path}")
    return 0 if not failed else 1


if __name__ == "__main__":
    sys.exit(main())
