#!/usr/bin/python3
"""Crossing counts of the contact scenes: runs each scene in each mode and counts,
with softbody-crossings (exact predicates, src/crossings), the intersecting surface
triangles of every written frame; prints a Markdown table (the one in
docs/contact-crossings.md) and writes it, with one JSON report per run, to
-crossings_dir.

The scenes: the project's contact scenes (scenes/contact/: head-on, wedge, sheet,
stack) and the coursework scenes of ../shared/seed-data (stairway, bunny, epcot,
fertility; skipped with a note when the seed data is absent). Each row: frames
written, frames with any crossing, then for each kind the frames it occurs in and
its largest count in a frame (free-free and free-fixed triangle pairs, self pairs
within a body, free surface vertices below the ground), the first clean frame from
which every frame is clean, the run's time loop and contact time (the result
file's loop_seconds and contact_seconds), and the kinetic energy of the last frame
over the gravitational energy of the first (the stack's measure of rest).

Usage:
  crossings_report.py                                    all scenes, both modes, 2 ranks
  crossings_report.py -crossings_cases stack,wedge -crossings_modes corotational
  crossings_report.py -- -friction 0.2                   softbody options for every run
"""
import json
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from softbody_tools import (ROOT, ToolParser, add_option, add_run_options, comma_list,  # noqa: E402
                            flatten, mpi_environment, one_line_error, parse_with_passthrough,
                            softbody_command)

PRACTICAL3 = ["-options_file", os.path.join(ROOT, "config", "practical3.opts")]
# name: (scene, softbody options). "seed:" scenes are under ../shared/seed-data.
CASES = {
    "stairway": ("seed:cggs-cw2-2024/stairway-scene.txt",
                 PRACTICAL3 + ["-friction", "0.5", "-steps", "800", "-output_every", "4"]),
    "bunny": ("seed:infomgp-p3/bunny-scene.txt", PRACTICAL3 + ["-steps", "200"]),
    "epcot": ("seed:infomgp-p3/epcot-scene.txt", PRACTICAL3 + ["-steps", "200"]),
    "fertility": ("seed:infomgp-p3/fertility-scene.txt", PRACTICAL3 + ["-steps", "200"]),
    "head-on": ("scenes/contact/head-on-scene.txt", ["-dt", "0.01", "-steps", "100"]),
    "wedge": ("scenes/contact/wedge-scene.txt", PRACTICAL3 + ["-dt", "0.01", "-steps", "200"]),
    "sheet": ("scenes/contact/sheet-scene.txt", PRACTICAL3 + ["-dt", "0.01", "-steps", "200"]),
    "stack": ("scenes/contact/stack-scene.txt",
              PRACTICAL3 + ["-dt", "0.01", "-steps", "1000", "-output_every", "10"]),
}
KINDS = ("free_free", "free_fixed", "self", "below_ground")


def parse(argv):
    parser = ToolParser(allow_abbrev=False, description=__doc__.split("\n\n")[0],
                        epilog="Options after `--` go to every softbody run.")
    add_run_options(parser)
    add_option(parser, "crossings_cases", metavar="LIST", type=comma_list(str), nargs="+",
               default=[list(CASES)],
               help=f"scenes to run (default: all: {','.join(CASES)})")
    add_option(parser, "crossings_modes", metavar="LIST", type=comma_list(str), nargs="+",
               default=[["linear", "corotational"]], help="softbody -mode values (default linear,corotational)")
    add_option(parser, "crossings_ranks", metavar="N", type=int, default=2, help="MPI ranks per run (default 2)")
    add_option(parser, "crossings_checker", metavar="PATH",
               default=os.path.join(ROOT, "build", "softbody-crossings"),
               help="the checker (default: build/softbody-crossings of this project)")
    add_option(parser, "crossings_shared", metavar="DIR", default=os.path.join(ROOT, "..", "shared"),
               help="the folder holding seed-data/ (default: ../shared beside the project)")
    add_option(parser, "crossings_dir", metavar="DIR", default=os.path.join(ROOT, "build", "crossings"),
               help="results, JSON reports and crossings.md (default: build/crossings)")
    add_option(parser, "crossings_repeat", metavar="N", type=int, default=1,
               help="run each case N times and keep the fastest loop (the machine's load makes "
                    "single runs vary; the counts must agree; default 1)")
    add_option(parser, "crossings_timeout", metavar="S", type=float, default=900,
               help="seconds before a run is stopped (default 900)")
    args = parse_with_passthrough(parser, argv)
    args.crossings_cases = flatten(args.crossings_cases)
    args.crossings_modes = flatten(args.crossings_modes)
    unknown = [c for c in args.crossings_cases if c not in CASES]
    if unknown:
        parser.error(f"-crossings_cases: unknown scene(s) {','.join(unknown)} (known: {','.join(CASES)})")
    if not os.path.exists(args.crossings_checker):
        parser.error(f"-crossings_checker: {args.crossings_checker} not found (built only with CGAL: "
                     "Debian's libcgal-dev)")
    return args


def scene_path(args, scene):
    if scene.startswith("seed:"):
        return os.path.join(args.crossings_shared, "seed-data", scene[len("seed:"):])
    return os.path.join(ROOT, scene)


