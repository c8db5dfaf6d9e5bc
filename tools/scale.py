#!/usr/bin/python3
"""Scaling on this machine: per-rank memory, set-up by stage and message volume per step.

Runs softbody over two series of box meshes (tools/box_mesh.py, 6 Kuhn tets per
cubic cell):
  strong  one mesh of -scale_tets tets (default 1e6), a 4 x 1 x 1 m beam, at
          every rank count of -scale_ranks (default 1,2,4,8,16);
  weak    -scale_tets_per_rank tets per rank (default 1e5): a P x 1 x 1 m beam
          at P ranks, so that every rank's part is about a unit cube of the same
          cells and an interior part has two neighbours whatever P is;
each in the modes -scale_modes (linear, corotational) and with -scale_contact
  off  one body, its end faces struck at +-1 m/s along z (as ./run bench);
  on   the same tets as two bodies of half the height stacked along y, under
       gravity (0, -9.81, 0) m/s^2 on a ground at y = 0: the lower one rests
       on the ground, the upper one falls onto it (two free bodies that can
       meet: the contact path whose halos follow the bodies).

Every point is run twice, -steps 1 and -steps 1 + S (S = -scale_steps); the long
run minus the short one, over S, is the traffic of a step, the short run is the
set-up's (with the first step). Measured from outside the program:
  - /usr/bin/time -f %M around every rank: each rank's peak resident set (MB);
  - PETSc's log: the point-to-point messages and bytes PETSc sends (its halo
    exchanges and scatters) on every rank (softbody's -log_rank_messages lines),
    and from the -log_view summary the time of each softbody log stage
    (src/app/log_stages.hpp);
  - Open MPI's monitoring components (pml_monitoring_enable 2, one file per rank):
    the bytes and messages each rank sends inside collectives (reductions,
    broadcasts, the boxes contact gathers), and the point-to-point messages
    outside persistent requests: softbody's own contact halos. (Open MPI 4.1's
    monitoring does not count messages on persistent requests, which PETSc's halo
    exchanges use; hence PETSc's own count for those.)
  - softbody's run summary: the time loop per step.
Ranks are oversubscribed on a machine with fewer cores: memory and message
volume are what the program does; times are only rough.

Writes into -scale_dir DIR (default build/scale/): scale.csv (one row per point),
scale-ranks.csv (one row per rank of each point), scale.md (tables, the fitted
model and its prediction at 1e8 tets on 1000 ranks), scale.png, command.txt,
meshes/ (reused when present) and runs/ (logs and the raw per-rank files).
-scale_report rewrites scale.md and scale.png from the CSV files without running.
docs/scaling.md explains every column.

Safety: a run whose predicted total memory (from the points measured before it
with the same mode and contact: the fitted memory model once there are three,
else a guess from the measured CG + GAMG series scaled to the points measured; 20 % margin) exceeds
-scale_max_memory_gb or the machine's available memory is skipped, and a run
whose ranks together grow past -scale_max_memory_gb, or that leaves the machine
less than 1 GB, is stopped; both are recorded. The solver options file
-scale_solver_options (default: softbody's own defaults) goes to every run and
is recorded in scale.csv.

Usage (from the project root; ./run scale passes -softbody build/softbody):
  ./run scale -scale_solver_options config/cg-gamg.opts
  ./run scale -scale_quick -scale_dir /tmp/scale      # small meshes at 1, 2, 3 ranks
  ./run scale -scale_series weak -scale_ranks 1,2,4 -scale_modes linear
Options after `--` go to every softbody run. Lists take commas or spaces.
Needs Debian's /usr/bin/python3 with python3-numpy and python3-matplotlib,
/usr/bin/time and Open MPI (its pml/coll monitoring components).
"""
import argparse
import csv
import math
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import box_mesh  # noqa: E402
from softbody_tools import (ToolParser, ROOT, add_option, add_run_options, comma_list, flatten,  # noqa: E402
                            mpi_environment, one_line_error, parse_with_passthrough)

SERIES = ("strong", "weak")
MODES = ("linear", "corotational")
CONTACT = ("off", "on")
STRONG_BEAM = (4.0, 1.0, 1.0)  # m; the weak beam is (P, 1, 1)
MATERIAL = {"density": 1000.0, "young": 1e6, "poisson": 0.4}
STRIKE_SPEED = 1.0  # m/s, +z at x = 0, -z at the far end (no contact)
GRAVITY = "0,-9.81,0"  # m/s^2 (contact)
# Contact: the lower body starts this far above the ground and the upper one this
# far above the lower (m): within the first steps' fall (g dt^2 ~ 1 mm at dt = 0.01 s).
GROUND_GAP = 1e-3
BODY_GAP = 2e-3
DT = 0.01  # s
SHORT_STEPS = 1  # the short run: set-up and the first step (which factorises)
TIME = "/usr/bin/time"
# Quick subset for the test suite: small meshes at 1, 2 and 3 ranks.
QUICK = {"tets": 6000, "tets_per_rank": 3000, "ranks": [1, 2, 3], "steps": 2, "modes": ["linear"]}
FULL = {"tets": 1000000, "tets_per_rank": 100000, "ranks": [1, 2, 4, 8, 16], "steps": 3, "modes": list(MODES)}
# Until three points of a mode are measured, a rank's peak memory is guessed as
# this constant, plus this much per tet of the whole mesh (what every rank held
# before the meshes went into slabs, and still holds with contact: the scene and
# the numbering; an over-estimate without contact, which only makes the guard
# careful), plus this much per tet of its share (matrix,
# preconditioner, vectors): the 1e6-tet strong series with CG + GAMG measured
# 1495 MB on 1 rank and 256 MB per rank on 16, i.e. about 173 MB held by every rank
# and 1322 MB shared. A direct factor needs more: the running guard (stop when the
# ranks together grow past -scale_max_memory_gb) is the safety net.
GUESS_BASE_MB = 50.0
GUESS_REPLICATED_MB_PER_TET = 1.3e-4
GUESS_SHARED_MB_PER_TET = 1.4e-3
# Memory poll interval of a running point (s) and the prediction's margin.
POLL_S = 0.5
PREDICTION_MARGIN = 1.2
# A run is stopped when the machine has less than this left (MB): other users' work
# must not be killed by the kernel's out-of-memory killer.
MIN_AVAILABLE_MB = 1024
# The model's target: 1e8 tets on 1000 ranks.
TARGET_TETS = 1e8
TARGET_RANKS = 1000
# Faces of a compact part inside a 3D partition (a cube's six), each with a halo like
# the weak series' parts' faces; edge and corner neighbours add little.
COMPACT_PART_FACES = 6

