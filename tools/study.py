#!/usr/bin/python3
"""Work-precision study: accuracy against cost of softbody runs.

Runs one scene to a fixed end time T over a grid of
  time steps   dt0, dt0/2, dt0/4, ... (-study_levels of them; steps = round(T / dt)),
  modes        linear, corotational,
  integrators  -integrator be (default), bdf2, newmark, alpha (-study_integrators),
  adaptive     integrators run with -dt_adapt at dt0 and every -tol of -study_tols
               (-study_adaptive; a series per integrator, its points the tolerances),
  solvers      direct (config/direct.opts: CHOLMOD Cholesky), CG + GAMG
               (config/cg-gamg.opts), CG + Jacobi (config/cg-jacobi.opts); the
               iterative ones at every -ksp_rtol of -study_rtols,
  ranks        1 and 2,
and compares the positions at T with a reference run of the same mode (by default
dt ten times smaller than the finest level, direct solver, the largest rank
count; integrator be when the study runs be alone, else newmark, second order:
-study_reference_integrator; with -study_reference_tol, -dt_adapt at that -tol).
Per run:
  error_l2   ||u - u_ref|| / ||u_ref||, u = x - X over all free vertices
             (relative L2 norm of the displacement field, dimensionless),
  error_max  max_i |x_i - x_ref,i| over the free vertices (m),
  loop_s     the run's own time-loop wall time (root attribute loop_seconds of its
             result file; set-up, which includes the linear mode's factorisation,
             is setup_s and not counted), iterations = solver_iterations.

Writes into -study_dir DIR (default study/):
  study.csv  one row per run (failed runs too, with their one-line error),
  study.md   the tables, the observed order in dt of every configuration
             (least-squares slope of log error_l2 against log dt over its levels),
             the Pareto front of each mode (runs that no other run of the mode
             beats in both error and run time; errors within 0.1 % count as equal)
             and the cheapest run per accuracy; with -study_adaptive, each
             adaptive run against the fastest fixed-dt run reaching its error,
  study.png  error against run time (log-log), one series per configuration,
  runs/      the result files (HDF5) and logs of every run; old ones are deleted
             first, nothing is reused.

Usage (from the project root; ./run study calls this with -softbody build/softbody):
  ./run study scenes/default-scene.txt
  ./run study SCENE -study_levels 6 -study_modes linear -study_ranks 2 -study_dir /tmp/s -- -alpha 0 -beta 0
Timings on a shared machine are noisy: -study_repeat N runs the grid N times and keeps
each point's fastest time loop. Everything after `--` is passed to every softbody run (the reference included),
e.g. -alpha 0 -beta 0 or -shear_scale 0.25. A run that fails (non-zero exit, e.g.
an iterative solve that does not converge; a time-out; an incomplete file) is
recorded as failed with its one-line error; the study goes on. Exit status: 0
when the study is complete, 1 when a reference run failed (no errors then), 2 for
bad arguments.

Needs Debian's /usr/bin/python3 with python3-numpy, python3-h5py, python3-matplotlib.
"""
import argparse
import csv
import math
import os
import shutil
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from softbody_tools import (ToolParser, CONFIG_DIR, ROOT, add_option, add_run_options, comma_list, flatten,  # noqa: E402
                            mpi_environment, one_line_error, parse_with_passthrough)

MODES = ("linear", "corotational")
INTEGRATORS = ("be", "bdf2", "newmark", "alpha")
# Options the study sets itself on every run; passing them after `--` would break it.
CONTROLLED = ("-scene", "-mode", "-dt", "-dt_schedule", "-steps", "-output", "-output_every",
              "-options_file", "-ksp_rtol", "-deform", "-integrator", "-dt_adapt", "-tol")
# tol: -tol of an adaptive run (empty: fixed dt); its substeps and fills of the system matrix.
COLUMNS = ["mode", "solver", "ranks", "dt", "rtol", "steps", "setup_s", "loop_s", "iterations",
           "error_l2", "error_max", "status", "contact_s", "message", "integrator", "tol", "accepted_steps",
           "rejected_steps", "system_fills"]
SOLVER_LABELS = {"direct": "direct (CHOLMOD Cholesky)", "cg-gamg": "CG + GAMG", "cg-jacobi": "CG + Jacobi",
                 "cg-warp": "CG + warp"}


# ----------------------------------------------------------------------------- arguments

