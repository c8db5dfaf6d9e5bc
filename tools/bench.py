#!/usr/bin/python3
"""Performance ladder: softbody against the machine and against other codes.

Meshes a beam (4 x 1 x 1 m, tools/box_mesh.py, 6 Kuhn tets per cubic cell) at
about each of -bench_tets tets, strikes it (the vertices of the x = 0 end face
at +vz, those of the x = 4 m end at -vz: the beam spins about y and bends) and
runs softbody on it over the grid
  modes    -bench_modes    linear, corotational
  solvers  -bench_solvers  presets config/NAME.opts (default: direct, cg-warp,
                           cg-gamg)
  ranks    -bench_ranks    1, 2
with -bench, which makes softbody measure itself (src/app/benchmark.hpp): median
step time over -bench_steps steps, one assembly of A (median of 5), the largest
factorisation / preconditioner set-up, solver iterations per step, the largest
resident set of any rank, a STREAM triad run on all ranks in the same run, and
the memory traffic a step needs at least (the nonzeros of K or A and of the
Cholesky factor) over that bandwidth: bound_fraction = bound / step time.

Writes into -study_dir DIR (default bench/): bench.csv (one row per run, failed
runs with their error line), bench.md (the table, the performance targets with a
verdict each, the reference figures), meshes/ (the meshes and scenes, reused
when present) and runs/ (one log per run).

Usage (from the project root; ./run bench calls this with -softbody build/softbody):
  ./run bench                                   # ladder 1e4,1e5
  ./run bench -bench_tets 1e6 -bench_ranks 2    # the million-tet rung
  ./run bench -bench_tets 1e4 -study_dir /tmp/b -bench_solvers direct,cg-warp,cg-gamg
Options after `--` go to every softbody run. Lists take commas or spaces.
Timings on a shared machine are noisy: the bandwidth is measured in the same
run for that reason, and -bench_repeat N keeps each point's fastest of N runs.
Needs Debian's /usr/bin/python3 with python3-numpy.
"""
import argparse
import csv
import math
import os
import platform
import shutil
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import box_mesh  # noqa: E402
from softbody_tools import (ToolParser, CONFIG_DIR, ROOT, add_option, add_run_options, comma_list, flatten,  # noqa: E402
                            mpi_environment, one_line_error, parse_with_passthrough)

MODES = ("linear", "corotational")
BEAM_SIZE = (4.0, 1.0, 1.0)
MATERIAL = {"density": 1000.0, "young": 1e6, "poisson": 0.4}
STRIKE_SPEED = 1.0  # m/s, +z at x = 0, -z at x = 4
COLUMNS = ["tets", "vertices", "mode", "solver", "ranks", "assemble_s", "factor_s", "step_s", "iterations",
           "peak_rss_mb", "bandwidth_gbs", "bound_fraction", "assemble_rate", "bound_s", "matrix_nonzeros",
           "factor_nonzeros", "steps", "status", "message"]
# softbody's -bench names for the columns.
ATTRIBUTE = {"assemble_s": "assemble_s", "factor_s": "factor_s", "step_s": "step_s", "iterations": "iterations",
             "peak_rss_mb": "peak_rss_mb", "bandwidth_gbs": "bandwidth_gbs", "bound_fraction": "bound_fraction",
             "assemble_rate": "assemble_rate", "bound_s": "bound_s", "matrix_nonzeros": "matrix_nonzeros",
             "factor_nonzeros": "factor_nonzeros", "steps": "bench_steps", "vertices": "bench_vertices",
             "tets": "bench_tets"}

# Per implicit step on one core of this kind of machine: tets -> seconds.
CHOLMOD_COURSEWORK = [(2.5e3, 0.23e-3), (22e3, 8.5e-3), (104e3, 75e-3)]  # linear, factorised once
VEGA_COROTATIONAL = [(2.5e3, 5.2e-3), (22e3, 107e-3), (104e3, 709e-3)]   # PCG + Jacobi
DOLFINX_ASSEMBLY_RATE = 0.55e6  # P1 elasticity tets/s per core


# ----------------------------------------------------------------------------- arguments

def _count(text):
    value = float(text)
    if not (value >= 1 and math.isfinite(value)):
        raise ValueError(f"{text}: a tet count must be at least 1")
    return int(round(value))


