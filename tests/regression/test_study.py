#!/usr/bin/env python3
"""The work-precision study (tools/study.py) on a small beam of its own.

Scene: a 2 x 0.4 x 0.4 m beam (tools/box_mesh.py, 10 x 2 x 2 cells, 99 vertices,
240 tets; E = 2.5e4 Pa, nu = 0.45, 1000 kg/m^3) struck by a smooth bending
velocity field v_z = 2 m/s cos(2 pi x / L) (no net momentum, mostly the lowest
bending mode, so backward Euler is in its asymptotic range already at
dt = 0.02 s), no damping (-alpha 0 -beta 0 passed through the study).

Study: T = 0.2 s, dt = 0.02 ... 0.00125 s (5 levels), linear and corotational,
direct and CG + GAMG at -ksp_rtol 1e-8, 1 and 2 ranks: 40 runs and 2 references
(dt = 0.000125 s, direct, 2 ranks). Checked from study.csv, independently of the
tool's own analysis:
- the CSV has the expected columns and exactly one successful row per grid point,
  steps = T / dt;
- the observed order of backward Euler (least-squares slope of log error vs
  log dt, direct solver, each mode and rank count) lies in [0.8, 1.2];
- the direct solver's errors decrease strictly as dt is halved;
- 1 and 2 ranks (direct) give the same errors to 1e-6 relative;
- one error recomputed from runs of this script (reference and coarsest level)
  matches the CSV;
- study.png is a valid PNG (signature, IHDR, a sensible size), study.md has the
  orders and the Pareto front.
Then a study whose iterative runs cannot converge (-ksp_max_it 1) must finish
and record those runs as failed with softbody's one-line error; its options are
given in the other spellings the tools accept (GNU --study-modes, the older
--solvers and --ranks, -name=value), so they are checked too.
Last, the adaptive configuration at its smallest (bdf2 at 2 levels and with
-dt_adapt -tol 1e-3, linear, direct, 1 rank): its row in study.csv and its
section in study.md.
"""
import csv
import math
import os
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STUDY = os.path.join(ROOT, "tools", "study.py")
BOX_MESH = os.path.join(ROOT, "tools", "box_mesh.py")
NX, NY, NZ = 10, 2, 2
LENGTH = 2.0
END_TIME = 0.2
DTS = [0.02 / 2 ** level for level in range(5)]
REFERENCE_DT = DTS[-1] / 10
PASSTHROUGH = ["-alpha", "0", "-beta", "0"]
COLUMNS = ["mode", "solver", "ranks", "dt", "rtol", "steps", "setup_s", "loop_s", "iterations",
           "error_l2", "error_max"]
ORDER_RANGE = (0.8, 1.2)
RANK_AGREEMENT = 1e-6


def make_scene(work):
    mesh = os.path.join(work, "beam.mesh")
    subprocess.run([sys.executable, BOX_MESH, mesh, "-box_size", str(LENGTH), "0.4", "0.4",
                    "-box_cells", str(NX), str(NY), str(NZ)], check=True, capture_output=True)
    velocities = []
    for k in range(NZ + 1):
        for j in range(NY + 1):
            for i in range(NX + 1):
                index = i + (NX + 1) * (j + (NY + 1) * k)
                velocities.append((0, index, (0.0, 0.0, 2.0 * math.cos(2 * math.pi * i / NX))))
    return harness.write_scene(os.path.join(work, "beam-study.txt"),
                               [("beam.mesh", 1000.0, 2.5e4, 0.45, False, (0, 0, 0), (1, 0, 0, 0))],
                               velocities)


def run_study(args, scene, study_dir, options, passthrough):
    command = [sys.executable, STUDY, scene, "-softbody", args.softbody, "-mpiexec", args.mpiexec,
               "-study_dir", study_dir] + options + ["--"] + passthrough
    start = time.time()
    result = subprocess.run(command, capture_output=True, text=True, timeout=900)
    return result, time.time() - start


def read_csv(path):
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return reader.fieldnames, list(reader)


def slope(dts, errors):
    return float(np.polyfit(np.log(dts), np.log(errors), 1)[0])


def final_positions(path):
    frames = harness.read_frames(path)
    return frames["positions"][-1], frames["mesh/rest_positions"]