def parse_arguments(argv):
    parser = ToolParser(
        prog="study.py", allow_abbrev=False,
        description="Work-precision study of softbody: runs SCENE to a fixed end time over time "
                    "steps, modes, solvers, tolerances and rank counts, measures each run's error "
                    "against a fine reference and its run time, and writes study.csv, study.md "
                    "and study.png.",
        epilog="Options after `--` go to every softbody run, e.g. `-- -alpha 0 -beta 0`. "
               "Lists take commas or spaces: -study_ranks 1,2 or -study_ranks 1 2. Every option "
               "also has its GNU spelling (--study-ranks) and its older one (--ranks).")
    parser.add_argument("scene", help="softbody scene file")
    add_run_options(parser, "study", "output folder for study.csv, study.md, study.png and runs/")
    add_option(parser, "study_end_time", "--end-time", dest="end_time", metavar="T", type=float, default=0.2,
               help="end time T (s) at which errors are measured (default 0.2)")
    add_option(parser, "study_dt0", "--dt0", dest="dt0", metavar="DT", type=float, default=0.02,
               help="largest time step (s); the levels are dt0, dt0/2, dt0/4, ... (default 0.02)")
    add_option(parser, "study_levels", "--levels", dest="levels", metavar="N", type=int, default=5,
               help="number of time-step levels (default 5; at least 2 for an order)")
    add_option(parser, "study_modes", "--modes", dest="modes", metavar="MODE", nargs="+", type=comma_list(str),
               default=[list(MODES)], help="elasticity modes (default: linear,corotational)")
    add_option(parser, "study_integrators", "--integrators", dest="integrators", metavar="NAME", nargs="+",
               type=comma_list(str), default=[["be"]],
               help="time integrators, values of softbody's -integrator (default: be; all: be,bdf2,newmark,alpha)")
    add_option(parser, "study_adaptive", "--adaptive", dest="adaptive", metavar="NAME", nargs="+",
               type=comma_list(str), default=[[]],
               help="integrators also run with -dt_adapt (time loop step -study_dt0) at every -study_tols "
                    "(default: none; e.g. bdf2,newmark)")
    add_option(parser, "study_tols", "--tols", dest="tols", metavar="TOL", nargs="+", type=comma_list(float),
               default=[[1e-2, 1e-3, 1e-4, 1e-5, 1e-6]],
               help="-tol values of the adaptive runs (default: 1e-2,1e-3,1e-4,1e-5,1e-6)")
    add_option(parser, "study_reference_integrator", "--reference-integrator", dest="reference_integrator",
               metavar="NAME", default=None,
               help="integrator of the reference runs (default: be when the study runs be alone, else newmark)")
    add_option(parser, "study_solvers", "--solvers", dest="solvers", metavar="NAME", nargs="+",
               type=comma_list(str), default=[["direct", "cg-gamg", "cg-jacobi"]],
               help="solver presets, names of config/NAME.opts; a preset with -ksp_type preonly is direct, "
                    "the others are run at every -study_rtols (default: direct,cg-gamg,cg-jacobi)")
    add_option(parser, "study_rtols", "--rtols", dest="rtols", metavar="RTOL", nargs="+", type=comma_list(float),
               default=[[1e-4, 1e-8]], help="-ksp_rtol values of the iterative solvers (default: 1e-4,1e-8)")
    add_option(parser, "study_ranks", "--ranks", dest="ranks", metavar="N", nargs="+", type=comma_list(int),
               default=[[1, 2]], help="MPI rank counts (default: 1,2)")
    add_option(parser, "study_reference_dt", "--reference-dt", dest="reference_dt", metavar="DT", type=float,
               default=None, help="time step (s) of the reference runs (default: the finest level's dt / 10)")
    add_option(parser, "study_reference_tol", "--reference-tol", dest="reference_tol", metavar="TOL", type=float,
               default=None,
               help="run the references with -dt_adapt at this -tol, in steps of -study_dt0 "
                    "(-study_reference_dt is then not used; default: fixed steps)")
    add_option(parser, "study_reference_ranks", "--reference-ranks", dest="reference_ranks", metavar="N", type=int,
               default=None, help="rank count of the reference runs (default: the largest of -study_ranks)")
    add_option(parser, "study_repeat", "--repeat", dest="repeat", metavar="N", type=int, default=1,
               help="run the grid this many times (passes alternately forwards and backwards) and keep each "
                    "point's fastest time loop; the references run once (default 1)")
    add_option(parser, "study_timeout", "--timeout", dest="timeout", metavar="S", type=float, default=3600,
               help="seconds after which a run is stopped and recorded as failed (default 3600)")
    args = parse_with_passthrough(parser, argv)
    args.modes = flatten(args.modes)
    args.integrators = flatten(args.integrators)
    args.adaptive = flatten(args.adaptive)
    args.tols = sorted(flatten(args.tols), reverse=True)
    args.solvers = flatten(args.solvers)
    args.rtols = flatten(args.rtols)
    args.ranks = flatten(args.ranks)

    def fail(message):
        parser.error(message)

    for mode in args.modes:
        if mode not in MODES:
            fail(f"-study_modes: unknown mode {mode!r} (choose from {', '.join(MODES)})")
    for integrator in args.integrators + args.adaptive + [args.reference_integrator or "be"]:
        if integrator not in INTEGRATORS:
            fail(f"-study_integrators: unknown integrator {integrator!r} (choose from {', '.join(INTEGRATORS)})")
    if args.reference_integrator is None:
        args.reference_integrator = "be" if args.integrators == ["be"] else "newmark"
    args.direct = {}
    for solver in args.solvers:
        path = os.path.join(CONFIG_DIR, solver + ".opts")
        if not os.path.isfile(path):
            fail(f"-study_solvers: no preset {path}")
        args.direct[solver] = _is_direct(path)
    if args.reference_tol is not None and not 0 < args.reference_tol < 1:
        fail("-study_reference_tol must lie in (0, 1)")
    if any(not 0 < t < 1 for t in args.tols):
        fail("-study_tols must lie in (0, 1)")
    if any(r <= 0 or not math.isfinite(r) for r in args.rtols):
        fail("-study_rtols must be positive")
    if any(n < 1 for n in args.ranks):
        fail("-study_ranks must be positive")
    if not (args.end_time > 0 and math.isfinite(args.end_time)):
        fail("-study_end_time must be positive")
    if not (args.dt0 > 0 and math.isfinite(args.dt0)):
        fail("-study_dt0 must be positive")
    if args.levels < 1:
        fail("-study_levels must be at least 1")
    if args.repeat < 1:
        fail("-study_repeat must be at least 1")
    args.dts = [args.dt0 / 2 ** level for level in range(args.levels)]
    if args.reference_dt is None:
        args.reference_dt = args.dts[-1] / 10
    if args.reference_ranks is None:
        args.reference_ranks = max(args.ranks)
    for dt in args.dts + [args.reference_dt]:
        steps = round(args.end_time / dt)
        if steps < 1 or abs(steps * dt - args.end_time) > 1e-9 * args.end_time:
            fail(f"time step {dt:g} s does not divide the end time {args.end_time:g} s "
                 f"(choose -study_end_time, -study_dt0 or -study_reference_dt so that T / dt is a whole number)")
    for option in args.extra:
        if option in CONTROLLED:
            fail(f"{option} is set by the study itself and cannot be passed after --")
    if not os.path.isfile(args.scene):
        fail(f"no scene file {args.scene}")
    args.softbody = os.path.abspath(args.softbody)
    if not (os.path.isfile(args.softbody) and os.access(args.softbody, os.X_OK)):
        fail(f"softbody executable {args.softbody} not found (build first: ./run build)")
    if shutil.which(args.mpiexec) is None:
        fail(f"MPI launcher {args.mpiexec} not found")
    return args