def parse_arguments(argv):
    parser = ToolParser(
        prog="bench.py", allow_abbrev=False,
        description="softbody performance ladder: beams of about N tets, both modes, direct and iterative "
                    "presets, 1 and 2 ranks; writes bench.csv and bench.md.",
        epilog="Options after `--` go to every softbody run. Lists take commas or spaces.")
    add_option(parser, "bench_tets", "--tets", dest="tets", metavar="N", nargs="+", type=comma_list(_count),
               default=[[10000, 100000]], help="tet counts of the ladder (default 1e4,1e5; 1e6 on request)")
    add_option(parser, "bench_modes", "--modes", dest="modes", metavar="MODE", nargs="+", type=comma_list(str),
               default=[list(MODES)], help="elasticity modes (default linear,corotational)")
    add_option(parser, "bench_solvers", "--solvers", dest="solvers", metavar="NAME", nargs="+",
               type=comma_list(str), default=[["direct", "cg-warp", "cg-gamg"]],
               help="solver presets config/NAME.opts (default direct,cg-warp,cg-gamg)")
    add_option(parser, "bench_ranks", "--ranks", dest="ranks", metavar="N", nargs="+", type=comma_list(int),
               default=[[1, 2]], help="MPI rank counts (default 1,2)")
    add_run_options(parser, "bench", "output folder for bench.csv, bench.md, meshes/ and runs/")
    add_option(parser, "bench_steps", "--steps", dest="steps", metavar="N", type=int, default=12,
               help="time steps per run; the step time is their median (default 12, at least 10)")
    add_option(parser, "bench_dt", "--dt", dest="dt", metavar="S", type=float, default=0.01,
               help="time step (s, default 0.01)")
    add_option(parser, "bench_repeat", "--repeat", dest="repeat", metavar="N", type=int, default=1,
               help="run every point N times and keep the fastest step (default 1)")
    add_option(parser, "bench_timeout", "--timeout", dest="timeout", metavar="S", type=float, default=7200,
               help="seconds after which a run is stopped and recorded as failed (default 7200)")
    args = parse_with_passthrough(parser, argv)
    args.tets = flatten(args.tets)
    args.modes = flatten(args.modes)
    args.solvers = flatten(args.solvers)
    args.ranks = flatten(args.ranks)
    for mode in args.modes:
        if mode not in MODES:
            parser.error(f"-bench_modes: unknown mode {mode!r} (choose from {', '.join(MODES)})")
    for solver in args.solvers:
        if not os.path.isfile(os.path.join(CONFIG_DIR, solver + ".opts")):
            parser.error(f"-bench_solvers: no preset config/{solver}.opts")
    if any(n < 1 for n in args.ranks):
        parser.error("-bench_ranks must be positive")
    if args.steps < 10:
        parser.error("-bench_steps must be at least 10 (the step time is a median over them)")
    if not (args.dt > 0 and math.isfinite(args.dt)):
        parser.error("-bench_dt must be positive")
    if args.repeat < 1:
        parser.error("-bench_repeat must be at least 1")
    args.softbody = os.path.abspath(args.softbody)
    if not (os.path.isfile(args.softbody) and os.access(args.softbody, os.X_OK)):
        parser.error(f"softbody executable {args.softbody} not found (build first: ./run build)")
    if shutil.which(args.mpiexec) is None:
        parser.error(f"MPI launcher {args.mpiexec} not found")
    return args


# ----------------------------------------------------------------------------- meshes

def beam_mesh(target_tets):
    """Vertices, tets (0-based) and cells of the beam meshed at about target_tets tets."""
    cells = box_mesh.cells_for_tets(BEAM_SIZE, target_tets)
    vertices, tets = box_mesh.box_mesh(BEAM_SIZE, cells)
    return vertices, tets, cells


def write_beam(folder, target_tets):
    """Writes folder/beam-N.mesh and folder/beam-N.txt (the struck beam); reuses them when
    present. Returns the scene path."""
    os.makedirs(folder, exist_ok=True)
    mesh_path = os.path.join(folder, f"beam-{target_tets}.mesh")
    scene_path = os.path.join(folder, f"beam-{target_tets}.txt")
    if os.path.exists(mesh_path) and os.path.exists(scene_path):
        return scene_path
    vertices, tets, _ = beam_mesh(target_tets)
    faces = box_mesh.boundary_faces(tets, len(vertices))
    refs = box_mesh.side_of_faces(vertices, faces, BEAM_SIZE)
    box_mesh.write_medit(mesh_path + ".part", vertices, tets, faces, refs)
    os.replace(mesh_path + ".part", mesh_path)
    left = np.flatnonzero(vertices[:, 0] <= 1e-12)
    right = np.flatnonzero(vertices[:, 0] >= BEAM_SIZE[0] - 1e-12)
    with open(scene_path, "w") as f:
        f.write(f"# softbody bench: beam {BEAM_SIZE[0]:g} x {BEAM_SIZE[1]:g} x {BEAM_SIZE[2]:g} m, "
                f"{len(tets)} tets, struck at both end faces (+-{STRIKE_SPEED:g} m/s along z)\n")
        f.write("1\n")
        f.write(f"{os.path.basename(mesh_path)} {MATERIAL['density']!r} {MATERIAL['young']!r} "
                f"{MATERIAL['poisson']!r} 0  0 0 0  1 0 0 0\n")
        f.write(f"{len(left) + len(right)}\n")
        for v in left:
            f.write(f"0 {v} 0 0 {STRIKE_SPEED!r}\n")
        for v in right:
            f.write(f"0 {v} 0 0 {-STRIKE_SPEED!r}\n")
    return scene_path


