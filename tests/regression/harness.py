"""Helpers of the softbody ctest scripts (the ones the tools share are in tools/softbody_tools.py).

Every script is run by ctest as
    python3 tests/regression/test_NAME.py --softbody BUILD/softbody --mpiexec MPIEXEC --work DIR [--shared ../shared]
and exits 0 (pass), 1 (fail) or 77 (skipped: ctest's SKIP_RETURN_CODE). Only
the tests that compare with the seed coursework data, test_seed_*.py, get
--shared (tests/regression/CMakeLists.txt); they call seed(), which skips the
test when the data is absent. Every other test runs on the project's own
scenes and meshes (scenes/, tests/data/, meshes written by tools/box_mesh.py).
"""
import argparse
import json
import os
import subprocess
import sys

TOOLS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools")
sys.path.insert(0, TOOLS)
from softbody_tools import (lumped_masses, read_all_datasets, read_frames,  # noqa: E402,F401
                            read_medit, read_petsc_aij, softbody_command, write_scene)
import softbody_tools  # noqa: E402


def mpi_environment():
    """softbody_tools.mpi_environment(), and ranks that wait yield their core
    (Open MPI's mpi_yield_when_idle): the suite runs tests side by side, each
    with more ranks than cores, and spinning ranks starve the other test's
    (a 4-test sample of the suite ran in 50 s instead of 90 s)."""
    env = softbody_tools.mpi_environment()
    env.setdefault("OMPI_MCA_mpi_yield_when_idle", "1")
    return env

SKIP = 77


def arguments(extra=None):
    """The command line ctest gives every script (and `extra(parser)`'s own options)."""
    parser = argparse.ArgumentParser(allow_abbrev=False)
    parser.add_argument("--softbody", required=True)
    parser.add_argument("--mpiexec", required=True)
    parser.add_argument("--shared", default=None, help="the seed data's parent folder (test_seed_*.py only)")
    parser.add_argument("--work", required=True)
    if extra:
        extra(parser)
    args = parser.parse_args()
    os.makedirs(args.work, exist_ok=True)
    return args


def seed(args, *parts):
    """Path inside ../shared/seed-data; skips the test when it is absent (or when
    the test was not given --shared)."""
    if args.shared is None:
        print("SKIP: no --shared folder given (only test_seed_*.py read the seed data)")
        sys.exit(SKIP)
    path = os.path.join(args.shared, "seed-data", *parts)
    if not os.path.exists(path):
        print(f"SKIP: {path} not found (tests that need ../shared skip without it)")
        sys.exit(SKIP)
    return os.path.abspath(path)


def run(args, ranks, options, timeout=300, check=True):
    """Runs softbody on `ranks` ranks; returns the CompletedProcess (text output).
    With check, a non-zero exit prints the command and its output and fails the test."""
    command = softbody_command(args.mpiexec, ranks, args.softbody, options)
    result = subprocess.run(command, capture_output=True, text=True, timeout=timeout, env=mpi_environment())
    if check and result.returncode != 0:
        print("command failed:", " ".join(command))
        print(result.stdout)
        print(result.stderr)
        sys.exit(1)
    return result


def fresh_result(work, name):
    """work/NAME.h5, with any .h5 and .xdmf of that name from an earlier run deleted."""
    path = os.path.join(work, name + ".h5")
    for old in (path, path[:-3] + ".xdmf"):
        if os.path.exists(old):
            os.remove(old)
    return path


def png_size(path):
    """(width, height) of a PNG file from its IHDR chunk, or None when it is not a PNG."""
    import struct
    with open(path, "rb") as f:
        head = f.read(24)
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return struct.unpack(">II", head[16:24])


def box_mesh(args, name, size, cells):
    """Writes a box mesh (tools/box_mesh.py) into the work folder; returns its path."""
    path = os.path.join(args.work, name)
    subprocess.run([sys.executable, os.path.join(TOOLS, "box_mesh.py"), path, "-box_size", *map(str, size),
                    "-box_cells", *map(str, cells)], check=True, capture_output=True)
    return path


def relative_difference(ours, reference):
    """max |ours - reference| / max |reference| (inf when the shapes differ)."""
    import numpy as np
    ours, reference = np.asarray(ours), np.asarray(reference)
    if ours.shape != reference.shape:
        return float("inf")
    return float(np.abs(ours - reference).max() / np.abs(reference).max())