def _is_direct(path):
    """A preset is direct when it selects -ksp_type preonly."""
    with open(path) as f:
        words = " ".join(line.split("#")[0] for line in f).split()
    return any(a == "-ksp_type" and b == "preonly" for a, b in zip(words, words[1:]))


# ----------------------------------------------------------------------------- runs

def run_softbody(args, name, mode, solver, rtol, ranks, dt, integrator="be", tol=None):
    """Runs softbody once; returns a dict with status, message, attributes and final positions."""
    import h5py
    runs = os.path.join(args.study_dir, "runs")
    out = os.path.join(runs, name + ".h5")
    steps = round(args.end_time / dt)
    command = [args.mpiexec, "-n", str(ranks), args.softbody,
               "-scene", os.path.abspath(args.scene), "-mode", mode,
               "-dt", repr(float(dt)), "-steps", str(steps), "-integrator", integrator,
               "-output", os.path.abspath(out), "-output_every", str(steps),
               "-options_file", os.path.join(CONFIG_DIR, solver + ".opts")]
    if rtol is not None:
        command += ["-ksp_rtol", repr(float(rtol))]
    if tol is not None:
        command += ["-dt_adapt", "-tol", repr(float(tol))]
    command += list(args.extra)
    result = {"mode": mode, "integrator": integrator, "solver": solver, "ranks": ranks, "dt": dt, "rtol": rtol,
              "steps": steps, "status": "failed", "message": "", "name": name, "tol": tol}
    for path in (out, os.path.join(runs, name + ".xdmf")):
        if os.path.exists(path):
            os.remove(path)
    try:
        proc = subprocess.run(command, capture_output=True, text=True, timeout=args.timeout,
                              env=mpi_environment(), cwd=ROOT)
        output, code = proc.stdout + proc.stderr, proc.returncode
    except subprocess.TimeoutExpired as expired:
        output = ((expired.stdout or b"").decode(errors="replace") if isinstance(expired.stdout, bytes)
                  else (expired.stdout or "")) + f"\n(timed out after {args.timeout:g} s)"
        code = None
    with open(os.path.join(runs, name + ".log"), "w") as log:
        log.write(" ".join(command) + "\n\n" + output)
    if code is None:
        result["message"] = f"timed out after {args.timeout:g} s"
        return result
    if code != 0:
        result["message"] = one_line_error(output, code)
        return result
    try:
        with h5py.File(out, "r") as f:
            # The run's statistics are the numeric scalar attributes ("gravity" is a vector,
            # "integrator" a name).
            attrs = {key: float(value) for key, value in f.attrs.items()
                     if np.size(value) == 1 and np.issubdtype(np.asarray(value).dtype, np.number)}
            positions = f["positions"][-1].astype(np.float64)
            rest = f["mesh/rest_positions"][()].astype(np.float64)
            vertex_body = f["mesh/vertex_body"][()]
            body_fixed = np.asarray(f["mesh/body_fixed"][()]).astype(bool)
            frame_time = float(f["time"][-1])
    except (OSError, KeyError) as error:
        result["message"] = f"unreadable result file {out}: {error}"
        return result
    problem = None
    if attrs.get("complete", 0) != 1:
        problem = "result file not marked complete"
    elif int(attrs.get("steps", -1)) != steps:
        problem = f"file says steps = {attrs.get('steps')}, expected {steps}"
    elif int(attrs.get("ranks", -1)) != ranks:
        problem = f"file says ranks = {attrs.get('ranks')}, expected {ranks}"
    elif abs(frame_time - args.end_time) > 1e-9 * args.end_time:
        problem = f"last frame at t = {frame_time!r} s, expected {args.end_time!r} s"
    elif not np.all(np.isfinite(positions)):
        problem = "non-finite positions at the end time"
    if problem:
        result["message"] = problem
        return result
    free = ~body_fixed[vertex_body]
    result.update(status="ok", setup_s=attrs.get("setup_seconds"), loop_s=attrs.get("loop_seconds"),
                  contact_s=attrs.get("contact_seconds"), iterations=attrs.get("solver_iterations"),
                  accepted_steps=attrs.get("accepted_steps"), rejected_steps=attrs.get("rejected_steps"),
                  system_fills=attrs.get("system_fills"),
                  positions=positions[free], rest=rest[free])
    return result


