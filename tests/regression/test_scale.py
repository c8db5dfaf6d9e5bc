#!/usr/bin/env python3
"""./run scale keeps working: the quick subset of tools/scale.py, checked against facts
it does not compute itself.

1. Bad options end with one line naming the option and exit status 2.
2. The quick subset (-scale_quick: strong series on a 6e3-tet beam, weak series at
   3e3 tets per rank, ranks 1, 2, 3, linear mode, without and with contact) writes
   scale.csv with one row per point and every column, every point measured;
   scale-ranks.csv with one row per rank of every point; scale.md with both tables
   and the model; scale.png.
3. Counts: the strong series keeps one mesh (same tets at every P); the weak series
   holds 3e3 tets per rank within 15 % (the box mesher rounds to whole cells).
4. Memory: every rank's peak resident set is measured and at least MIN_PROCESS_MB
   (a process that has started Open MPI and PETSc holds several times more);
   the shared file pages (shared libraries) sampled per rank, where a sample
   caught the run, are at least 1 MB and less than the smallest peak.
5. Messages: at one rank a step sends nothing (no other rank to send to); at 2 and
   3 ranks every rank sends something every step.
6. Weak series without contact: a rank's part is a unit cube of the same cells and
   touches one neighbour (P = 2) or one or two (P = 3, the middle part two), across
   the same cross-section; so the bytes a rank sends per step, divided by the mean
   number of interfaces a rank has (2 (P - 1) / P), agree between P = 2 and 3 within
   a factor MAX_HALO_RATIO. They are not equal: the solver's iteration count and its
   coarse levels' traffic change with the partition.
7. Memory, independently: the 2-rank weak point's long run is repeated with
   /usr/bin/time replaced by a probe that polls the rank's VmHWM in
   /proc/PID/status (the kernel's high-water mark of the resident set, read while
   the process runs) instead of the exit status's rusage that time reports; per rank
   the two agree within MEMORY_RELATIVE + MEMORY_ABSOLUTE_MB (two runs of the same
   deterministic program; the probe misses growth after its last poll).

8. Per-rank figures: the messages PETSc logged on each rank (softbody's
   -log_rank_messages lines, which the tool reads) sum to the total of -log_view's
   own summary in every run's log (its 4 digits); and a point's largest, smallest
   and mean bytes per step are those of its ranks' rows in scale-ranks.csv, so the
   largest is never below the mean.

Run with --probe PREFIX COMMAND... it is the probe: runs COMMAND, writes the last
VmHWM it read (kB) to PREFIX.RANK and exits with COMMAND's status.
"""
import csv
import os
import re
import shlex
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

TOOLS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools")
sys.path.insert(0, TOOLS)
import scale  # noqa: E402

MAX_HALO_RATIO = 1.5
MEMORY_RELATIVE = 0.05
MEMORY_ABSOLUTE_MB = 3.0
MIN_PROCESS_MB = 10.0
PROBE_INTERVAL_S = 0.005
RANKS = (1, 2, 3)
WEAK_TETS_PER_RANK = 3000


def probe(prefix, command):
    """Runs command; writes the last VmHWM (kB) read from /proc/PID/status while it ran."""
    proc = subprocess.Popen(command)
    peak = 0
    while proc.poll() is None:
        try:
            with open(f"/proc/{proc.pid}/status") as f:
                for line in f:
                    if line.startswith("VmHWM:"):
                        peak = max(peak, int(line.split()[1]))
        except OSError:
            pass
        time.sleep(PROBE_INTERVAL_S)
    with open(f"{prefix}.{os.environ.get('OMPI_COMM_WORLD_RANK', '0')}", "w") as f:
        f.write(f"{peak}\n")
    return proc.returncode


def read_csv(path):
    if not os.path.isfile(path):
        return [], []
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return list(reader), reader.fieldnames or []


def check_bad_options(checks, args):
    for options, named in ((["-scale_ranks", "0"], "-scale_ranks"), (["-scale_modes", "elastic"], "-scale_modes"),
                           (["-scale_solver_options", "/nonexistent.opts"], "-scale_solver_options"),
                           (["-scale_contact", "maybe"], "-scale_contact"), (["-scale_tets", "x"], "-scale_tets")):
        result = subprocess.run([sys.executable, os.path.join(TOOLS, "scale.py"), "-softbody", args.softbody] + options,
                                capture_output=True, text=True, timeout=60)
        lines = result.stderr.strip().splitlines()
        checks.check(result.returncode == 2 and len(lines) == 1 and named in lines[0],
                     f"{' '.join(options)}: one error line naming {named}, exit 2 ({lines})")