def main():
    args = harness.arguments()
    checks = harness.Checks()
    scene = make_scene(args.work)
    study_dir = os.path.join(args.work, "study")

    result, seconds = run_study(args, scene, study_dir,
                                ["-study_modes", "linear,corotational", "-study_solvers", "direct,cg-gamg",
                                 "-study_rtols", "1e-8", "-study_ranks", "1,2", "-study_levels", "5"], PASSTHROUGH)
    if not checks.check(result.returncode == 0, f"study.py exits 0 (took {seconds:.1f} s)"):
        print(result.stdout[-3000:])
        print(result.stderr[-3000:])
        checks.exit()
    print("\n".join(result.stdout.splitlines()[-24:]))

    # CSV: columns and rows.
    fields, rows = read_csv(os.path.join(study_dir, "study.csv"))
    checks.check(fields[:len(COLUMNS)] == COLUMNS and "status" in fields,
                 f"study.csv columns start with {', '.join(COLUMNS)} and have a status ({fields})")
    expected = {(mode, solver, ranks, dt) for mode in ("linear", "corotational")
                for solver in ("direct", "cg-gamg") for ranks in (1, 2) for dt in DTS}
    keys = [(r["mode"], r["solver"], int(r["ranks"]), float(r["dt"])) for r in rows]
    checks.check(len(rows) == 40 and set(keys) == expected and len(set(keys)) == len(keys),
                 f"study.csv: one row per grid point ({len(rows)} rows, expected 40)")
    checks.check(all(r["status"] == "ok" for r in rows),
                 "every run succeeded (" + "; ".join(r["message"] for r in rows if r["status"] != "ok") + ")")
    checks.check(all(int(r["steps"]) == round(END_TIME / float(r["dt"])) for r in rows),
                 "steps = T / dt in every row")
    checks.check(all((r["rtol"] == "") == (r["solver"] == "direct") for r in rows)
                 and all(float(r["rtol"]) == 1e-8 for r in rows if r["solver"] != "direct"),
                 "rtol empty for the direct solver, 1e-8 for CG + GAMG")
    numeric_ok = all(float(r[c]) >= 0 and math.isfinite(float(r[c])) for r in rows
                     for c in ("setup_s", "loop_s", "iterations", "error_l2", "error_max"))
    checks.check(numeric_ok, "setup_s, loop_s, iterations, error_l2, error_max are finite numbers >= 0")
    direct_iterations = all(int(float(r["iterations"])) == int(r["steps"]) for r in rows if r["solver"] == "direct")
    checks.check(direct_iterations, "direct solver: one 'iteration' (solve) per step")

    def series(mode, solver, ranks, column="error_l2"):
        chosen = sorted((float(r["dt"]), float(r[column])) for r in rows
                        if r["mode"] == mode and r["solver"] == solver and int(r["ranks"]) == ranks
                        and r["status"] == "ok")
        return [c[0] for c in chosen], [c[1] for c in chosen]

    for mode in ("linear", "corotational"):
        for ranks in (1, 2):
            dts, errors = series(mode, "direct", ranks)
            if len(dts) < 2:
                checks.check(False, f"{mode}, direct, {ranks} rank(s): too few runs for an order")
                continue
            order = slope(dts, errors)
            checks.check(ORDER_RANGE[0] <= order <= ORDER_RANGE[1],
                         f"{mode}, direct, {ranks} rank(s): observed order {order:.3f} in "
                         f"[{ORDER_RANGE[0]}, {ORDER_RANGE[1]}] (errors {', '.join(f'{e:.3e}' for e in errors[::-1])})")
            decreasing = all(errors[i] < errors[i + 1] for i in range(len(errors) - 1))
            checks.check(decreasing, f"{mode}, direct, {ranks} rank(s): error decreases as dt is halved")
        for column in ("error_l2", "error_max"):
            _, one = series(mode, "direct", 1, column)
            _, two = series(mode, "direct", 2, column)
            worst = max((abs(a - b) / abs(b) for a, b in zip(one, two)), default=float("inf"))
            checks.check(len(one) == len(two) == 5 and worst <= RANK_AGREEMENT,
                         f"{mode}, direct: 1 vs 2 ranks {column} agree to {worst:.2e} relative "
                         f"(<= {RANK_AGREEMENT:g})")
        # CG + GAMG at 1e-8 is as accurate as the direct solver on this scale.
        _, direct = series(mode, "direct", 2)
        _, gamg = series(mode, "cg-gamg", 2)
        worst = max((abs(a - b) / b for a, b in zip(gamg, direct)), default=float("inf"))
        checks.check(worst <= 1e-3, f"{mode}: CG + GAMG (1e-8) errors match the direct ones to {worst:.2e}")
        checks.check(all(float(r["iterations"]) >= float(r["steps"]) for r in rows
                         if r["mode"] == mode and r["solver"] == "cg-gamg"),
                     f"{mode}: CG + GAMG reports at least one iteration per step")

    # One error recomputed from runs made here, not by the study.
    ref_path = os.path.join(args.work, "check-reference.h5")
    run_path = os.path.join(args.work, "check-coarse.h5")
    harness.run(args, 2, ["-scene", scene, "-mode", "linear", "-dt", REFERENCE_DT,
                          "-steps", round(END_TIME / REFERENCE_DT), "-output", ref_path,
                          "-output_every", round(END_TIME / REFERENCE_DT)] + PASSTHROUGH)
    harness.run(args, 1, ["-scene", scene, "-mode", "linear", "-dt", DTS[0], "-steps", round(END_TIME / DTS[0]),
                          "-output", run_path] + PASSTHROUGH)
    x_ref, rest = final_positions(ref_path)
    x, _ = final_positions(run_path)
    ours_l2 = np.linalg.norm(x - x_ref) / np.linalg.norm(x_ref - rest)
    ours_max = np.sqrt(((x - x_ref) ** 2).sum(axis=1)).max()
    row = next(r for r in rows if r["mode"] == "linear" and r["solver"] == "direct"
               and int(r["ranks"]) == 1 and float(r["dt"]) == DTS[0])
    checks.check(abs(float(row["error_l2"]) - ours_l2) <= 1e-6 * ours_l2
                 and abs(float(row["error_max"]) - ours_max) <= 1e-6 * ours_max,
                 f"linear, direct, 1 rank, dt {DTS[0]}: CSV error_l2 {float(row['error_l2']):.6e} / error_max "
                 f"{float(row['error_max']):.6e} m match this script's {ours_l2:.6e} / {ours_max:.6e} m")

    # Picture and report.
    png = os.path.join(study_dir, "study.png")
    size = harness.png_size(png) if os.path.exists(png) else None
    checks.check(size is not None and size[0] >= 600 and size[1] >= 300
                 and os.path.getsize(png) < 500_000,
                 f"study.png is a valid PNG ({size}, {os.path.getsize(png) if os.path.exists(png) else 0} bytes)")
    md_path = os.path.join(study_dir, "study.md")
    md = open(md_path).read() if os.path.exists(md_path) else ""
    checks.check("Observed order" in md and "Pareto front" in md and "| linear |" in md,
                 "study.md has the orders and the Pareto front")
    checks.check(os.path.isdir(os.path.join(study_dir, "runs"))
                 and len([n for n in os.listdir(os.path.join(study_dir, "runs")) if n.endswith(".h5")]) == 42,
                 "runs/ holds the 40 runs and the 2 references")

    # A study with runs that fail: recorded, not a crash.
    failing_dir = os.path.join(args.work, "study-failing")
    result, seconds = run_study(args, scene, failing_dir,
                                ["--study-modes", "linear", "--solvers", "direct", "cg-jacobi", "-study_rtols=1e-8",
                                 "--ranks", "1", "--study-levels=2"], PASSTHROUGH + ["-ksp_max_it", "1"])
    checks.check(result.returncode == 0, f"study with unconverging runs exits 0 ({seconds:.1f} s)")
    if os.path.exists(os.path.join(failing_dir, "study.csv")):
        _, rows = read_csv(os.path.join(failing_dir, "study.csv"))
        failed = [r for r in rows if r["solver"] == "cg-jacobi"]
        good = [r for r in rows if r["solver"] == "direct"]
        checks.check(len(failed) == 2 and all(r["status"] == "failed" and "did not converge" in r["message"]
                                              and r["error_l2"] == "" for r in failed),
                     "CG + Jacobi with -ksp_max_it 1: both runs recorded as failed with the solver's "
                     f"message ({[r['message'] for r in failed]})")
        checks.check(len(good) == 2 and all(r["status"] == "ok" and r["error_l2"] != "" for r in good),
                     "the direct runs of the same study still succeed")
        md = open(os.path.join(failing_dir, "study.md")).read()
        checks.check("Failed runs: 2" in md and "did not converge" in md, "study.md lists the 2 failed runs")
    else:
        checks.check(False, "study with unconverging runs wrote study.csv\n" + result.stdout + result.stderr)
    adaptive_study(args, checks, scene)
    checks.exit()