def add_errors(row, reference):
    if row["status"] != "ok" or reference is None or reference["status"] != "ok":
        return
    x, x_ref, rest = row["positions"], reference["positions"], reference["rest"]
    if x.shape != x_ref.shape:
        row["status"], row["message"] = "failed", "vertex count differs from the reference"
        return
    u_ref = x_ref - rest
    norm_ref = np.linalg.norm(u_ref)
    diff = x - x_ref
    row["error_l2"] = float(np.linalg.norm(diff) / norm_ref) if norm_ref > 0 else float("nan")
    row["error_max"] = float(np.sqrt((diff ** 2).sum(axis=1)).max())


# ----------------------------------------------------------------------------- analysis

def config_key(row):
    return (row["mode"], row["solver"], row["rtol"], row["ranks"], row["integrator"], row.get("tol") is not None)


def series_name(integrator, adaptive):
    return integrator + (" -dt_adapt" if adaptive else "")


def run_name(row):
    """The integrator of a row, with -dt_adapt and its -tol."""
    return row["integrator"] + ("" if row.get("tol") is None else f" -dt_adapt -tol {row['tol']:g}")


def config_label(solver, rtol, ranks, mode=None, integrator="be", tol=None):
    text = (integrator if tol is None else f"{integrator} -dt_adapt -tol {tol:g}") + ", " \
        + SOLVER_LABELS.get(solver, solver)
    if rtol is not None:
        text += f", rtol {rtol:g}"
    text += f", {ranks} rank" + ("s" if ranks != 1 else "")
    return (mode + ": " + text) if mode else text


def _good(row):
    e = row.get("error_l2")
    return row["status"] == "ok" and e is not None and math.isfinite(e) and e > 0


def observed_orders(rows):
    """{config: (order or None, points used)}: least-squares slope of log error_l2 vs log dt."""
    orders = {}
    for key in _unique(config_key(r) for r in rows if r.get("tol") is None):
        points = [(r["dt"], r["error_l2"]) for r in rows if config_key(r) == key and _good(r)]
        if len(points) >= 2:
            dts, errors = np.log([p[0] for p in points]), np.log([p[1] for p in points])
            orders[key] = (float(np.polyfit(dts, errors, 1)[0]), len(points))
        else:
            orders[key] = (None, len(points))
    return orders


def pareto_front(rows):
    """Runs (of one mode) that no other run beats in both error_l2 and loop time, fastest first."""
    good = [r for r in rows if _good(r) and r.get("loop_s") is not None]
    same = 1e-3  # errors that agree to 0.1 % count as equal (1 vs 2 ranks, a tight rtol)

    def beats(o, r):
        no_worse = o["error_l2"] <= r["error_l2"] * (1 + same) and o["loop_s"] <= r["loop_s"]
        better = o["error_l2"] < r["error_l2"] * (1 - same) or o["loop_s"] < r["loop_s"]
        return no_worse and better

    front = []
    for r in good:
        dominated = any(o is not r and beats(o, r) for o in good)
        if not dominated:
            front.append(r)
    return sorted(front, key=lambda r: r["loop_s"])


def cheapest_per_accuracy(rows):
    """[(target, fastest run with error_l2 <= target)] for every decade the runs span."""
    good = [r for r in rows if _good(r)]
    if not good:
        return []
    low = math.floor(math.log10(min(r["error_l2"] for r in good)))
    high = math.ceil(math.log10(max(r["error_l2"] for r in good)))
    out = []
    for exponent in range(high, low, -1):
        target = 10.0 ** exponent
        fitting = [r for r in good if r["error_l2"] <= target]
        if fitting:
            out.append((target, min(fitting, key=lambda r: r["loop_s"])))
    return out


def _unique(items):
    seen = []
    for item in items:
        if item not in seen:
            seen.append(item)
    return seen


# ----------------------------------------------------------------------------- output

def _fmt(value, spec):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    return format(value, spec)


def write_csv(path, rows):
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(COLUMNS)
        for r in rows:
            writer.writerow([r["mode"], r["solver"], r["ranks"], repr(float(r["dt"])),
                             "" if r["rtol"] is None else repr(float(r["rtol"])), r["steps"],
                             _fmt(r.get("setup_s"), ".6g"), _fmt(r.get("loop_s"), ".6g"),
                             _fmt(r.get("iterations"), ".0f"), _fmt(r.get("error_l2"), ".17g"),
                             _fmt(r.get("error_max"), ".17g"), r["status"],
                             _fmt(r.get("contact_s"), ".6g"), r.get("message", ""), r["integrator"],
                             "" if r.get("tol") is None else repr(float(r["tol"])),
                             _fmt(r.get("accepted_steps"), ".0f"), _fmt(r.get("rejected_steps"), ".0f"),
                             _fmt(r.get("system_fills"), ".0f")])


def _rtol_text(rtol):
    return "–" if rtol is None else f"{rtol:g}"


def _row_cells(r):
    return [run_name(r), SOLVER_LABELS.get(r["solver"], r["solver"]), _rtol_text(r["rtol"]), str(r["ranks"]),
            f"{r['dt']:g}", str(r["steps"]), _fmt(r.get("setup_s"), ".3f"), _fmt(r.get("loop_s"), ".3f"),
            _fmt(r.get("iterations"), ".0f"), _fmt(r.get("error_l2"), ".3e"), _fmt(r.get("error_max"), ".3e"),
            "ok" if r["status"] == "ok" else "FAILED: " + r.get("message", "").replace("|", "/")]


def _table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cells) + " |" for cells in rows]
    return "\n".join(lines)