def check_memory_probe(checks, args, folder, rank_rows):
    """Repeats the 2-rank weak point's long run under the VmHWM probe."""
    log = os.path.join(folder, "runs", "weak-linear-contact-off-2-long.log")
    if not checks.check(os.path.isfile(log), f"{log} written"):
        return
    command = shlex.split(open(log).readline())
    # The rank command is `sh -c SCRIPT STEM.rss softbody ...`: put the probe in its place.
    at = command.index("sh")
    prefix = os.path.join(args.work, "vmhwm")
    command = command[:at] + [sys.executable, os.path.abspath(__file__), "--probe", prefix] + command[at + 4:]
    result = subprocess.run(command, capture_output=True, text=True, timeout=300, env=harness.mpi_environment())
    if not checks.check(result.returncode == 0, "the probed run exits 0"):
        print(result.stdout[-2000:], result.stderr[-2000:])
        return
    measured = {int(r["rank"]): float(r["mem_mb"]) for r in rank_rows
                if r["series"] == "weak" and r["contact"] == "off" and int(r["ranks"]) == 2}
    for rank in (0, 1):
        hwm = int(open(f"{prefix}.{rank}").read()) / 1024
        time_mb = measured.get(rank, float("nan"))
        tolerance = MEMORY_RELATIVE * time_mb + MEMORY_ABSOLUTE_MB
        checks.check(abs(hwm - time_mb) <= tolerance,
                     f"rank {rank}: time's %M {time_mb:.1f} MB, VmHWM {hwm:.1f} MB (within {tolerance:.1f} MB)")


def check_rank_messages(checks, folder, rows, rank_rows):
    """8: the per-rank lines against -log_view's total; the rows' extremes against the ranks'."""
    logs = sorted(name for name in os.listdir(os.path.join(folder, "runs")) if name.endswith(".log"))
    compared = 0
    for name in logs:
        text = open(os.path.join(folder, "runs", name)).read()
        lines = re.findall(r"^\s*messages\s+rank \d+: \d+ messages, (\d+) bytes", text, re.M)
        total = re.search(r"^MPI Msg Len \(bytes\):\s+\S+\s+\S+\s+\S+\s+([0-9.]+e[+-]\d+)", text, re.M)
        if lines and total and float(total.group(1)) > 0:
            compared += 1
            ours = sum(float(b) for b in lines)
            checks.check(abs(ours / float(total.group(1)) - 1) <= 1e-3,
                         f"{name}: the ranks' lines sum to {ours:.0f} B, -log_view's total {total.group(1)}")
    checks.check(compared >= 4, f"per-rank message lines compared with -log_view's total in {compared} logs")
    for row in rows:
        if row["status"] != "ok":
            continue
        mine = [float(r["step_bytes"]) for r in rank_rows if (r["series"], r["contact"], r["ranks"])
                == (row["series"], row["contact"], row["ranks"])]
        label = f"{row['series']} contact {row['contact']} P = {row['ranks']}"
        close = lambda a, b: abs(a - b) <= 1e-5 * max(abs(b), 1.0)  # the CSV's 6 digits
        checks.check(len(mine) == int(row["ranks"]) and close(max(mine), float(row["step_bytes_max"]))
                     and close(min(mine), float(row["step_bytes_min"]))
                     and float(row["step_bytes_min"]) <= float(row["step_bytes_mean"]) <= float(row["step_bytes_max"]),
                     f"{label}: step bytes largest / mean / smallest {row['step_bytes_max']} / "
                     f"{row['step_bytes_mean']} / {row['step_bytes_min']} from the ranks' {mine}")