def adaptive_study(args, checks, scene):
    """The adaptive configuration at its smallest: bdf2 at two fixed levels and with -dt_adapt -tol 1e-3."""
    study_dir = os.path.join(args.work, "study-adaptive")
    result, seconds = run_study(args, scene, study_dir,
                                ["-study_modes", "linear", "-study_solvers", "direct", "-study_ranks", "1",
                                 "-study_levels", "2", "-study_integrators", "bdf2", "-study_adaptive", "bdf2",
                                 "-study_tols", "1e-3"], PASSTHROUGH)
    if not checks.check(result.returncode == 0, f"adaptive study exits 0 ({seconds:.1f} s)"):
        print(result.stdout, result.stderr)
        return
    _, rows = read_csv(os.path.join(study_dir, "study.csv"))
    adaptive = [r for r in rows if r["tol"] != ""]
    fixed = [r for r in rows if r["tol"] == ""]
    ok = (len(adaptive) == 1 and len(fixed) == 2 and adaptive[0]["status"] == "ok"
          and float(adaptive[0]["tol"]) == 1e-3 and float(adaptive[0]["dt"]) == DTS[0]
          and int(adaptive[0]["accepted_steps"]) >= int(adaptive[0]["steps"])
          and math.isfinite(float(adaptive[0]["error_l2"])))
    checks.check(ok, "study.csv: one adaptive row (bdf2, -tol 1e-3, dt = dt0, substeps >= steps, an error) "
                     f"beside the 2 fixed-dt rows: {adaptive}")
    md = open(os.path.join(study_dir, "study.md")).read()
    checks.check("## Adaptive mode (-dt_adapt)" in md and "| 0.001 |" in md,
                 "study.md has the adaptive section with the -tol 1e-3 row")


if __name__ == "__main__":
    main()