COLUMNS = ["series", "mode", "contact", "ranks", "tets", "vertices", "tets_per_rank", "solver_options", "steps",
           "mem_max_mb", "mem_mean_mb", "mem_min_mb", "mem_rank0_mb", "mem_sum_mb", "mem_imbalance", "mem_file_mb",
           "setup_s", "assembly_s", "factorisation_s", "contact_s", "loop_s_per_step", "setup_bytes_mean",
           "step_bytes_max", "step_bytes_mean", "step_bytes_min", "step_msgs_mean",
           "step_p2p_bytes_max", "step_p2p_bytes_mean", "step_p2p_bytes_min",
           "step_coll_bytes_max", "step_coll_bytes_mean", "step_coll_bytes_min", "step_mpi_p2p_bytes_max",
           "step_mpi_p2p_bytes_mean", "step_mpi_p2p_bytes_min",
           "load_avg", "status", "message"]
RANK_COLUMNS = ["series", "mode", "contact", "ranks", "tets", "rank", "mem_mb", "setup_coll_bytes",
                "step_p2p_bytes", "step_p2p_msgs", "step_coll_bytes", "step_coll_msgs", "step_mpi_p2p_bytes",
                "step_mpi_p2p_msgs", "step_bytes"]
# softbody's log stages (src/app/log_stages.hpp) -> columns: each stage's time in the
# long run, the slowest rank's (s).
STAGES = {"Set-up": "setup_s", "Assembly": "assembly_s", "Factorisation": "factorisation_s", "Contact": "contact_s"}


# ----------------------------------------------------------------------------- arguments

def _count(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text}: not a number")
    if not (value >= 1 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"{text}: a tet count must be at least 1")
    return int(round(value))


def _choices(parser, option, values, allowed):
    for value in values:
        if value not in allowed:
            parser.error(f"{option}: unknown value {value!r} (choose from {', '.join(allowed)})")


class OneLineErrors(ToolParser):
    """An option error is one line, "scale.py: error: ...", and exit status 2."""

    def error(self, message):
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        sys.exit(2)


def parse_arguments(argv):
    parser = OneLineErrors(
        prog="scale.py", allow_abbrev=False,
        description="softbody scaling on this machine: per-rank peak memory, set-up by stage, bytes and "
                    "messages per step and rank, strong and weak series; writes scale.csv, scale-ranks.csv, scale.md, "
                    "scale.png.",
        epilog="Options after `--` go to every softbody run. Lists take commas or spaces.")
    add_option(parser, "scale_series", "-series", dest="series", metavar="NAME", nargs="+", type=comma_list(str),
               default=[list(SERIES)], help="series to run: strong, weak (default both)")
    add_option(parser, "scale_ranks", "-ranks", dest="ranks", metavar="P", nargs="+", type=comma_list(int),
               default=None, help="rank counts (default 1,2,4,8,16; quick 1,2,3)")
    add_option(parser, "scale_tets", "-tets", dest="tets", metavar="N", type=_count, default=None,
               help="tets of the strong series' mesh (default 1e6; quick 6e3)")
    add_option(parser, "scale_tets_per_rank", "-tets_per_rank", dest="tets_per_rank", metavar="N", type=_count,
               default=None, help="tets per rank of the weak series (default 1e5; quick 3e3)")
    add_option(parser, "scale_modes", "-modes", dest="modes", metavar="MODE", nargs="+", type=comma_list(str),
               default=None, help="elasticity modes (default linear,corotational; quick linear)")
    add_option(parser, "scale_contact", "-contact", dest="contact", metavar="off|on", nargs="+",
               type=comma_list(str), default=[list(CONTACT)], help="without and/or with contact (default off,on)")
    add_option(parser, "scale_steps", "-steps", dest="steps", metavar="S", type=int, default=None,
               help="steps of the long run beyond the short run's one; per-step figures are the difference "
                    "over S (default 3; quick 2)")
    add_option(parser, "scale_quick", "-quick", dest="quick", action="store_true",
               help="the quick subset: 6e3-tet strong mesh, 3e3 tets per rank, ranks 1,2,3, 2 steps, linear mode")
    add_option(parser, "scale_solver_options", "-solver_options", dest="solver_options", metavar="FILE",
               default="default", help="options file for every run, e.g. config/cg-gamg.opts "
                                       "(default: 'default', softbody's compiled-in solvers)")
    add_option(parser, "scale_report", "-report", dest="report_only", action="store_true",
               help="run nothing: rewrite scale.md and scale.png from the folder's scale.csv and scale-ranks.csv")
    add_option(parser, "scale_max_memory_gb", "-max_memory_gb", dest="max_memory_gb", metavar="GB", type=float,
               default=18.0, help="skip a run predicted to need more in total, stop one that grows past it "
                                  "(default 18)")
    add_option(parser, "scale_timeout", "-timeout", dest="timeout", metavar="S", type=float, default=3600,
               help="seconds after which a run is stopped and recorded as failed (default 3600)")
    add_run_options(parser)
    add_option(parser, "scale_dir", "-study_dir", "--study-dir", dest="study_dir", metavar="DIR",
               default=os.path.join(ROOT, "build", "scale"),
               help="output folder for scale.csv, scale-ranks.csv, scale.md, scale.png, meshes/, runs/ "
                    "(default build/scale)")
    args = parse_with_passthrough(parser, argv)
    preset = QUICK if args.quick else FULL
    args.ranks = flatten(args.ranks) if args.ranks else preset["ranks"]
    args.tets = args.tets or preset["tets"]
    args.tets_per_rank = args.tets_per_rank or preset["tets_per_rank"]
    args.steps = args.steps if args.steps is not None else preset["steps"]
    args.modes = flatten(args.modes) if args.modes else preset["modes"]
    args.series, args.contact = flatten(args.series), flatten(args.contact)
    _choices(parser, "-scale_series", args.series, SERIES)
    _choices(parser, "-scale_modes", args.modes, MODES)
    _choices(parser, "-scale_contact", args.contact, CONTACT)
    if not args.ranks or any(p < 1 for p in args.ranks):
        parser.error("-scale_ranks: rank counts must be positive")
    if args.steps < 1:
        parser.error("-scale_steps must be at least 1")
    if args.tets < 12 or args.tets_per_rank < 12:
        parser.error("-scale_tets and -scale_tets_per_rank must be at least 12 (two bodies of one cell)")
    if not (args.max_memory_gb > 0 and math.isfinite(args.max_memory_gb)):
        parser.error("-scale_max_memory_gb must be positive")
    if args.solver_options != "default":
        args.solver_options = os.path.abspath(args.solver_options)
        if not os.path.isfile(args.solver_options):
            parser.error(f"-scale_solver_options: no file {args.solver_options}")
    args.softbody = os.path.abspath(args.softbody)
    if not (os.path.isfile(args.softbody) and os.access(args.softbody, os.X_OK)):
        parser.error(f"softbody executable {args.softbody} not found (build first: ./run build)")
    if shutil.which(args.mpiexec) is None:
        parser.error(f"MPI launcher {args.mpiexec} not found")
    if not os.access(TIME, os.X_OK):
        parser.error(f"{TIME} not found (Debian package time)")
    args.study_dir = os.path.abspath(args.study_dir)
    return args


