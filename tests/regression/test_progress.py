"""The progress line and -quiet.

Runs the beam scene (150 steps; 40 corotational ones on one rank, to last
about a second) with stderr on a pseudo-terminal (python's pty module) or on a
pipe:
(a) one rank on a terminal: rank 0 rewrites one line with carriage returns,
    "step N/40  t = ... s  ... steps/s  ETA ...  solver its ...", the step
    counts rise, the first step is shown at once (so even a run faster than
    the 0.25 s refresh has an update with an ETA before the final one), at
    most four updates a second (+ the first and the final one), and the last
    update is "step 40/40" ending with a newline; the summary still goes to
    stdout.
(b) two ranks under mpirun on a terminal (the ranks' stderr is a pipe to
    mpirun, whose stderr is the terminal): the same line.
(c) a pipe (CI): no progress line; -progress forces it into the pipe.
(d) -quiet on a terminal: nothing at all on stdout or stderr; -progress 0: no
    line; an error under -quiet is still reported (one line).
"""
import os
import pty
import re
import select
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()
scene = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scenes", "beam-scene.txt")
STEPS = 150
LINE = re.compile(r"step (\d+)/(\d+)  t = \S+ s  \S+ steps/s  (ETA [^ ]+( \S+)*|in [^ ]+( \S+)*)  solver its \d+")


def launch(ranks, options, terminal, steps=STEPS):
    """Runs softbody; stderr on a pseudo-terminal (terminal) or a pipe. Returns
    (exit code, stdout, stderr bytes, wall seconds)."""
    command = ([args.softbody] if ranks == 1 else [args.mpiexec, "-n", str(ranks), args.softbody])
    command += ["-scene", scene, "-steps", str(steps)] + [str(o) for o in options]
    start = time.time()
    if not terminal:
        r = subprocess.run(command, capture_output=True, env=harness.mpi_environment(), timeout=300)
        return r.returncode, r.stdout.decode(), r.stderr, time.time() - start
    master, slave = pty.openpty()
    process = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave,
                               env=harness.mpi_environment())
    os.close(slave)
    err = b""
    while True:
        ready, _, _ = select.select([master], [], [], 0.1)
        if ready:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the terminal closed: every writer has exited
                break
            if not chunk:
                break
            err += chunk
        elif process.poll() is not None:
            break
    out = process.stdout.read().decode()
    process.wait(timeout=300)
    os.close(master)
    return process.returncode, out, err, time.time() - start


def updates(stderr):
    """The progress updates: the texts between carriage returns that are progress lines."""
    text = stderr.decode(errors="replace")
    return [u.strip() for u in text.split("\r") if LINE.search(u)], text


def check_progress(label, ranks, options, terminal, steps=STEPS):
    code, out, err, wall = launch(ranks, options, terminal, steps)
    lines, text = updates(err)
    checks.check(code == 0 and len(lines) >= 2,
                 f"{label}: exit {code}, {len(lines)} progress updates in {wall:.1f} s, e.g. '{lines[0] if lines else ''}'")
    if not lines:
        print("stderr was:", repr(text[:500]))
        return
    counts = [int(LINE.search(u).group(1)) for u in lines]
    checks.check(counts == sorted(counts) and counts[-1] == steps and LINE.search(lines[-1]).group(2) == str(steps),
                 f"{label}: step counts rise {counts[:3]}...{counts[-2:]} to {steps}/{steps}")
    checks.check(len(lines) <= 4 * wall + 3, f"{label}: {len(lines)} updates <= 4 per second over {wall:.1f} s + 3")
    checks.check(counts[0] == 1 and text.rstrip(" ").endswith("\n") and "in " in lines[-1] and "ETA" in lines[0],
                 f"{label}: step 1 at once with an ETA, the final line '{lines[-1]}' ends with a newline")
    checks.check("softbody run summary" in out, f"{label}: the summary still goes to stdout")


def check_silent(label, ranks, options, terminal, want_stdout):
    code, out, err, _ = launch(ranks, options, terminal)
    lines, text = updates(err)
    checks.check(code == 0 and not lines and not text.strip() and (bool(out.strip()) == want_stdout),
                 f"{label}: exit {code}, no progress line, stderr {'empty' if not text.strip() else repr(text[:80])}, "
                 f"stdout {'with the summary' if out.strip() else 'empty'}")


check_progress("(a) 1 rank, terminal", 1, ["-mode", "corotational"], True, steps=40)
check_progress("(b) 2 ranks under mpirun, terminal", 2, [], True)
check_silent("(c) 2 ranks, pipe", 2, [], False, True)
check_progress("(c) 2 ranks, pipe, -progress", 2, ["-progress"], False)
check_silent("(d) 1 rank, terminal, -quiet", 1, ["-quiet"], True, False)
check_silent("(d) 2 ranks, terminal, -quiet", 2, ["-quiet"], True, False)
check_silent("(d) 1 rank, terminal, -progress 0", 1, ["-progress", "0"], True, True)
code, out, err, _ = launch(2, ["-quiet", "-dt", "-1"], True)
text = err.decode(errors="replace")
checks.check(code != 0 and text.count("softbody: error: option -dt") == 1 and not out.strip(),
             f"(d) -quiet keeps errors: exit {code}, stderr '{text.strip().splitlines()[0] if text.strip() else ''}'")
checks.exit()