# ----------------------------------------------------------------------------- runs

def parse_bench_line(text):
    """The name=value pairs of softbody's 'softbody bench:' line (None when absent)."""
    for line in text.splitlines():
        if line.startswith("softbody bench:"):
            values = {}
            for item in line.split(":", 1)[1].split():
                name, _, value = item.partition("=")
                values[name] = float(value)
            return values
    return None


def run_point(args, scene, tets, mode, solver, ranks):
    name = f"{tets}-{mode}-{solver}-{ranks}"
    command = [args.mpiexec, "-n", str(ranks), args.softbody, "-scene", os.path.abspath(scene), "-mode", mode,
               "-options_file", os.path.join(CONFIG_DIR, solver + ".opts"), "-dt", repr(args.dt),
               "-steps", str(args.steps), "-bench"] + list(args.extra)
    row = {"tets": tets, "mode": mode, "solver": solver, "ranks": ranks, "status": "failed", "message": ""}
    try:
        proc = subprocess.run(command, capture_output=True, text=True, timeout=args.timeout,
                              env=mpi_environment(), cwd=ROOT)
        output, code = proc.stdout + proc.stderr, proc.returncode
    except subprocess.TimeoutExpired:
        output, code = f"(timed out after {args.timeout:g} s)", None
    with open(os.path.join(args.study_dir, "runs", name + ".log"), "w") as log:
        log.write(" ".join(command) + "\n\n" + output)
    if code is None:
        row["message"] = f"timed out after {args.timeout:g} s"
        return row
    if code != 0:
        row["message"] = one_line_error(output, code)
        return row
    values = parse_bench_line(output)
    if values is None:
        row["message"] = "no 'softbody bench:' line in the output"
        return row
    for column, attribute in ATTRIBUTE.items():
        row[column] = values.get(attribute, float("nan"))
    row["tets"] = int(row["tets"])
    row["vertices"] = int(row["vertices"])
    row["steps"] = int(row["steps"])
    row["status"] = "ok"
    return row


# ----------------------------------------------------------------------------- report

def loglog(points, x):
    """Piecewise log-log interpolation (extrapolated from the nearest segment)."""
    xs = np.log([p[0] for p in points])
    ys = np.log([p[1] for p in points])
    lx = math.log(x)
    i = int(np.clip(np.searchsorted(xs, lx) - 1, 0, len(xs) - 2))
    slope = (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i])
    return math.exp(ys[i] + slope * (lx - xs[i]))


def _fmt(value, digits=3):
    if isinstance(value, str):
        return value
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, int):
        return str(value)
    if value == 0:
        return "0"
    if abs(value) >= 1e4 or abs(value) < 1e-3:
        return f"{value:.{digits}g}"
    return f"{value:.{digits}g}"


