"""Signals and crashes lose nothing.

The beam scene runs "forever" (-steps 1000000) until a signal arrives once the
.xdmf lists a few frames:
(a) SIGTERM to a 1-rank run: it finishes the step, writes its frame and a
    checkpoint, closes the file (complete = 0, interrupted = 15) and exits
    with 143 after one line "softbody: stopped by SIGTERM after step N ...";
    the file holds frames 0..N, the .xdmf lists them; -restart from it to step
    N + 10 equals an uninterrupted run of N + 10 steps bit for bit.
(b) SIGINT and SIGTERM to mpirun running 2 ranks (mpirun passes them on): the
    run exits non-zero with the same line, and its file is closed the same way.
(c) SIGKILL (kill -9) to a 1-rank run with -checkpoint_every 5: the file still
    opens (complete = 0); the .xdmf lists frames 0..n, all whole in the file
    (frame f at time f dt, nothing torn); the file may hold one frame more (the
    frame being written when the kill came: the .xdmf is extended after the
    file's flush, and HDF5 may write a dataset's new extent before that), never
    more than -flush_every (1); and -restart continues the killed file from its
    last checkpoint to the same frames as an uninterrupted run, bit for bit.
"""
import os
import re
import signal
import subprocess
import sys
import time

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()
work = os.path.abspath(args.work)
scene = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scenes", "beam-scene.txt")
DT = 0.02  # the default -dt
STOPPED = re.compile(r"softbody: stopped by (SIG\w+) after step (\d+) of 1000000")


def fresh(name):
    return harness.fresh_result(work, name)


def run_until(out, ranks, options, sig, frames=6):
    """Starts a long run, waits until its .xdmf lists `frames` frames, sends `sig`
    (to mpirun for several ranks); returns (exit code, stdout, stderr)."""
    command = ([args.softbody] if ranks == 1 else [args.mpiexec, "-n", str(ranks), args.softbody])
    command += ["-scene", scene, "-steps", "1000000", "-output", out] + options
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=harness.mpi_environment())
    xdmf, deadline = out[:-3] + ".xdmf", time.time() + 120
    while time.time() < deadline and process.poll() is None:
        if os.path.exists(xdmf) and open(xdmf).read().count("<Time ") >= frames:
            break
        time.sleep(0.02)
    process.send_signal(sig)
    stdout, stderr = process.communicate(timeout=120)
    return process.returncode, stdout, stderr


def check_file(label, out, interrupted=None, unlisted=0):
    """The file opens, the frames its .xdmf lists are whole and the file's first
    frames; the file holds at most `unlisted` frames more. Returns the listed
    frames."""
    times, positions, _ = harness.xdmf_frames(out[:-3] + ".xdmf")
    listed = harness.read_frames(out, first_frames=len(times))
    n, extra = len(times), listed["stored_frames"] - len(times)
    whole = (np.allclose(listed["time"], DT * np.arange(n), rtol=1e-12, atol=1e-12) and
             bool(np.isfinite(listed["positions"]).all()) and bool(np.isfinite(listed["velocities"]).all()) and
             bool((np.abs(listed["positions"]).max(axis=(1, 2)) > 0).all()))
    with h5py.File(out, "r") as f:
        attribute = int(f.attrs.get("interrupted", -1))
    checks.check(listed["complete"] == 0 and n > 0 and whole and 0 <= extra <= unlisted and
                 np.array_equal(times, listed["time"]) and np.array_equal(positions, listed["positions"]) and
                 (interrupted is None or attribute in interrupted),
                 f"{label}: the file opens, complete = {listed['complete']}, interrupted = {attribute}; the .xdmf "
                 f"lists {n} whole frames (frame f at f dt), the file's first; {extra} more in the file "
                 f"(at most {unlisted})")
    return listed


def same_frames(label, reference, result):
    a, b = harness.read_frames(reference), harness.read_frames(result)
    ok = all(np.array_equal(a[k], b[k]) for k in ("time", "positions", "velocities"))
    checks.check(ok and b["complete"] == 1,
                 f"{label}: {len(b['time'])} frames equal the uninterrupted run's bit for bit, complete = {b['complete']}")


# (a) SIGTERM, one rank.
out = fresh("term")
code, stdout, stderr = run_until(out, 1, ["-checkpoint_every", "100000"], signal.SIGTERM)
lines = [line for line in stderr.splitlines() if line.strip()]
match = STOPPED.search(stderr)
checks.check(code == 143 and match is not None and len(lines) == 1 and match.group(1) == "SIGTERM",
             f"(a) SIGTERM: exit {code}, one line: '{lines[0] if lines else ''}'")
if match:
    steps = int(match.group(2))
    r = check_file("(a) SIGTERM", out, interrupted=(15,))
    with h5py.File(out, "r") as f:
        checkpoint_steps = [int(f[f"checkpoint/{s}"].attrs["step"]) for s in (0, 1) if f"checkpoint/{s}" in f]
    checks.check(len(r["time"]) == steps + 1 and checkpoint_steps == [steps],
                 f"(a) frames 0..{len(r['time']) - 1} for step {steps}; checkpoint at step {checkpoint_steps}")
    reference = fresh("term_reference")
    harness.run(args, 1, ["-scene", scene, "-steps", steps + 10, "-output", reference, "-quiet"])
    harness.run(args, 1, ["-scene", scene, "-steps", steps + 10, "-restart", out, "-quiet"])
    same_frames(f"(a) -restart from the SIGTERM checkpoint to step {steps + 10}", reference, out)

# (b) SIGINT and SIGTERM to mpirun, two ranks.
for sig in (signal.SIGINT, signal.SIGTERM):
    out = fresh(f"mpirun_{sig.name}")
    code, stdout, stderr = run_until(out, 2, ["-quiet"], sig)
    match = STOPPED.search(stderr)
    checks.check(code != 0 and match is not None and "PETSC ERROR" not in stderr,
                 f"(b) {sig.name} to mpirun, 2 ranks: exit {code}, "
                 f"'{match.group(0) if match else stderr.strip()[:300]}'")
    if match:
        r = check_file(f"(b) {sig.name} to mpirun", out, interrupted=(signal.SIGINT, signal.SIGTERM))
        checks.check(len(r["time"]) == int(match.group(2)) + 1,
                     f"(b) {sig.name}: frames 0..{len(r['time']) - 1}, the last one the interrupted step's")

# (c) SIGKILL, one rank: nothing flushed is lost; the restart continues the killed file.
out = fresh("killed")
code, _, _ = run_until(out, 1, ["-checkpoint_every", "5", "-quiet"], signal.SIGKILL, frames=12)
r = check_file(f"(c) SIGKILL (exit {code})", out, unlisted=1)
with h5py.File(out, "r") as f:
    slots = {s: (int(f[f"checkpoint/{s}"].attrs["valid"]), int(f[f"checkpoint/{s}"].attrs["step"]))
             for s in (0, 1) if f"checkpoint/{s}" in f}
last = max(step for valid, step in slots.values() if valid)
checks.check(len(r["time"]) >= 12 and last % 5 == 0 and last <= len(r["time"]) - 1,
             f"(c) checkpoint slots (valid, step) {slots}: the newest, step {last}, is among the "
             f"{len(r['time'])} frames")
target = len(r["time"]) + 5
reference = fresh("killed_reference")
harness.run(args, 1, ["-scene", scene, "-steps", target, "-output", reference, "-quiet"])
harness.run(args, 1, ["-scene", scene, "-steps", target, "-restart", out, "-quiet"])
same_frames(f"(c) -restart of the killed file from step {last} to step {target}", reference, out)
checks.exit()