def write_markdown(path, args, rows, references, orders, fronts, elapsed, png):
    md = [f"# Work-precision study: `{args.scene}`", ""]
    md.append(f"End time T = {args.end_time:g} s; time steps {', '.join(f'{dt:g}' for dt in args.dts)} s; "
              f"modes {', '.join(args.modes)}; integrators {', '.join(args.integrators)} "
              + (f"and with -dt_adapt {', '.join(args.adaptive)} at -tol {', '.join(f'{t:g}' for t in args.tols)} "
                 if args.adaptive else "")
              + f"(reference: {args.reference_integrator}); solvers {', '.join(args.solvers)} "
              f"(iterative at -ksp_rtol {', '.join(f'{t:g}' for t in args.rtols)}); "
              f"ranks {', '.join(map(str, args.ranks))}."
              + (f" Extra options: `{' '.join(args.extra)}`." if args.extra else ""))
    md.append("")
    md.append("Error of a run: its positions at T against the reference of the same mode; "
              "`rel. L2` = ||u - u_ref|| / ||u_ref|| with u = x - X over all free vertices, "
              "`max (m)` = max over free vertices of |x - x_ref|. Run time `loop (s)` = the "
              "run's time-loop wall time (`loop_seconds`; set-up, including the linear mode's "
              "factorisation, is `set-up (s)`). Iterations: total over all steps "
              "(1 per step for the direct solver).")
    md.append("")
    md.append(f"Study wall time {elapsed:.0f} s"
              + (f"; every grid point ran {args.repeat} times and keeps its fastest time loop." if args.repeat > 1
                 else "; every grid point ran once (timings on a shared machine are noisy: -study_repeat)."))
    md.append("")
    md.append("## References")
    md.append("")
    md.append(_table(["mode", "integrator", "solver", "ranks", "dt (s)", "steps", "set-up (s)", "loop (s)",
                      "status"],
                     [[ref["mode"], run_name(ref), SOLVER_LABELS.get(ref["solver"], ref["solver"]),
                       str(ref["ranks"]),
                       f"{ref['dt']:g}", str(ref["steps"]), _fmt(ref.get("setup_s"), ".3f"),
                       _fmt(ref.get("loop_s"), ".3f"),
                       "ok" if ref["status"] == "ok" else "FAILED: " + ref["message"]]
                      for ref in references.values()]))
    md.append("")
    md.append("## Observed order in dt")
    md.append("")
    md.append("Least-squares slope of log(rel. L2 error) against log(dt) over the levels of each "
              "configuration (backward Euler: 1 expected while the time error dominates; an "
              "iterative solve's tolerance shows as a flatter slope).")
    md.append("")
    order_rows = []
    for key, (order, used) in orders.items():
        mode, solver, rtol, ranks, integrator, _ = key
        finest = [r for r in rows if config_key(r) == key and _good(r)]
        finest = min(finest, key=lambda r: r["dt"]) if finest else None
        order_rows.append([mode, integrator, SOLVER_LABELS.get(solver, solver), _rtol_text(rtol), str(ranks),
                           "" if order is None else f"{order:.2f}", f"{used}/{len(args.dts)}",
                           _fmt(finest["error_l2"], ".3e") if finest else ""])
    md.append(_table(["mode", "integrator", "solver", "rtol", "ranks", "order", "levels used",
                      "rel. L2 at finest dt"], order_rows))
    md.append("")
    md.append("## Pareto front")
    md.append("")
    md.append("Per mode (each mode has its own reference): the runs that no other run of the mode "
              "beats in both rel. L2 error and run time, fastest first.")
    for mode in args.modes:
        md.append("")
        md.append(f"### {mode}")
        md.append("")
        md.append(_table(["integrator", "solver", "rtol", "ranks", "dt (s)", "loop (s)", "rel. L2", "max (m)"],
                         [[run_name(r), SOLVER_LABELS.get(r["solver"], r["solver"]), _rtol_text(r["rtol"]),
                           str(r["ranks"]),
                           f"{r['dt']:g}", f"{r['loop_s']:.3f}", f"{r['error_l2']:.3e}",
                           _fmt(r.get("error_max"), ".3e")] for r in fronts.get(mode, [])]))
        cheapest = cheapest_per_accuracy([r for r in rows if r["mode"] == mode])
        if cheapest:
            md.append("")
            md.append("Fastest run reaching a given accuracy:")
            md.append("")
            md.append(_table(["rel. L2 <=", "integrator", "solver", "rtol", "ranks", "dt (s)", "loop (s)",
                              "rel. L2"],
                             [[f"{target:g}", run_name(r), SOLVER_LABELS.get(r["solver"], r["solver"]),
                               _rtol_text(r["rtol"]), str(r["ranks"]), f"{r['dt']:g}",
                               f"{r['loop_s']:.3f}", f"{r['error_l2']:.3e}"] for target, r in cheapest]))
    if args.adaptive:
        md += adaptive_section(args, rows)
    failed = [r for r in rows if r["status"] != "ok"]
    md.append("")
    md.append(f"## Failed runs: {len(failed)}")
    if failed:
        md.append("")
        md.append(_table(["mode", "integrator", "solver", "rtol", "ranks", "dt (s)", "error"],
                         [[r["mode"], run_name(r), r["solver"], _rtol_text(r["rtol"]), str(r["ranks"]), f"{r['dt']:g}",
                           r["message"].replace("|", "/")] for r in failed]))
    md.append("")
    md.append("## All runs")
    header = ["integrator", "solver", "rtol", "ranks", "dt (s)", "steps", "set-up (s)", "loop (s)", "iterations",
              "rel. L2", "max (m)", "status"]
    for mode in args.modes:
        md.append("")
        md.append(f"### {mode}")
        md.append("")
        md.append(_table(header, [_row_cells(r) for r in rows if r["mode"] == mode]))
    md.append("")
    md.append(f"![error against run time]({os.path.basename(png)})")
    md.append("")
    with open(path, "w") as f:
        f.write("\n".join(md))