def targets(rows):
    """The performance targets, each as (target, figures, verdict), for the default presets
    (linear: direct; corotational: cg-warp, or another iterative preset when it did not run)."""
    ok = [r for r in rows if r["status"] == "ok"]
    lines = []
    iterative = "cg-warp" if any(r["solver"] == "cg-warp" for r in ok) else None

    def verdict(flag):
        return "met" if flag else "not met"

    linear_direct = [r for r in ok if r["mode"] == "linear" and r["solver"] == "direct" and r["tets"] >= 1e5 * 0.9]
    for r in linear_direct:
        cholmod = loglog(CHOLMOD_COURSEWORK, r["tets"])
        lines.append((f"linear direct step, {r['tets']} tets, {r['ranks']} rank(s): bound_fraction >= 0.6 "
                      f"and faster than the coursework's CHOLMOD ({1e3 * cholmod:.3g} ms at this size)",
                      f"bound_fraction {r['bound_fraction']:.2f}, step {1e3 * r['step_s']:.3g} ms",
                      verdict(r["bound_fraction"] >= 0.6 and r["step_s"] < cholmod)))
    def default_corotational(r):
        return r["mode"] == "corotational" and r["solver"] != "direct" and (iterative is None or r["solver"] == iterative)

    for r in ok:
        if default_corotational(r) and r["tets"] >= 1e5 * 0.9:
            rate = r["assemble_rate"]
            lines.append((f"corotational K assembly >= 5 M tets/s per core (10 x DOLFINx's "
                          f"{DOLFINX_ASSEMBLY_RATE / 1e6:.2f} M), {r['tets']} tets, {r['ranks']} rank(s)",
                          f"{rate / 1e6:.2f} M tets/s per rank", verdict(rate >= 5e6)))
    corotational = [r for r in ok if default_corotational(r)]
    for r in corotational:
        if r["ranks"] == 1 and 0.5e5 <= r["tets"] <= 2e5:
            vega = loglog(VEGA_COROTATIONAL, r["tets"])
            lines.append((f"corotational step ({r['solver']}), {r['tets']} tets, 1 rank: at least 5 x faster than "
                          f"Vega ({1e3 * vega:.3g} ms at this size, so <= {1e3 * vega / 5:.3g} ms)",
                          f"{1e3 * r['step_s']:.3g} ms ({vega / r['step_s']:.1f} x)",
                          verdict(r["step_s"] <= vega / 5)))
    for r2 in corotational:
        if r2["ranks"] == 2 and r2["tets"] >= 0.5e5:
            for r1 in corotational:
                if r1["ranks"] == 1 and r1["tets"] == r2["tets"] and r1["solver"] == r2["solver"]:
                    speedup = r1["step_s"] / r2["step_s"]
                    lines.append((f"corotational step ({r2['solver']}), {r2['tets']} tets: 2 ranks >= 1.4 x "
                                  f"faster than 1", f"{1e3 * r1['step_s']:.3g} -> {1e3 * r2['step_s']:.3g} ms "
                                  f"({speedup:.2f} x)", verdict(speedup >= 1.4)))
    for r2 in ok:
        if r2["mode"] == "linear" and r2["solver"] == "direct" and r2["ranks"] == 2 and r2["tets"] >= 0.5e5:
            for r1 in ok:
                if (r1["mode"] == "linear" and r1["ranks"] == 1 and r1["tets"] == r2["tets"]
                        and r1["solver"] == r2["solver"]):
                    speedup = r1["step_s"] / r2["step_s"]
                    # "not slower": within the run-to-run noise of a shared machine (5 %).
                    lines.append((f"linear step ({r2['solver']}), {r2['tets']} tets: not slower on 2 ranks",
                                  f"{1e3 * r1['step_s']:.3g} -> {1e3 * r2['step_s']:.3g} ms ({speedup:.2f} x)",
                                  verdict(speedup >= 0.95)))
    million = [r for r in rows if r["tets"] >= 0.9e6 and r["ranks"] == 2]
    for mode in MODES:
        runs = [r for r in million if r["mode"] == mode]
        if runs:
            best = [r for r in runs if r["status"] == "ok"]
            lines.append((f"1e6 tets, {mode}, 2 ranks, within the machine's memory",
                          ", ".join(f"{r['solver']}: " + (f"peak RSS {r['peak_rss_mb']:.0f} MB per rank, step "
                                                           f"{r['step_s']:.3g} s" if r["status"] == "ok"
                                                           else r["message"]) for r in runs),
                          verdict(bool(best))))
    return lines