class Checks:
    """Collects named pass/fail checks and prints them; exit() ends the script."""

    def __init__(self):
        self.failed = 0
        self.passed = 0

    def check(self, ok, message):
        print(("PASS " if ok else "FAIL ") + message)
        if ok:
            self.passed += 1
        else:
            self.failed += 1
        return ok

    def exit(self):
        print(f"{self.passed} passed, {self.failed} failed")
        sys.exit(1 if self.failed or not self.passed else 0)


def xdmf_frames(xdmf_path):
    """Reads an .xdmf written by softbody without ParaView: per listed frame, its
    time and the positions and velocities its HDF hyperslabs select (resolved
    with h5py against the .h5 beside it). Returns (times, positions, velocities)."""
    import xml.etree.ElementTree as ET
    import h5py
    import numpy as np
    root = ET.parse(xdmf_path).getroot()
    folder = os.path.dirname(os.path.abspath(xdmf_path))
    collection = root.find("Domain/Grid")
    assert collection.get("CollectionType") == "Temporal"
    times, positions, velocities = [], [], []

    def resolve(item):
        file_name, rest = item.text.strip().split(":", 1)
        dataset, slab = rest.split("|")
        start, stride, count, _ = [[int(v) for v in part.split()] for part in slab.split(":")]
        with h5py.File(os.path.join(folder, file_name), "r") as f:
            data = f[dataset]
            index = tuple(slice(s, s + c * t, t) for s, t, c in zip(start, stride, count))
            values = data[index]
        return values.reshape([int(d) for d in item.get("Dimensions").split()])

    for grid in collection.findall("Grid"):
        times.append(float(grid.find("Time").get("Value")))
        positions.append(resolve(grid.find("Geometry/DataItem")))
        velocity = [a for a in grid.findall("Attribute") if a.get("Name") == "velocity"][0]
        velocities.append(resolve(velocity.find("DataItem")))
    return np.array(times), np.array(positions), np.array(velocities)


def paraview_frames(args, xdmf_path, timeout=120):
    """Reads an .xdmf with ParaView's own Xdmf3 reader (pvpython, Debian's
    python3-paraview): (times, positions, velocities, cells per frame), or None
    when pvpython is not installed."""
    import shutil
    import numpy as np
    pvpython = shutil.which("pvpython")
    if not pvpython:
        return None
    script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "paraview_read.py")
    out = os.path.join(args.work, os.path.basename(xdmf_path) + ".paraview.npz")
    if os.path.exists(out):
        os.remove(out)
    result = subprocess.run([pvpython, "--force-offscreen-rendering", script, os.path.abspath(xdmf_path), out],
                            capture_output=True, text=True, timeout=timeout)
    if result.returncode != 0 or not os.path.exists(out):
        raise RuntimeError("pvpython could not read " + xdmf_path + ":\n" + result.stdout[-2000:] +
                           result.stderr[-2000:])
    data = np.load(out)
    return data["times"], data["positions"], data["velocities"], data["cells"]


def crossings_checker(args):
    """softbody-crossings, built beside the softbody under test; exits with SKIP
    when it was not built (CGAL not found when configuring)."""
    checker = os.path.join(os.path.dirname(os.path.abspath(args.softbody)), "softbody-crossings")
    if not os.path.exists(checker):
        print(f"SKIP: {checker} not built (CGAL not found when configuring: Debian's libcgal-dev)")
        sys.exit(SKIP)
    return checker


def run_crossings(args, checks, path, *options, ranks=1):
    """Runs softbody-crossings on a result file (on `ranks` ranks, with `options`);
    returns its -json report, or None after a failed check when it failed."""
    report = path[:-3] + f"-{ranks}.json"
    command = [crossings_checker(args), path, "-json", report, *options]
    if ranks > 1:
        command = [args.mpiexec, "-n", str(ranks), *command]
    run = subprocess.run(command, capture_output=True, text=True, timeout=300, env=mpi_environment())
    if not checks.check(run.returncode == 0, f"softbody-crossings {os.path.basename(path)} {' '.join(options)} "
                        f"on {ranks} rank(s): exit {run.returncode}"):
        print(run.stdout, run.stderr)
        return None
    with open(report) as f:
        return json.load(f)
