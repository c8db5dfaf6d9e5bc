"""The .xdmf beside every result file is a ParaView time series of the deformed
mesh with velocity as a point field.

(a) A 2-rank run of the beam scene, frames every 2 steps: ParaView's own Xdmf3
    reader (pvpython, Debian's python3-paraview; this part is skipped without
    it) lists every time of /time, and at every frame its points equal
    /positions and its "velocity" field equals /velocities exactly, with all
    the tets. Independently of ParaView, the .xdmf's hyperslabs resolved with
    h5py select the same frames.
(b) The .xdmf is extended after every flushed frame (it is written when the
    file is opened): while a run goes on it lists exactly the frames already
    in the file. Checked on a run stopped by SIGKILL, and with -flush_every 4
    on a finished run (all frames listed at the end).
(c) A restarted run's file (in place and copied, with -flush_every 1 and 3)
    has an .xdmf listing all its frames, the continued ones and the new ones.
"""
import os
import signal
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()
scene = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scenes", "beam-scene.txt")


def result(name):
    path = os.path.join(args.work, name + ".h5")
    for p in (path, path[:-3] + ".xdmf"):
        if os.path.exists(p):
            os.remove(p)
    return path


def same_as_file(h5, label, may_lag=0):
    """The .xdmf (read without ParaView) lists the file's frames: all of them, or all but
    at most `may_lag` last ones (a run killed between flushing the file and extending its
    .xdmf leaves the frames of that flush unlisted), each equal to the file's."""
    times, positions, velocities = harness.xdmf_frames(h5[:-3] + ".xdmf")
    n = len(times)
    r = harness.read_frames(h5, first_frames=n if may_lag else None)
    ok = (r["stored_frames"] - may_lag <= n <= r["stored_frames"] and np.array_equal(times, r["time"][:n]) and
          np.array_equal(positions, r["positions"][:n]) and np.array_equal(velocities, r["velocities"][:n]))
    checks.check(ok, f"{label}: the .xdmf lists {n} frames, the file holds {r['stored_frames']} (at most "
                     f"{may_lag} unlisted); times, positions and velocities selected by its hyperslabs "
                     f"equal the file's")
    return r


# (a) ParaView reads the time series.
out = result("beam")
harness.run(args, 2, ["-scene", scene, "-steps", 10, "-output_every", 2, "-output", out, "-quiet"])
r = same_as_file(out, "(a) h5py")
paraview = harness.paraview_frames(args, out[:-3] + ".xdmf")
if paraview is None:
    print("SKIP (a) ParaView part: pvpython not found (Debian package python3-paraview)")
else:
    times, positions, velocities, cells = paraview
    checks.check(np.array_equal(times, r["time"]),
                 f"(a) ParaView's Xdmf3 reader lists the times {list(times)} = /time")
    checks.check(positions.shape == r["positions"].shape and np.array_equal(positions, r["positions"]),
                 f"(a) ParaView's points equal /positions at all {len(times)} frames "
                 f"({positions.shape[1]} points each)")
    checks.check(velocities.shape == r["velocities"].shape and np.array_equal(velocities, r["velocities"]),
                 "(a) ParaView's point field 'velocity' equals /velocities at every frame")
    checks.check(bool(np.all(cells == len(r["mesh/tets"]))),
                 f"(a) every frame has all {len(r['mesh/tets'])} tets as cells")

# (b) A run killed by SIGKILL: the .xdmf lists the frames in the file, no more (and at
# most the last flush's frame fewer, when the kill fell between the two writes).
out = result("killed")
process = subprocess.Popen([args.softbody, "-scene", scene, "-steps", "1000000", "-output", out, "-quiet"],
                           env=harness.mpi_environment(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
deadline = time.time() + 60
while time.time() < deadline and (not os.path.exists(out[:-3] + ".xdmf") or
                                  open(out[:-3] + ".xdmf").read().count("<Time ") < 6):
    time.sleep(0.05)
process.send_signal(signal.SIGKILL)
process.wait()
r = same_as_file(out, "(b) after SIGKILL", may_lag=1)  # -flush_every 1: one frame per flush
checks.check(len(r["time"]) >= 6 and r["complete"] == 0,
             f"(b) the killed run's file opens with {len(r['time'])} frames, complete = {r['complete']}")
if paraview is not None:
    times, positions, _, _ = harness.paraview_frames(args, out[:-3] + ".xdmf")
    n = len(times)
    checks.check(n >= len(r["time"]) - 1 and np.array_equal(times, r["time"][:n]) and
                 np.array_equal(positions, r["positions"][:n]),
                 f"(b) ParaView reads the killed run's {n} frames")

out = result("flush4")
harness.run(args, 2, ["-scene", scene, "-steps", 10, "-flush_every", 4, "-output", out, "-quiet"])
same_as_file(out, "(b) -flush_every 4, finished")

# (c) Restarted runs.
part = result("part")
harness.run(args, 2, ["-scene", scene, "-steps", 6, "-checkpoint_every", 3, "-output", part, "-quiet"])
copy = result("continued")
harness.run(args, 2, ["-scene", scene, "-steps", 10, "-restart", part, "-output", copy, "-quiet"])
same_as_file(copy, "(c) restart into a new file")
harness.run(args, 2, ["-scene", scene, "-steps", 10, "-restart", part, "-quiet"])
r = same_as_file(part, "(c) restart in place")
checks.check(len(r["time"]) == 11, f"(c) the continued file holds frames 0..10 ({len(r['time'])})")
harness.run(args, 2, ["-scene", scene, "-steps", 15, "-restart", part, "-flush_every", 3, "-quiet"])
r = same_as_file(part, "(c) restart in place again, -flush_every 3")
checks.exit()