def write_outputs(args, rows, started):
    with open(os.path.join(args.study_dir, "bench.csv"), "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({c: row.get(c, "") for c in COLUMNS})
    md = ["# softbody bench", ""]
    md.append(f"Beam {BEAM_SIZE[0]:g} x {BEAM_SIZE[1]:g} x {BEAM_SIZE[2]:g} m (tools/box_mesh.py, 6 Kuhn tets per "
              f"cell), {MATERIAL['density']:g} kg/m^3, E = {MATERIAL['young']:g} Pa, nu = {MATERIAL['poisson']:g}, "
              f"struck at both end faces (+-{STRIKE_SPEED:g} m/s along z); dt = {args.dt:g} s, {args.steps} steps, "
              f"default damping. Machine: {platform.node()}, {os.cpu_count()} cores; run "
              f"{time.strftime('%Y-%m-%d %H:%M', time.localtime(started))}, "
              f"{(time.time() - started) / 60:.1f} min, load average at the end "
              f"{os.getloadavg()[0]:.1f}.")
    md.append("")
    md.append("step_s: median over the steps; assemble_s: one fill of A (median of 5); factor_s: the largest "
              "factorisation or preconditioner set-up; iterations: per step; peak_rss_mb: largest of the ranks; "
              "bandwidth_gbs: STREAM triad on all ranks in the same run; bound_fraction: the step's memory "
              "traffic lower bound (nonzeros of K or A and of the Cholesky factor) over that bandwidth, divided "
              "by step_s; assemble M/s: tets per second per rank of one fill.")
    md.append("")
    header = ["tets", "vertices", "mode", "solver", "ranks", "assemble_s", "factor_s", "step_s", "iterations",
              "peak_rss_mb", "bandwidth_gbs", "bound_fraction", "assemble M/s"]
    md.append("| " + " | ".join(header) + " |")
    md.append("|" + "---|" * len(header))
    for r in rows:
        if r["status"] != "ok":
            md.append(f"| {r['tets']} | | {r['mode']} | {r['solver']} | {r['ranks']} | failed: "
                      f"{r['message']} |" + " |" * (len(header) - 6))
            continue
        cells = [r["tets"], r["vertices"], r["mode"], r["solver"], r["ranks"], r["assemble_s"], r["factor_s"],
                 r["step_s"], r["iterations"], round(r["peak_rss_mb"]), r["bandwidth_gbs"], r["bound_fraction"],
                 r["assemble_rate"] / 1e6]
        md.append("| " + " | ".join(_fmt(c) for c in cells) + " |")
    md.append("")
    lines = targets(rows)
    if lines:
        md.append("## Targets")
        md.append("")
        md.append("| target | measured | verdict |")
        md.append("|---|---|---|")
        for target, figures, verdict in lines:
            md.append(f"| {target} | {figures} | {verdict} |")
        md.append("")
    md.append("Reference figures per implicit step on one core of this kind of machine: the "
              "coursework's Eigen + CHOLMOD (linear, factorised once) 0.23 ms at 2.5k tets, 8.5 ms at 22k, 75 ms "
              "at 104k; Vega FEM corotational, PCG + Jacobi, 5.2 ms, 107 ms, 709 ms; DOLFINx 0.5 assembles P1 "
              "elasticity at about 0.55 M tets/s per core. Sizes in between are interpolated log-log.")
    md.append("")
    md.append("Reproduce: `./run bench -bench_tets " + ",".join(str(t) for t in args.tets) + " -bench_modes "
              + ",".join(args.modes) + " -bench_solvers " + ",".join(args.solvers) + " -bench_ranks "
              + ",".join(str(n) for n in args.ranks) + "`.")
    with open(os.path.join(args.study_dir, "bench.md"), "w") as f:
        f.write("\n".join(md) + "\n")


def main(argv=None):
    args = parse_arguments(sys.argv[1:] if argv is None else argv)
    started = time.time()
    os.makedirs(os.path.join(args.study_dir, "runs"), exist_ok=True)
    meshes = os.path.join(args.study_dir, "meshes")
    rows = []
    for tets in args.tets:
        scene = write_beam(meshes, tets)
        for mode in args.modes:
            for solver in args.solvers:
                for ranks in args.ranks:
                    best = None
                    for _ in range(args.repeat):
                        row = run_point(args, scene, tets, mode, solver, ranks)
                        if best is None or (row["status"] == "ok" and
                                            (best["status"] != "ok" or row["step_s"] < best["step_s"])):
                            best = row
                    rows.append(best)
                    if best["status"] == "ok":
                        print(f"bench: {best['tets']} tets {mode} {solver} {ranks} rank(s): step "
                              f"{1e3 * best['step_s']:.3g} ms, assembly {1e3 * best['assemble_s']:.3g} ms, "
                              f"{best['iterations']:.3g} iterations, bound fraction {best['bound_fraction']:.2f}",
                              flush=True)
                    else:
                        print(f"bench: {tets} tets {mode} {solver} {ranks} rank(s): failed: {best['message']}",
                              flush=True)
                    write_outputs(args, rows, started)
    write_outputs(args, rows, started)
    print(f"bench: wrote {os.path.join(args.study_dir, 'bench.csv')} and bench.md")
    return 0 if all(r["status"] == "ok" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