def run_case(args, name, mode):
    """Runs one scene in one mode -crossings_repeat times and checks each result; returns
    the table row's figures (the fastest loop and contact times of the runs)."""
    rows = [run_once(args, name, mode) for _ in range(max(1, args.crossings_repeat))]
    row = rows[-1]
    for key in ("loop_seconds", "contact_seconds"):
        times = [r[key] for r in rows if r.get(key) is not None]
        row[key] = min(times) if times else None
    counts = {json.dumps([[frame[k] for k in KINDS] for frame in r["report"]["frames"]])
              for r in rows if "report" in r}
    if len(counts) > 1:
        row["note"] = f"the counts differ between the {len(rows)} runs"
    return row


def run_once(args, name, mode):
    """Runs one scene in one mode and checks it."""
    scene, options = CASES[name]
    path = scene_path(args, scene)
    row = {"scene": name, "mode": mode}
    if not os.path.exists(path):
        row["note"] = f"skipped: {path} not found"
        return row
    out = os.path.join(args.crossings_dir, f"{name}-{mode}.h5")
    for old in (out, out[:-3] + ".xdmf"):
        if os.path.exists(old):
            os.remove(old)
    command = softbody_command(args.mpiexec, args.crossings_ranks, args.softbody,
                               ["-scene", path, "-mode", mode, *options, "-output", out, "-quiet",
                                *args.extra])
    start = time.time()
    try:
        run = subprocess.run(command, capture_output=True, text=True, timeout=args.crossings_timeout,
                             env=mpi_environment())
        if run.returncode != 0:
            row["note"] = "run failed: " + one_line_error(run.stdout + run.stderr, run.returncode)
    except subprocess.TimeoutExpired:
        row["note"] = f"run stopped after {args.crossings_timeout:g} s"
    row["wall_seconds"] = time.time() - start
    if os.path.exists(out):
        row.update(check(args, out))
    return row


def check(args, out):
    """The checker's report of a result file, and the run's figures from the file."""
    import h5py
    report_path = out[:-3] + "-crossings.json"
    run = subprocess.run([args.crossings_checker, out, "-json", report_path], capture_output=True,
                         text=True, timeout=args.crossings_timeout)
    if run.returncode != 0:
        return {"note": "check failed: " + one_line_error(run.stdout + run.stderr, run.returncode)}
    with open(report_path) as f:
        report = json.load(f)
    figures = {"report": report}
    with h5py.File(out, "r") as f:
        figures["loop_seconds"] = f.attrs.get("loop_seconds")
        figures["contact_seconds"] = f.attrs.get("contact_seconds")
        kinetic, gravitational = f["energy/kinetic"][...], f["energy/gravitational"][...]
        if len(kinetic) and gravitational[0] > 0:
            figures["rest"] = kinetic[-1] / gravitational[0]
    return figures


def cell(value, digits=3):
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def table(rows):
    head = ("| scene | mode | frames | with crossings | free-free | free-fixed | self | below ground "
            "| clean from | loop (contact) s | KE end / E_grav start |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for row in rows:
        report = row.get("report")
        if not report:
            lines.append(f"| {row['scene']} | {row['mode']} | {row.get('note', '-')} |" + " |" * 9)
            continue
        kinds = []
        for kind in KINDS:
            summary = report["kinds"][kind]
            if kind == "below_ground" and report["ground_y"] is None:
                kinds.append("no ground")
            elif summary["frames"] == 0:
                kinds.append("0")
            elif kind == "below_ground":
                kinds.append(f"{summary['frames']} / {summary['max']} ({report['max_ground_depth']:.1g} m)")
            else:
                kinds.append(f"{summary['frames']} / {summary['max']}")
        clean = report["clean_from_frame"]
        loop = f"{cell(row.get('loop_seconds'))} ({cell(row.get('contact_seconds'))})"
        note = f" ({row['note']})" if row.get("note") else ""
        lines.append(f"| {row['scene']} | {row['mode']}{note} | {report['frames_checked']} "
                     f"| {report['frames_with_crossings']} | " + " | ".join(kinds)
                     + f" | {'never' if clean < 0 else clean} | {loop} | {cell(row.get('rest'))} |")
    return "\n".join(lines)


def main(argv=None):
    args = parse(sys.argv[1:] if argv is None else argv)
    os.makedirs(args.crossings_dir, exist_ok=True)
    load = os.getloadavg()
    rows = []
    for name in args.crossings_cases:
        for mode in args.crossings_modes:
            row = run_case(args, name, mode)
            rows.append(row)
            print(f"{name} {mode}: {row.get('note') or 'done'} ({row.get('wall_seconds', 0):.1f} s)",
                  file=sys.stderr, flush=True)
    text = table(rows)
    legend = ("Kinds: frames with it / largest count in a frame (triangle pairs; below ground: "
              f"vertices, and the deepest). {args.crossings_ranks} ranks; the fastest loop of "
              f"{args.crossings_repeat} run(s); load average {load[0]:.1f} at the start, "
              f"{os.getloadavg()[0]:.1f} at the end; softbody options after the scene's: "
              f"{' '.join(args.extra) or 'none'}.")
    with open(os.path.join(args.crossings_dir, "crossings.md"), "w") as f:
        f.write(text + "\n\n" + legend + "\n")
    with open(os.path.join(args.crossings_dir, "crossings.json"), "w") as f:
        json.dump([{k: v for k, v in row.items() if k != "report"} | {"summary": {
            k: v for k, v in row.get("report", {}).items() if k != "frames"}} for row in rows], f, indent=1)
    print(text)
    print()
    print(legend)
    return 0


if __name__ == "__main__":
    sys.exit(main())