def fastest_fixed(rows, row):
    """The fastest fixed-dt run of row's mode whose error is at most row's (None: none reaches it)."""
    fitting = [r for r in rows if r["mode"] == row["mode"] and r.get("tol") is None and _good(r)
               and r.get("loop_s") is not None and r["error_l2"] <= row["error_l2"]]
    return min(fitting, key=lambda r: r["loop_s"]) if fitting else None


def adaptive_section(args, rows):
    md = ["", "## Adaptive mode (-dt_adapt)", "",
          f"Each adaptive run takes the steps of dt = {args.dt0:g} s (frames) in substeps sized by its local "
          "error estimate at -tol. `fixed` is the fastest fixed-dt run of the mode (any integrator and "
          "solver) whose error is at most the adaptive run's; `ratio` = adaptive loop / that loop."]
    for key in _unique(config_key(r) for r in rows if r.get("tol") is not None):
        mode, solver, rtol, ranks, integrator, _ = key
        series = sorted([r for r in rows if config_key(r) == key], key=lambda r: -r["tol"])
        errors = [r["error_l2"] for r in series if _good(r)]
        monotone = len(errors) == len(series) and all(b < a for a, b in zip(errors, errors[1:]))
        md += ["", f"### {mode}: {config_label(solver, rtol, ranks, None, integrator)} -dt_adapt", "",
               "error at T falls monotonically with -tol: " + ("yes" if monotone else "no"), ""]
        cells = []
        for r in series:
            best = fastest_fixed(rows, r) if _good(r) else None
            ratio = r["loop_s"] / best["loop_s"] if best and r.get("loop_s") and best["loop_s"] > 0 else None
            cells.append([f"{r['tol']:g}", _fmt(r.get("accepted_steps"), ".0f"), _fmt(r.get("rejected_steps"), ".0f"),
                          _fmt(r.get("system_fills"), ".0f"), _fmt(r.get("loop_s"), ".3f"),
                          _fmt(r.get("error_l2"), ".3e"),
                          f"{best['integrator']} dt {best['dt']:g}: {best['loop_s']:.3f} s" if best else "none reaches it",
                          _fmt(ratio, ".2f")])
        md.append(_table(["-tol", "substeps", "rejected", "A filled", "loop (s)", "rel. L2", "fixed", "ratio"],
                         cells))
    return md