# ----------------------------------------------------------------------------- meshes and scenes

def body_box(series, ranks):
    """The box (m) of the body without contact: the strong beam, or the weak P x 1 x 1 beam."""
    return STRONG_BEAM if series == "strong" else (float(ranks), 1.0, 1.0)


def write_mesh(folder, size, tets):
    """folder/box-LX-LY-LZ-N.mesh (reused when present). Returns (path, vertices, tets, cells)."""
    os.makedirs(folder, exist_ok=True)
    cells = box_mesh.cells_for_tets(size, tets)
    name = "box-" + "-".join(f"{s:g}" for s in size) + f"-{tets}.mesh"
    path = os.path.join(folder, name)
    vertices, elements = box_mesh.box_mesh(size, cells)
    if not os.path.exists(path):
        faces = box_mesh.boundary_faces(elements, len(vertices))
        refs = box_mesh.side_of_faces(vertices, faces, size)
        box_mesh.write_medit(path + ".part", vertices, elements, faces, refs)
        os.replace(path + ".part", path)
    return path, vertices, elements


def _body_line(mesh, centroid):
    return (f"{os.path.basename(mesh)} {MATERIAL['density']!r} {MATERIAL['young']!r} {MATERIAL['poisson']!r} 0  "
            + " ".join(repr(float(c)) for c in centroid) + "  1 0 0 0\n")