def main():
    if len(sys.argv) > 2 and sys.argv[1] == "--probe":
        sys.exit(probe(sys.argv[2], sys.argv[3:]))
    args = harness.arguments()
    checks = harness.Checks()
    check_bad_options(checks, args)

    folder = os.path.join(args.work, "scale")
    command = [sys.executable, os.path.join(TOOLS, "scale.py"), "-softbody", args.softbody, "-mpiexec", args.mpiexec,
               "-scale_quick", "-scale_solver_options", os.path.join(TOOLS, "..", "config", "cg-gamg.opts"),
               "-scale_dir", folder]
    started = time.time()
    result = subprocess.run(command, capture_output=True, text=True, timeout=540)
    print(result.stdout)
    checks.check(result.returncode == 0, f"tools/scale.py -scale_quick exits 0 in {time.time() - started:.0f} s "
                                         f"({result.stderr.strip()[-300:]})")

    rows, columns = read_csv(os.path.join(folder, "scale.csv"))
    checks.check(columns == scale.COLUMNS, f"scale.csv has the {len(scale.COLUMNS)} columns")
    expected = {(s, "linear", c, p) for s in ("strong", "weak") for c in ("off", "on") for p in RANKS}
    seen = [(r["series"], r["mode"], r["contact"], int(r["ranks"])) for r in rows]
    checks.check(set(seen) == expected and len(seen) == len(expected), f"scale.csv: {len(rows)} rows, one per point")
    for row in rows:
        label = f"{row['series']} contact {row['contact']} P = {row['ranks']}"
        if not checks.check(row["status"] == "ok", f"{label}: measured ({row['message']})"):
            continue
        ranks = int(row["ranks"])
        checks.check(row["solver_options"] == "config/cg-gamg.opts", f"{label}: solver options recorded")
        checks.check(float(row["mem_min_mb"]) >= MIN_PROCESS_MB, f"{label}: smallest rank peak {row['mem_min_mb']} MB")
        if row["mem_file_mb"]:  # sampled every 0.5 s: a run may end before the first sample
            checks.check(1 <= float(row["mem_file_mb"]) < float(row["mem_min_mb"]),
                         f"{label}: shared file pages {row['mem_file_mb']} MB per rank, part of its peak")
        if ranks == 1:
            checks.check(float(row["step_bytes_max"]) == 0 and float(row["setup_bytes_mean"]) == 0,
                         f"{label}: nothing sent")
        else:
            checks.check(float(row["step_bytes_min"]) > 0 and float(row["step_p2p_bytes_min"]) > 0,
                         f"{label}: every rank sends every step ({float(row['step_bytes_min']):.0f} B at least)")
        if row["series"] == "weak":
            per_rank = int(row["tets"]) / ranks
            checks.check(abs(per_rank / WEAK_TETS_PER_RANK - 1) <= 0.15, f"{label}: {per_rank:.0f} tets per rank")
    strong = {r["tets"] for r in rows if r["series"] == "strong" and r["contact"] == "off"}
    checks.check(len(strong) == 1, f"strong series: one mesh ({strong} tets)")

    halo = {int(r["ranks"]): float(r["step_p2p_bytes_mean"]) / (2 * (int(r["ranks"]) - 1) / int(r["ranks"]))
            for r in rows if r["series"] == "weak" and r["contact"] == "off" and int(r["ranks"]) > 1
            and r["status"] == "ok"}
    if checks.check(sorted(halo) == [2, 3], "weak series without contact measured at 2 and 3 ranks"):
        ratio = max(halo.values()) / min(halo.values())
        checks.check(ratio <= MAX_HALO_RATIO, f"weak series: bytes per rank and interface per step "
                                              f"{halo[2]:.0f} (P = 2), {halo[3]:.0f} (P = 3), ratio {ratio:.2f}")

    rank_rows, _ = read_csv(os.path.join(folder, "scale-ranks.csv"))
    checks.check(len(rank_rows) == 2 * 2 * sum(RANKS), f"scale-ranks.csv: {len(rank_rows)} rows, one per rank")
    checks.check(all(float(r["mem_mb"]) >= MIN_PROCESS_MB for r in rank_rows), "every rank's peak memory measured")
    text = open(os.path.join(folder, "scale.md")).read() if os.path.isfile(os.path.join(folder, "scale.md")) else ""
    checks.check("## Strong scaling" in text and "## Weak scaling" in text and "## Model" in text
                 and "oversubscribed" in text, "scale.md: both tables, the model, the oversubscription note")
    png = os.path.join(folder, "scale.png")
    checks.check(os.path.isfile(png) and open(png, "rb").read(8) == b"\x89PNG\r\n\x1a\n", "scale.png written")
    check_memory_probe(checks, args, folder, rank_rows)
    check_rank_messages(checks, folder, rows, rank_rows)
    checks.exit()


if __name__ == "__main__":
    main()