def write_plot(path, args, rows, fronts):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import ticker
    from matplotlib.lines import Line2D

    modes = [m for m in args.modes]
    solver_rtols = _unique((r["solver"], r["rtol"], r["integrator"], r.get("tol") is not None) for r in rows)
    several = len(args.integrators) > 1 or bool(args.adaptive)
    palette = {("direct", None): "#1f4e9c", ("cg-gamg", 1e-8): "#1a9850", ("cg-gamg", 1e-4): "#91cf60",
               ("cg-jacobi", 1e-8): "#d73027", ("cg-jacobi", 1e-4): "#fc8d59"}
    spare = iter(["#7b3294", "#c2a5cf", "#8c510a", "#dfc27d", "#01665e", "#80cdc1", "#636363"])
    # One colour per solver; with several integrators one per integrator (and solver).
    integrator_palette = {("be", False): "#1f4e9c", ("bdf2", False): "#1a9850", ("newmark", False): "#d73027",
                          ("alpha", False): "#7b3294", ("be", True): "#6baed6", ("bdf2", True): "#a6d96a",
                          ("newmark", True): "#f4a582", ("alpha", True): "#c2a5cf"}
    one_solver = len(_unique(k[:2] for k in solver_rtols)) == 1
    colours = {}
    for key in solver_rtols:
        if not several:
            colour = palette.get(key[:2])
        else:
            colour = integrator_palette.get(key[2:]) if one_solver else None
        colours[key] = colour or next(spare, "#999999")
    rank_list = sorted(_unique(r["ranks"] for r in rows))
    styles = ["-", "--", ":", "-."]
    markers = ["o", "s", "^", "D"]
    rank_style = {n: (styles[i % 4], markers[i % 4]) for i, n in enumerate(rank_list)}

    fig, axes = plt.subplots(1, len(modes), figsize=(max(6.4 * len(modes), 9.6), 5.6), squeeze=False,
                             sharey=True)
    all_errors = [r["error_l2"] for r in rows if _good(r)]
    for ax, mode in zip(axes[0], modes):
        mode_rows = [r for r in rows if r["mode"] == mode]
        for key in solver_rtols:
            solver, rtol, integrator, adaptive = key
            for ranks in rank_list:
                series = sorted([r for r in mode_rows if r["solver"] == solver and r["rtol"] == rtol
                                 and r["integrator"] == integrator and (r.get("tol") is not None) == adaptive
                                 and r["ranks"] == ranks and _good(r)],
                                key=lambda r: -(r["tol"] if adaptive else r["dt"]))
                if not series:
                    continue
                style, marker = rank_style[ranks]
                marker = "*" if adaptive else marker
                ax.plot([r["loop_s"] for r in series], [r["error_l2"] for r in series], linestyle=style,
                        marker=marker, color=colours[key], markersize=8 if adaptive else 5, linewidth=1.4,
                        markerfacecolor="white" if ranks != rank_list[0] else colours[key])
                for r in series if adaptive and integrator == args.adaptive[0] and ranks == rank_list[-1] else []:
                    ax.annotate(f"tol={r['tol']:g}", (r["loop_s"], r["error_l2"]), textcoords="offset points",
                                xytext=(6, -9), fontsize=7, color=colours[key])
        front = fronts.get(mode, [])
        if front:
            xs, ys = [], []
            for r in front:  # staircase: the best error reachable within a run time
                if xs:
                    xs.append(r["loop_s"])
                    ys.append(ys[-1])
                xs.append(r["loop_s"])
                ys.append(r["error_l2"])
            ax.plot(xs, ys, color="black", linewidth=0.8, alpha=0.5, zorder=0)
            ax.scatter([r["loop_s"] for r in front], [r["error_l2"] for r in front], s=110,
                       facecolors="none", edgecolors="black", linewidths=1.0, zorder=5)
        # dt labels along the direct solver's series on the largest rank count (one per level)
        labelled = sorted([r for r in mode_rows if r["solver"] == (args.solvers[0]) and _good(r)
                           and r["ranks"] == rank_list[-1] and r["rtol"] is None and r.get("tol") is None
                           and r["integrator"] == args.integrators[0]], key=lambda r: -r["dt"])
        for r in labelled:
            ax.annotate(f"dt={r['dt']:g}", (r["loop_s"], r["error_l2"]), textcoords="offset points",
                        xytext=(6, 3), fontsize=7, color=colours.get((r["solver"], None, r["integrator"], False),
                                                                     "black"))
        failed = sum(1 for r in mode_rows if r["status"] != "ok")
        ax.set_xscale("log")
        ax.set_yscale("log")
        for axis in (ax.xaxis, ax.yaxis):  # labels at 1, 2, 5 x 10^k: readable over a narrow range
            axis.set_major_locator(ticker.LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
            axis.set_major_formatter(ticker.FuncFormatter(lambda value, _: f"{value:g}"))
            axis.set_minor_locator(ticker.LogLocator(base=10, subs=(3.0, 4.0, 6.0, 7.0, 8.0, 9.0)))
            axis.set_minor_formatter(ticker.NullFormatter())
        ax.grid(True, which="major", alpha=0.35)
        ax.grid(True, which="minor", alpha=0.12)
        ax.set_xlabel("run time: wall time of the time loop (s)")
        title = f"{mode} mode"
        if failed:
            title += f" ({failed} failed run{'s' if failed > 1 else ''} not shown)"
        ax.set_title(title)
    axes[0][0].set_ylabel("error at T: relative L2 norm of displacement error\n||u - u_ref|| / ||u_ref||  (dimensionless)")
    if all_errors:
        axes[0][0].set_ylim(min(all_errors) / 2, max(all_errors) * 2)

    solver_handles = [Line2D([], [], color=colours[k], linewidth=2.5, marker="*" if k[3] else None,
                             label=(f"{series_name(k[2], k[3])}, " if several else "") + SOLVER_LABELS.get(k[0], k[0])
                             + ("" if k[1] is None else f", rtol {k[1]:g}"))
                      for k in solver_rtols]
    other_handles = [Line2D([], [], color="grey", linestyle=rank_style[n][0], marker=rank_style[n][1],
                            markerfacecolor="grey" if n == rank_list[0] else "white",
                            label=f"{n} MPI rank" + ("s" if n != 1 else "")) for n in rank_list]
    other_handles.append(Line2D([], [], color="black", marker="o", markersize=10, markerfacecolor="none",
                                linestyle="-", linewidth=0.8, alpha=0.6,
                                label="Pareto front (no run is both faster and more accurate)"))
    columns = 3
    legend_rows = math.ceil(len(solver_handles) / columns) + 1
    first = fig.legend(handles=solver_handles, loc="lower center", ncol=min(len(solver_handles), columns),
                       fontsize=9, frameon=False, bbox_to_anchor=(0.5, 0.045))
    fig.add_artist(first)
    fig.legend(handles=other_handles, loc="lower center", ncol=len(other_handles), fontsize=9,
               frameon=False, bbox_to_anchor=(0.5, 0.0))
    fig.suptitle(f"{os.path.basename(args.scene)}: error at T = {args.end_time:g} s against run time; "
                 f"\npoints along a line: dt = {args.dts[0]:g} s (left) halved down to {args.dts[-1]:g} s (right)"
                 + (f"; -dt_adapt (stars): -tol {args.tols[0]:g} (left) to {args.tols[-1]:g}" if args.adaptive
                    else ""),
                 fontsize=10.5)
    fig.tight_layout(rect=(0, 0.045 * legend_rows + 0.01, 1, 0.93))
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ----------------------------------------------------------------------------- main

def main(argv=None):
    args = parse_arguments(sys.argv[1:] if argv is None else argv)
    started = time.time()
    runs_dir = os.path.join(args.study_dir, "runs")
    os.makedirs(runs_dir, exist_ok=True)
    for name in os.listdir(runs_dir):  # nothing stale: every run is made anew
        if name.endswith((".h5", ".xdmf", ".log")):
            os.remove(os.path.join(runs_dir, name))
    for name in ("study.csv", "study.md", "study.png"):
        if os.path.exists(os.path.join(args.study_dir, name)):
            os.remove(os.path.join(args.study_dir, name))

    grid = []
    for mode in args.modes:
        for integrator in args.integrators:
            for solver in args.solvers:
                for rtol in ([None] if args.direct[solver] else args.rtols):
                    for ranks in args.ranks:
                        for dt in args.dts:
                            grid.append((mode, solver, rtol, ranks, dt, integrator, None))
        for integrator in args.adaptive:
            for solver in args.solvers:
                for rtol in ([None] if args.direct[solver] else args.rtols):
                    for ranks in args.ranks:
                        for tol in args.tols:
                            grid.append((mode, solver, rtol, ranks, args.dt0, integrator, tol))
    reference_solver = next((s for s in args.solvers if args.direct[s]), "direct")
    total = len(grid) * args.repeat + len(args.modes)
    reference_dt = args.dt0 if args.reference_tol is not None else args.reference_dt
    adaptive_reference = "" if args.reference_tol is None else f" -dt_adapt -tol {args.reference_tol:g}"
    print(f"study: {args.scene}, T = {args.end_time:g} s, {len(grid)} runs + {len(args.modes)} "
          f"reference(s) (dt {reference_dt:g} s{adaptive_reference}, {args.reference_integrator}, {reference_solver}, "
          f"{args.reference_ranks} ranks) "
          f"into {args.study_dir}", flush=True)

    count = 0
    references = {}
    for mode in args.modes:
        count += 1
        name = (f"reference_{mode}_{args.reference_integrator}_{reference_solver}_np{args.reference_ranks}"
                f"_dt{reference_dt:g}" + ("" if args.reference_tol is None else f"_adapt_tol{args.reference_tol:g}"))
        ref = run_softbody(args, name, mode, reference_solver, None, args.reference_ranks, reference_dt,
                           args.reference_integrator, args.reference_tol)
        references[mode] = ref
        print(f"[{count}/{total}] reference {mode}: "
              + (f"{ref['steps']} steps, loop {ref['loop_s']:.2f} s" if ref["status"] == "ok"
                 else "FAILED: " + ref["message"]), flush=True)

    # Pass 1 over the grid; with --repeat, further passes (alternately backwards, so that a
    # burst of load on a shared machine hits other configurations) keep each point's
    # fastest time loop. Errors and iterations do not depend on the pass.
    rows = {}
    for repetition in range(args.repeat):
        for point in (grid if repetition % 2 == 0 else grid[::-1]):
            mode, solver, rtol, ranks, dt, integrator, tol = point
            count += 1
            if repetition and rows[point]["status"] != "ok":
                continue
            name = (f"{mode}_{integrator}_{solver}" + ("" if rtol is None else f"_rtol{rtol:g}")
                    + f"_np{ranks}_dt{dt:g}" + ("" if tol is None else f"_adapt_tol{tol:g}"))
            row = run_softbody(args, name, mode, solver, rtol, ranks, dt, integrator, tol)
            if repetition == 0:
                add_errors(row, references[mode])
                if row["status"] == "ok" and references[mode]["status"] != "ok":
                    row["message"] = "no error: the reference run failed"
                row.pop("positions", None)
                row.pop("rest", None)
                rows[point] = row
            elif row["status"] == "ok" and row["loop_s"] < rows[point]["loop_s"]:
                for key in ("setup_s", "loop_s", "contact_s"):
                    rows[point][key] = row[key]
            text = (f"loop {row['loop_s']:.3f} s, {row['iterations']:.0f} iterations"
                    + (f", rel. L2 {_fmt(rows[point].get('error_l2'), '.3e')}" if repetition == 0 else "")
                    if row["status"] == "ok" else "FAILED: " + row["message"])
            label = f"pass {repetition + 1}: " if args.repeat > 1 else ""
            print(f"[{count}/{total}] {label}{config_label(solver, rtol, ranks, mode, integrator, tol)}, dt {dt:g}: "
                  f"{text}",
                  flush=True)
    rows = [rows[point] for point in grid]

    orders = observed_orders(rows)
    fronts = {mode: pareto_front([r for r in rows if r["mode"] == mode]) for mode in args.modes}
    elapsed = time.time() - started
    csv_path = os.path.join(args.study_dir, "study.csv")
    md_path = os.path.join(args.study_dir, "study.md")
    png_path = os.path.join(args.study_dir, "study.png")
    write_csv(csv_path, rows)
    write_plot(png_path, args, rows, fronts)
    write_markdown(md_path, args, rows, references, orders, fronts, elapsed, png_path)

    print()
    print("observed order in dt (slope of log rel. L2 error vs log dt):")
    for key, (order, used) in orders.items():
        print(f"  {config_label(key[1], key[2], key[3], key[0], key[4]):66s} "
              + ("  n/a" if order is None else f"{order:5.2f}") + f"  ({used} levels)")
    for mode in args.modes:
        print(f"Pareto front, {mode} (fastest first):")
        for r in fronts[mode]:
            print(f"  {config_label(r['solver'], r['rtol'], r['ranks'], None, r['integrator'], r.get('tol')):52s} "
                  f"dt {r['dt']:<9g} "
                  f"loop {r['loop_s']:8.3f} s  rel. L2 {r['error_l2']:.3e}")
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        print(f"{len(failed)} failed run(s):")
        for r in failed:
            print(f"  {config_label(r['solver'], r['rtol'], r['ranks'], r['mode'], r['integrator'], r.get('tol'))}, "
                  f"dt {r['dt']:g}: "
                  f"{r['message']}")
    print(f"wrote {csv_path}, {md_path}, {png_path} ({elapsed:.0f} s)")
    bad_references = [m for m, ref in references.items() if ref["status"] != "ok"]
    if bad_references:
        print(f"study: the reference run failed for {', '.join(bad_references)}: no errors for that mode",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