def write_scene(folder, series, ranks, tets, contact):
    """The scene of one point; returns (scene path, total tets, total vertices, extra softbody options)."""
    size = body_box(series, ranks)
    scene = os.path.join(folder, f"{series}-{ranks if series == 'weak' else 'all'}-{tets}-contact-{contact}.txt")
    if contact == "off":
        mesh, vertices, elements = write_mesh(folder, size, tets)
        left = np.flatnonzero(vertices[:, 0] <= 1e-12)
        right = np.flatnonzero(vertices[:, 0] >= size[0] - 1e-12)
        with open(scene, "w") as f:
            f.write(f"# softbody scale: {size[0]:g} x {size[1]:g} x {size[2]:g} m box, {len(elements)} tets, "
                    f"end faces struck at +-{STRIKE_SPEED:g} m/s along z\n1\n")
            f.write(_body_line(mesh, (0.0, 0.0, 0.0)))
            f.write(f"{len(left) + len(right)}\n")
            f.writelines(f"0 {v} 0 0 {STRIKE_SPEED!r}\n" for v in left)
            f.writelines(f"0 {v} 0 0 {-STRIKE_SPEED!r}\n" for v in right)
        return scene, len(elements), len(vertices), []
    half = (size[0], size[1] / 2, size[2])
    mesh, vertices, elements = write_mesh(folder, half, max(6, tets // 2))
    lower = half[1] / 2 + GROUND_GAP
    upper = lower + half[1] + BODY_GAP
    with open(scene, "w") as f:
        f.write(f"# softbody scale: two {half[0]:g} x {half[1]:g} x {half[2]:g} m boxes of {len(elements)} tets "
                f"stacked along y above a ground at y = 0, under gravity\n2\n")
        f.write(_body_line(mesh, (0.0, lower, 0.0)))
        f.write(_body_line(mesh, (0.0, upper, 0.0)))
    return scene, 2 * len(elements), 2 * len(vertices), ["-gravity", GRAVITY, "-ground", "0"]


# ----------------------------------------------------------------------------- one run

def read_monitoring(prefix, ranks):
    """Per rank: bytes and messages sent to other ranks by collectives ("I" lines: the
    point-to-point traffic Open MPI's collectives generate) and by point-to-point calls
    on non-persistent requests ("E" lines), from Open MPI's monitoring files
    PREFIX.RANK.prof (pml_monitoring_enable 2). Open MPI 4.1's monitoring does not see
    messages on persistent requests (MPI_Start), which PETSc's halo exchanges use:
    read_petsc_log counts those."""
    sent = []
    for rank in range(ranks):
        counts = {"coll_bytes": 0, "coll_msgs": 0, "mpi_p2p_bytes": 0, "mpi_p2p_msgs": 0}
        with open(f"{prefix}.{rank}.prof") as f:
            for line in f:
                fields = line.split("\t")
                if len(fields) < 5 or fields[0] not in ("E", "I"):
                    continue
                if int(fields[1]) == int(fields[2]):
                    continue  # a rank's messages to itself do not leave it
                kind = "coll" if fields[0] == "I" else "mpi_p2p"
                counts[kind + "_bytes"] += int(fields[3].split()[0])
                counts[kind + "_msgs"] += int(fields[4].split()[0])
        sent.append(counts)
    return sent


def read_petsc_summary(text, ranks):
    """From softbody's output: the point-to-point messages and bytes PETSc logged on
    every rank (its -log_rank_messages lines, counted as -log_view counts them: every
    message a rank sends or receives, its halo exchanges on persistent requests
    included, and half the sum: what a rank sends in a symmetric exchange), lists
    indexed by rank; and from -log_view's summary (printed by rank 0) the slowest
    rank's run time (s) and each log stage's time (s, mean over ranks)."""
    summary = {"time_s": 0.0, "p2p_msgs": [0.0] * ranks, "p2p_bytes": [0.0] * ranks, "stages": {}}
    number = r"([0-9.]+e[+-]\d+)"
    time_line = re.search(r"^Time \(sec\):\s+" + number, text, re.M)
    if time_line:
        summary["time_s"] = float(time_line.group(1))
    for rank, msgs, length in re.findall(r"^\s*messages\s+rank (\d+): (\d+) messages, (\d+) bytes", text, re.M):
        if int(rank) < ranks:
            # PETSc adds the length of a persistent send it starts with no message in it
            # (a one-rank run shows bytes and 0 messages): no message, no bytes.
            summary["p2p_msgs"][int(rank)] = float(msgs)
            summary["p2p_bytes"][int(rank)] = float(length) if int(msgs) > 0 else 0.0
    block = text.split("Summary of Stages:", 1)
    for line in block[1].splitlines()[2:] if len(block) == 2 else []:
        match = re.match(r"\s*\d+:\s+(.+?):\s+" + number, line)
        if not match:
            break
        summary["stages"][match.group(1)] = float(match.group(2))
    return summary


def read_peak_memory(prefix, ranks):
    """Per rank: the peak resident set (MB) that /usr/bin/time -f %M (kB) wrote to PREFIX.RANK."""
    peaks = []
    for rank in range(ranks):
        with open(f"{prefix}.{rank}") as f:
            numbers = [line.strip() for line in f if line.strip().isdigit()]
        peaks.append(int(numbers[-1]) / 1024.0)
    return peaks


def descendants(root_pid):
    """{pid: (command name, resident set in MB)} of root_pid's descendants (the ranks under mpirun)."""
    children, found = {}, {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                name, rest = f.read().split(" (", 1)[1].rsplit(")", 1)
            fields = rest.split()
            children.setdefault(int(fields[1]), []).append(int(entry))
            found[int(entry)] = (name, int(fields[21]) * os.sysconf("SC_PAGE_SIZE") / 2**20)
        except (OSError, IndexError, ValueError):
            continue
    result, stack = {}, list(children.get(root_pid, []))
    while stack:
        pid = stack.pop()
        if pid in found:
            result[pid] = found[pid]
        stack.extend(children.get(pid, []))
    return result


def file_pages_mb(pid):
    """RssFile of /proc/PID/status (MB): the resident pages mapped from files, almost all
    of them shared libraries' code and data, which the ranks of one machine share."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("RssFile:"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return None


def run_softbody(args, command, log_path):
    """Runs command, stopping it past -scale_timeout or when its ranks together hold more
    than -scale_max_memory_gb. Returns (output, exit code or None, reason when stopped,
    the ranks' largest file-backed resident set sampled while they ran (MB, mean over
    the ranks; None when no sample caught them))."""
    name = os.path.basename(args.softbody)[:15]  # /proc's command names are cut at 15
    file_mb = {}
    with open(log_path + ".out", "w") as out:
        proc = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, env=mpi_environment(), cwd=ROOT,
                                start_new_session=True)
        started, reason = time.time(), ""
        while proc.poll() is None:
            time.sleep(POLL_S)
            processes = descendants(proc.pid)
            for pid, (command_name, _) in processes.items():
                pages = file_pages_mb(pid) if command_name == name else None
                if pages is not None:
                    file_mb[pid] = max(file_mb.get(pid, 0.0), pages)
            if time.time() - started > args.timeout:
                reason = f"stopped after {args.timeout:g} s"
            elif sum(rss for _, rss in processes.values()) > 1024 * args.max_memory_gb:
                reason = f"stopped: the ranks held more than {args.max_memory_gb:g} GB together"
            elif available_mb() < MIN_AVAILABLE_MB:
                reason = f"stopped: less than {MIN_AVAILABLE_MB} MB of memory left on the machine"
            if reason:
                os.killpg(proc.pid, 9)
                proc.wait()
                break
    with open(log_path + ".out") as f:
        output = f.read()
    os.remove(log_path + ".out")
    shared = float(np.mean(list(file_mb.values()))) if file_mb else None
    return output, (None if reason else proc.returncode), reason, shared


def measure(args, scene, extra, mode, ranks, steps, stem):
    """One run of `steps` steps with the per-rank probes; returns (output, code, reason,
    file-backed MB per rank) as run_softbody."""
    for name in os.listdir(os.path.dirname(stem)):
        if name.startswith(os.path.basename(stem) + "."):
            os.remove(os.path.join(os.path.dirname(stem), name))
    options = ["-scene", scene, "-mode", mode, "-dt", repr(DT), "-steps", str(steps),
               "-log_view", "-log_rank_messages"] + extra
    if args.solver_options != "default":
        options = ["-options_file", args.solver_options] + options
    rank_command = ["sh", "-c", f'exec {TIME} -f %M -o "$0.$OMPI_COMM_WORLD_RANK" "$@"', stem + ".rss",
                    args.softbody] + options + list(args.extra)
    command = [args.mpiexec, "-n", str(ranks), "--mca", "pml_monitoring_enable", "2",
               "--mca", "pml_monitoring_enable_output", "3", "--mca", "pml_monitoring_filename", stem + ".mon"]
    output, code, reason, shared = run_softbody(args, command + rank_command, stem)
    with open(stem + ".log", "w") as log:
        log.write(shlex.join(command + rank_command) + "\n\n" + output)
    return output, code, reason, shared


def predicted_rank_mb(rows, mode, contact, tets, ranks):
    """A rank's peak memory (MB) predicted for `tets` tets on `ranks` ranks from the points
    measured so far with the same mode and contact: the fitted model (fit_memory) once
    there are three, else the guess above scaled to the largest measured point (its
    measured peak over the guess's, at least 1)."""
    measured = [r for r in rows if r["status"] == "ok" and r["mode"] == mode and r["contact"] == contact]
    if len(measured) >= 3:
        return memory_model(fit_memory(measured), tets, ranks)

    def guess(tets, ranks):
        return GUESS_BASE_MB + GUESS_REPLICATED_MB_PER_TET * tets + GUESS_SHARED_MB_PER_TET * tets / ranks

    scale = max([1.0] + [r["mem_max_mb"] / guess(r["tets"], r["ranks"]) for r in measured])
    return scale * guess(tets, ranks)


def available_mb():
    """MemAvailable of /proc/meminfo (MB)."""
    with open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) / 1024
    return float("inf")


def run_point(args, rows, rank_rows, series, mode, contact, ranks):
    target = args.tets if series == "strong" else args.tets_per_rank * ranks
    meshes = os.path.join(args.study_dir, "meshes")
    scene, tets, vertices, extra = write_scene(meshes, series, ranks, target, contact)
    row = {"series": series, "mode": mode, "contact": contact, "ranks": ranks, "tets": tets, "vertices": vertices,
           "tets_per_rank": round(tets / ranks), "steps": args.steps, "status": "failed", "message": "",
           "solver_options": os.path.relpath(args.solver_options, ROOT) if args.solver_options != "default"
           else "default"}
    predicted_gb = PREDICTION_MARGIN * ranks * predicted_rank_mb(rows, mode, contact, tets, ranks) / 1024
    if predicted_gb > min(args.max_memory_gb, available_mb() / 1024):
        row["status"], row["message"] = "skipped", (f"predicted {predicted_gb:.1f} GB in total, above "
                                                    f"-scale_max_memory_gb {args.max_memory_gb:g} or the "
                                                    f"{available_mb() / 1024:.1f} GB available")
        return row
    stem = os.path.join(args.study_dir, "runs", f"{series}-{mode}-contact-{contact}-{ranks}")
    results = {}
    for label, steps in (("short", SHORT_STEPS), ("long", SHORT_STEPS + args.steps)):
        output, code, reason, shared = measure(args, scene, extra, mode, ranks, steps, f"{stem}-{label}")
        if code != 0:
            row["message"] = f"{label} run: " + (reason or one_line_error(output, code))
            if reason.startswith("stopped:"):
                row["status"] = "stopped"
            return row
        results[label] = (read_petsc_summary(output, ranks), read_monitoring(f"{stem}-{label}.mon", ranks),
                          read_peak_memory(f"{stem}-{label}.rss", ranks), output)
        if shared is not None:
            row["mem_file_mb"] = shared
    fill_measurements(args, row, results, rank_rows)
    return row


def fill_measurements(args, row, results, rank_rows):
    """Fills row (and appends to rank_rows) from the short and long runs' results:
    (PETSc summary, Open MPI monitoring, peak memory per rank, output) each."""
    ranks = row["ranks"]
    long_log, short_log = results["long"][0], results["short"][0]
    long_sent, short_sent = results["long"][1], results["short"][1]
    memory = results["long"][2]
    for stage, column in STAGES.items():
        row[column] = long_log["stages"].get(stage, 0.0)
    loop = re.search(r"time loop ([0-9.]+) s", results["long"][3])
    row["loop_s_per_step"] = float(loop.group(1)) / (SHORT_STEPS + args.steps) if loop else 0.0

    def step(long_value, short_value):
        return max(0.0, (long_value - short_value) / args.steps)
    per_rank = []
    for rank in range(ranks):
        per_rank.append({**{key: row[key] for key in ("series", "mode", "contact", "ranks", "tets")}, "rank": rank,
                         "mem_mb": memory[rank], "setup_coll_bytes": short_sent[rank]["coll_bytes"],
                         **{"step_" + key: step(long_log[key][rank], short_log[key][rank])
                            for key in ("p2p_bytes", "p2p_msgs")},
                         **{"step_" + key: step(long_sent[rank][key], short_sent[rank][key])
                            for key in ("coll_bytes", "coll_msgs", "mpi_p2p_bytes", "mpi_p2p_msgs")}})
        # Bytes of a rank: PETSc's (persistent requests), the collectives' and softbody's
        # own point-to-point (the contact halos, non-persistent; PETSc sends almost
        # nothing on non-persistent requests: 18 kB per step at 8 ranks before the halos).
        per_rank[-1]["step_bytes"] = sum(per_rank[-1]["step_" + key]
                                         for key in ("p2p_bytes", "coll_bytes", "mpi_p2p_bytes"))
    rank_rows.extend(per_rank)
    mem = np.array(memory)
    row.update(mem_max_mb=mem.max(), mem_mean_mb=mem.mean(), mem_min_mb=mem.min(), mem_rank0_mb=mem[0],
               mem_sum_mb=mem.sum(), mem_imbalance=mem.max() / mem.mean(), status="ok")
    for name in ("step_bytes", "step_p2p_bytes", "step_coll_bytes", "step_mpi_p2p_bytes"):
        values = np.array([r[name] for r in per_rank])  # max and min over the ranks' own figures
        row.update({f"{name}_max": values.max(), f"{name}_mean": values.mean(), f"{name}_min": values.min()})
    row.update(step_msgs_mean=np.mean([r["step_p2p_msgs"] + r["step_coll_msgs"] + r["step_mpi_p2p_msgs"]
                                       for r in per_rank]),
               setup_bytes_mean=np.mean(short_log["p2p_bytes"]) + np.mean([r["setup_coll_bytes"] for r in per_rank]))


# ----------------------------------------------------------------------------- model

def fit_memory(rows):
    """Least-squares fit (relative) of a rank's peak memory, mem = a + b N + c N / P (MB; N tets):
    a the program and libraries, b what every rank holds of the whole scene, c its
    share. Coefficients clipped at 0. None with fewer than three points."""
    if len(rows) < 3:
        return None
    N = np.array([r["tets"] for r in rows], float)
    P = np.array([r["ranks"] for r in rows], float)
    measured = np.array([r["mem_max_mb"] for r in rows], float)
    # Relative residuals: the small points weigh as much as the big ones.
    A = np.column_stack([np.ones_like(N), N, N / P]) / measured[:, None]
    return _nonnegative_lstsq(A, np.ones_like(measured))


def fit_halo(rows):
    """Bytes a rank sends per step across one face of its part, and the tets of that
    part, from the weak series (point-to-point only): at its largest P >= 3 the
    rank that sends most is an interior part with two faces; at P = 2 each part has
    one. None without a weak point at P > 1."""
    weak = {r["ranks"]: r for r in rows if r["series"] == "weak" and r["ranks"] > 1}
    if not weak:
        return None
    largest = max(weak)
    faces = 2 if largest >= 3 else 1
    return weak[largest]["step_p2p_bytes_max"] / faces, weak[largest]["tets"] / largest


def fit_gathered(rows):
    """Least-squares e in: the bytes a rank sends inside collectives per step (mean over
    ranks) = e N (P - 1) / P, what an allgather of the whole state costs a rank (it sends
    (P - 1) / P of the whole); clipped at 0. Also the largest relative deviation over
    the points. None without a point at P > 1."""
    rows = [r for r in rows if r["ranks"] > 1]
    if not rows:
        return None
    x = np.array([r["tets"] * (r["ranks"] - 1) / r["ranks"] for r in rows], float)
    y = np.array([r["step_coll_bytes_mean"] for r in rows], float)
    e = max(0.0, float(x @ y / (x @ x)))
    return e, float(np.max(np.abs(e * x - y) / np.maximum(y, 1.0)))


def bytes_model(halo, e, tets, ranks):
    """Bytes a rank sends per step with `tets` tets on `ranks` ranks: COMPACT_PART_FACES
    faces of the measured per-face halo, scaled by the part's surface ((N/P)^(2/3)), plus
    the gathered e N (P - 1) / P."""
    per_face, part_tets = halo
    return (COMPACT_PART_FACES * per_face * (tets / ranks / part_tets) ** (2 / 3)
            + e * tets * (ranks - 1) / ranks)


def memory_model(coefficients, tets, ranks):
    return coefficients[0] + coefficients[1] * tets + coefficients[2] * tets / ranks


def _nonnegative_lstsq(A, b):
    """min |A x - b| over x >= 0 by trying every subset of free columns (few columns)."""
    best, best_residual = np.zeros(A.shape[1]), float(np.sum(b ** 2))
    columns = A.shape[1]
    for mask in range(1, 2 ** columns):
        keep = [j for j in range(columns) if mask >> j & 1]
        x, *_ = np.linalg.lstsq(A[:, keep], b, rcond=None)
        if np.any(x < 0):
            continue
        full = np.zeros(columns)
        full[keep] = x
        residual = float(np.sum((A @ full - b) ** 2))
        if residual < best_residual:
            best, best_residual = full, residual
    return best


def model_lines(rows):
    """Markdown lines: per mode and contact, the fitted figures, the largest relative
    deviation of each fit from the points it was fitted to, and the prediction at
    TARGET_TETS tets on TARGET_RANKS ranks."""
    lines = ["| mode | contact | a (MB) | b (kB/tet, whole mesh) | c (kB/tet, own part) | memory fit off by | "
             f"memory per rank at {TARGET_TETS:.0e} tets, {TARGET_RANKS} ranks (with b = 0) | halo per face and step "
             "(part of N/P tets) | e (B/tet, gathered) | e fit off by | bytes per rank per step there |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for mode in MODES:
        for contact in CONTACT:
            chosen = [r for r in rows if r["status"] == "ok" and r["mode"] == mode and r["contact"] == contact]
            # A part's halo does not depend on contact, and with contact the weak series'
            # two stacked bodies fall whole to one rank each at small P: halo without it.
            no_contact = [r for r in rows if r["status"] == "ok" and r["mode"] == mode and r["contact"] == "off"]
            # One rank runs PETSc's sequential matrices and Galerkin products (GAMG's
            # parallel product holds about 50 MB more at 1e5 tets per rank): the
            # parallel points alone tell how memory goes towards TARGET_RANKS.
            parallel = [r for r in chosen if r["ranks"] >= 2]
            memory, halo, gathered = fit_memory(parallel), fit_halo(no_contact), fit_gathered(chosen)
            if memory is None or halo is None or gathered is None:
                continue
            memory_error = max(abs(memory_model(memory, r["tets"], r["ranks"]) / r["mem_max_mb"] - 1)
                               for r in parallel)
            mem = memory_model(memory, TARGET_TETS, TARGET_RANKS)
            step = bytes_model(halo, gathered[0], TARGET_TETS, TARGET_RANKS)
            own = memory_model((memory[0], 0.0, memory[2]), TARGET_TETS, TARGET_RANKS)
            lines.append(f"| {mode} | {contact} | {memory[0]:.0f} | {1024 * memory[1]:.3g} | "
                         f"{1024 * memory[2]:.3g} | {100 * memory_error:.0f} % | {_size_mb(mem)} ({_size_mb(own)}) | "
                         f"{_size_bytes(halo[0])} ({halo[1]:.3g}) | {gathered[0]:.3g} | {100 * gathered[1]:.0f} % | "
                         f"{_size_bytes(step)} |")
    return lines


# The scale-out targets read off these series: the strong series' summed peak memory
# at its largest P at most this times that at 2 ranks, and no rank above this times
# the mean; the weak series' largest rank within this of P = 1, and the bytes a rank
# sends per step flat (largest over smallest at P > 1) within this.
STRONG_SUM_GROWTH = 1.5
RANK_IMBALANCE = 1.3
WEAK_MEMORY_GROWTH = 1.3
WEAK_BYTES_SPREAD = 1.5


def _has(row, key):
    return isinstance(row.get(key), (int, float)) and not np.isnan(row[key])


def _private_sum(row):
    """The ranks' summed peaks less their file-backed pages (shared libraries, which the
    ranks of one machine share: counted once per machine, not once per rank)."""
    return row["mem_sum_mb"] - row["ranks"] * row["mem_file_mb"]


def target_lines(rows):
    """Markdown lines: per mode and contact, the targets with the measured figure and a verdict."""
    lines = ["| series | mode | contact | target | measured | verdict |", "|---|---|---|---|---|---|"]

    def add(series, mode, contact, target, value, limit):
        verdict = "met" if value <= limit else "not met"
        lines.append(f"| {series} | {mode} | {contact} | {target} | {value:.2f} | {verdict} |")
    for mode in MODES:
        for contact in CONTACT:
            for series in SERIES:
                ok = {r["ranks"]: r for r in rows if r["status"] == "ok" and r["series"] == series
                      and r["mode"] == mode and r["contact"] == contact}
                if len(ok) < 2:
                    continue
                largest = max(ok)
                if series == "strong" and 2 in ok and largest > 2:
                    add(series, mode, contact, f"sum of peaks at P = {largest} / at P = 2 <= {STRONG_SUM_GROWTH}",
                        ok[largest]["mem_sum_mb"] / ok[2]["mem_sum_mb"], STRONG_SUM_GROWTH)
                    add(series, mode, contact, f"largest rank / mean at P = {largest} <= {RANK_IMBALANCE}",
                        ok[largest]["mem_imbalance"], RANK_IMBALANCE)
                    if all(_has(ok[p], "mem_file_mb") for p in (2, largest)):
                        add(series, mode, contact, f"the same sums less each rank's shared file pages "
                                                   f"<= {STRONG_SUM_GROWTH}",
                            _private_sum(ok[largest]) / _private_sum(ok[2]), STRONG_SUM_GROWTH)
                if series == "weak" and 1 in ok:
                    add(series, mode, contact, f"largest rank at P = {largest} / at P = 1 <= {WEAK_MEMORY_GROWTH}",
                        ok[largest]["mem_max_mb"] / ok[1]["mem_max_mb"], WEAK_MEMORY_GROWTH)
                    if all(_has(ok[p], "mem_file_mb") for p in (1, largest)):
                        add(series, mode, contact, f"the same less the rank's shared file pages "
                                                   f"<= {WEAK_MEMORY_GROWTH}",
                            (ok[largest]["mem_max_mb"] - ok[largest]["mem_file_mb"])
                            / (ok[1]["mem_max_mb"] - ok[1]["mem_file_mb"]), WEAK_MEMORY_GROWTH)
                    sending = [r["step_bytes_mean"] for p, r in ok.items() if p > 1]
                    if len(sending) >= 2 and min(sending) > 0:
                        add(series, mode, contact, f"bytes per rank per step, largest / smallest over P > 1 <= "
                                                   f"{WEAK_BYTES_SPREAD}", max(sending) / min(sending),
                            WEAK_BYTES_SPREAD)
                        # The weak parts lie in a row: an end part has one neighbour,
                        # the others two, 2 (P - 1) / P on average (its halo).
                        per_face = [r["step_bytes_mean"] / (2 * (p - 1) / p) for p, r in ok.items() if p > 1]
                        add(series, mode, contact, f"the same per interface of a part (2 (P - 1) / P per rank) "
                                                   f"<= {WEAK_BYTES_SPREAD}", max(per_face) / min(per_face),
                            WEAK_BYTES_SPREAD)
    return lines


def _size_mb(mb):
    return f"{mb / 1024:.3g} GB" if mb >= 1024 else f"{mb:.0f} MB"


def _size_bytes(b):
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if b >= scale:
            return f"{b / scale:.3g} {unit}"
    return f"{b:.0f} B"


# ----------------------------------------------------------------------------- outputs

def _fmt(value, digits=3):
    if isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)):
        return str(value)
    if value == 0:
        return "0"
    return f"{value:.{digits}g}"


def write_csv(path, columns, rows):
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({c: _fmt(row.get(c, ""), 6) if not isinstance(row.get(c, ""), str) else row.get(c, "")
                             for c in columns})


def table_lines(rows, series):
    lines = ["| mode | contact | ranks | tets | peak MB per rank: max / mean / min | rank 0 | sum MB | "
             "of which shared file pages per rank MB | "
             "set-up s | assembly s | factorisation s | contact s | s per step | bytes sent per rank per step: "
             "max / mean / min | msgs per rank per step (mean) | of which collectives (bytes, mean) | "
             "set-up bytes per rank (mean) | status |",
             "|" + "---|" * 18]
    for r in rows:
        if r["series"] != series:
            continue
        if r["status"] != "ok":
            lines.append(f"| {r['mode']} | {r['contact']} | {r['ranks']} | {r['tets']} | "
                         + "| " * 13 + f"{r['status']}: {r['message']} |")
            continue
        lines.append(
            f"| {r['mode']} | {r['contact']} | {r['ranks']} | {r['tets']} | "
            f"{r['mem_max_mb']:.0f} / {r['mem_mean_mb']:.0f} / {r['mem_min_mb']:.0f} | {r['mem_rank0_mb']:.0f} | "
            f"{r['mem_sum_mb']:.0f} | {_fmt(r.get('mem_file_mb', ''))} | {r['setup_s']:.2f} | {r['assembly_s']:.2f} | {r['factorisation_s']:.2f} | "
            f"{r['contact_s']:.2f} | {r['loop_s_per_step']:.3f} | {_size_bytes(r['step_bytes_max'])} / "
            f"{_size_bytes(r['step_bytes_mean'])} / {_size_bytes(r['step_bytes_min'])} | "
            f"{r['step_msgs_mean']:.0f} | {_size_bytes(r['step_coll_bytes_mean'])} | "
            f"{_size_bytes(r['setup_bytes_mean'])} | ok |")
    return lines


def write_markdown(args, rows, started):
    loads = [r["load_avg"] for r in rows if isinstance(r.get("load_avg"), float)]
    when = (f"; started {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime(started))}, "
            f"{(time.time() - started) / 60:.1f} min" if started else "")
    lines = ["# softbody scaling on this machine", "",
             f"Command: `./run scale {shlex.join(args.argv)}`", "",
             f"Machine: {platform.node()}, {os.cpu_count()} cores, "
             f"{os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 2**30:.0f} GB"
             + (f"; 1-minute load average {min(loads):.1f} to {max(loads):.1f} after the points" if loads else "")
             + f"{when}. Ranks beyond the cores are oversubscribed: memory and "
             "message volume are what the program does, times only rough.", "",
             f"Solver options: `{rows[0]['solver_options'] if rows else args.solver_options}`; modes "
             f"{', '.join(args.modes)}; contact {', '.join(args.contact)}; dt = {DT} s; per-step figures over "
             f"{args.steps} steps (a {SHORT_STEPS + args.steps}-step run minus a {SHORT_STEPS}-step run).", ""]
    for series, title in (("strong", f"Strong scaling: one mesh of about {args.tets:.3g} tets"),
                          ("weak", f"Weak scaling: about {args.tets_per_rank:.3g} tets per rank")):
        if series in args.series:
            lines += [f"## {title}", ""] + table_lines(rows, series) + [""]
    lines += ["## Targets", ""] + target_lines(rows) + [""]
    lines += ["## Model", "",
              "Per mode and contact, with N tets on P ranks (tools/scale.py: fit_memory, fit_halo, fit_gathered): "
              "a rank's peak memory mem = a + b N + c N/P (MB), fitted over the measured points at P >= 2 (one rank "
              "runs PETSc's sequential matrices and products, another regime); the bytes a "
              f"rank sends per step = {COMPACT_PART_FACES} faces x the halo per face measured in the weak series "
              "without contact (its largest P: an interior part has two faces), scaled by (N/P)^(2/3), "
              "+ e N (P-1)/P, e fitted to the collectives' bytes; (b = 0): what a rank would hold if nothing "
              f"were replicated; extrapolated to N = {TARGET_TETS:.0e}, P = {TARGET_RANKS}.", ""]
    lines += model_lines(rows) + [""]
    with open(os.path.join(args.study_dir, "scale.md"), "w") as f:
        f.write("\n".join(lines))


def write_plot(args, rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    series = [s for s in SERIES if s in args.series]
    figure, axes = plt.subplots(2, len(series), figsize=(6 * len(series), 8), squeeze=False)
    for column, name in enumerate(series):
        for mode in args.modes:
            for contact in args.contact:
                points = [r for r in rows if r["series"] == name and r["mode"] == mode and r["contact"] == contact
                          and r["status"] == "ok"]
                if not points:
                    continue
                ranks = [r["ranks"] for r in points]
                style = dict(marker="o" if mode == "linear" else "s", linestyle="-" if contact == "off" else "--",
                             label=f"{mode}, contact {contact}")
                axes[0, column].plot(ranks, [r["mem_max_mb"] for r in points], **style)
                sending = [r for r in points if r["ranks"] > 1]  # one rank sends nothing
                if sending:
                    axes[1, column].plot([r["ranks"] for r in sending], [r["step_bytes_mean"] for r in sending],
                                         **style)
        axes[0, column].set_title(f"{name} scaling" + (f", {args.tets:.3g} tets" if name == "strong" else
                                                       f", {args.tets_per_rank:.3g} tets per rank"))
        axes[0, column].set_ylabel("largest rank's peak memory (MB)")
        axes[0, column].set_ylim(bottom=0)
        axes[1, column].set_ylabel("bytes sent per rank per step (mean over ranks)")
        if axes[1, column].has_data():
            axes[1, column].set_yscale("log")
        for axis in axes[:, column]:
            if not axis.has_data():
                continue
            axis.set_xscale("log", base=2)
            axis.set_xticks(sorted(args.ranks))
            axis.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
            axis.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            axis.set_xlabel("ranks")
            axis.grid(True, which="both", alpha=0.3)
            if axis.get_legend_handles_labels()[0]:
                axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(os.path.join(args.study_dir, "scale.png"), dpi=100)
    plt.close(figure)


def write_outputs(args, rows, rank_rows, started):
    write_csv(os.path.join(args.study_dir, "scale.csv"), COLUMNS, rows)
    write_csv(os.path.join(args.study_dir, "scale-ranks.csv"), RANK_COLUMNS, rank_rows)
    write_markdown(args, rows, started)
    write_plot(args, rows)


INTEGER_COLUMNS = ("ranks", "tets", "vertices", "tets_per_rank", "steps", "rank")


def read_rows(path):
    """The rows of a scale.csv or scale-ranks.csv written before, numbers as numbers."""
    rows = []
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            for key, value in row.items():
                if key in INTEGER_COLUMNS and value:
                    row[key] = int(value)
                elif value and key not in ("series", "mode", "contact", "solver_options", "status", "message"):
                    row[key] = float(value)
            rows.append(row)
    return rows


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    args = parse_arguments(argv)
    args.argv = argv
    command_file = os.path.join(args.study_dir, "command.txt")
    if args.report_only:
        rows = read_rows(os.path.join(args.study_dir, "scale.csv"))
        rank_rows = read_rows(os.path.join(args.study_dir, "scale-ranks.csv"))
        for key, column, order in (("ranks", "ranks", None), ("series", "series", SERIES), ("modes", "mode", MODES),
                                   ("contact", "contact", CONTACT)):
            values = {r[column] for r in rows}
            setattr(args, key, sorted(values) if order is None else [v for v in order if v in values])
        args.steps = rows[0]["steps"] if rows else args.steps
        strong = [r["tets"] for r in rows if r["series"] == "strong"]
        args.tets = strong[0] if strong else args.tets
        weak = [r["tets_per_rank"] for r in rows if r["series"] == "weak"]
        args.tets_per_rank = round(sum(weak) / len(weak), -2) if weak else args.tets_per_rank
        if os.path.isfile(command_file):
            args.argv = shlex.split(open(command_file).read())
        write_outputs(args, rows, rank_rows, None)
        print(f"scale: rewrote {os.path.join(args.study_dir, 'scale.md')} and scale.png from scale.csv")
        return 0
    os.makedirs(os.path.join(args.study_dir, "runs"), exist_ok=True)
    with open(command_file, "w") as f:
        f.write(shlex.join(argv) + "\n")
    started, rows, rank_rows = time.time(), [], []
    # Rank counts outermost: a run cut short has every series and variant up to the same P.
    points = [(s, m, c, p) for p in sorted(args.ranks) for s in args.series for m in args.modes for c in args.contact]
    for series, mode, contact, ranks in points:
        row = run_point(args, rows, rank_rows, series, mode, contact, ranks)
        row["load_avg"] = os.getloadavg()[0]
        rows.append(row)
        print(f"scale: {series} {mode} contact {contact} {ranks} rank(s) {row['tets']} tets: "
              + (f"peak {row['mem_max_mb']:.0f} MB per rank, {_size_bytes(row['step_bytes_mean'])} "
                 f"per rank per step" if row["status"] == "ok" else f"{row['status']}: {row['message']}"),
              flush=True)
        rows.sort(key=lambda r: (SERIES.index(r["series"]), MODES.index(r["mode"]), CONTACT.index(r["contact"]),
                                 r["ranks"]))
        write_outputs(args, rows, rank_rows, started)
    print(f"scale: wrote {os.path.join(args.study_dir, 'scale.md')} ({len(rows)} points)")
    return 0 if all(r["status"] in ("ok", "skipped", "stopped") for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
