"""Shared helpers for the softbody ctest scripts.

Every script is run by ctest as
    python3 tests/<script>.py --softbody BUILD/softbody --mpiexec MPIEXEC --shared ../shared --work DIR
and exits 0 (pass), 1 (fail) or 77 (skipped: ctest's SKIP_RETURN_CODE).
"""
import argparse
import os
import subprocess
import sys

SKIP = 77


def arguments(extra=None):
    parser = argparse.ArgumentParser()
    parser.add_argument("--softbody", required=True)
    parser.add_argument("--mpiexec", required=True)
    parser.add_argument("--shared", required=True)
    parser.add_argument("--work", required=True)
    if extra:
        extra(parser)
    args = parser.parse_args()
    os.makedirs(args.work, exist_ok=True)
    return args


def seed(args, *parts):
    """Path inside ../shared/seed-data; skips the test when it is absent."""
    path = os.path.join(args.shared, "seed-data", *parts)
    if not os.path.exists(path):
        print(f"SKIP: {path} not found (tests that need ../shared skip without it)")
        sys.exit(SKIP)
    return os.path.abspath(path)


def run(args, ranks, options, timeout=300, check=True):
    """Runs softbody on `ranks` ranks; returns the CompletedProcess (text output)."""
    env = dict(os.environ)
    env.setdefault("OMPI_MCA_rmaps_base_oversubscribe", "1")
    if os.geteuid() == 0:
        env["OMPI_ALLOW_RUN_AS_ROOT"] = "1"
        env["OMPI_ALLOW_RUN_AS_ROOT_CONFIRM"] = "1"
    command = [args.mpiexec, "-n", str(ranks), args.softbody] + [str(o) for o in options]
    result = subprocess.run(command, capture_output=True, text=True, timeout=timeout, env=env)
    if check and result.returncode != 0:
        print("command failed:", " ".join(command))
        print(result.stdout)
        print(result.stderr)
        sys.exit(1)
    return result


def write_scene(path, bodies, velocities=None):
    """bodies: list of (mesh, density, young, poisson, fixed, (px,py,pz), (qw,qx,qy,qz));
    velocities: list of (mesh, vertex, (vx,vy,vz)) or None for no section."""
    with open(path, "w") as f:
        f.write(f"{len(bodies)}\n")
        for mesh, rho, young, nu, fixed, p, q in bodies:
            f.write(f"{mesh} {rho!r} {young!r} {nu!r} {int(fixed)} "
                    + " ".join(repr(float(c)) for c in p) + " "
                    + " ".join(repr(float(c)) for c in q) + "\n")
        if velocities is not None:
            f.write(f"{len(velocities)}\n")
            for m, v, vel in velocities:
                f.write(f"{m} {v} " + " ".join(repr(float(c)) for c in vel) + "\n")
    return path


def read_frames(path):
    """Returns a dict of numpy arrays from a softbody HDF5 result, and its
    "complete" attribute (0 or 1)."""
    import h5py
    with h5py.File(path, "r") as f:
        frames = {name: f[name][()] for name in
                  ("time", "positions", "velocities", "energy/kinetic", "energy/elastic",
                   "energy/gravitational", "mesh/tets", "mesh/boundary_triangles", "mesh/vertex_body",
                   "mesh/rest_positions", "mesh/body_fixed")}
        frames["complete"] = int(f.attrs["complete"])
    return frames


def box_mesh(args, name, size, cells):
    """Writes a box mesh (tools/box_mesh.py) into the work folder; returns its path."""
    tools = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools")
    path = os.path.join(args.work, name)
    subprocess.run([sys.executable, os.path.join(tools, "box_mesh.py"), path, "--size", *map(str, size),
                    "--cells", *map(str, cells)], check=True, capture_output=True)
    return path


def read_petsc_aij(path):
    """Reads a PETSc binary AIJ matrix file into a scipy-free dense-or-COO triple
    (rows, cols, values, shape). Big-endian int32 header, as PETSc writes it."""
    import numpy as np
    with open(path, "rb") as f:
        header = np.fromfile(f, dtype=">i4", count=4)
        assert header[0] == 1211216, f"{path}: not a PETSc Mat file"
        m, n, nnz = int(header[1]), int(header[2]), int(header[3])
        row_lengths = np.fromfile(f, dtype=">i4", count=m)
        cols = np.fromfile(f, dtype=">i4", count=nnz)
        values = np.fromfile(f, dtype=">f8", count=nnz)
    rows = np.repeat(np.arange(m), row_lengths)
    return rows, cols.astype(np.int64), values.astype(np.float64), (m, n)


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


def mpi_env():
    """The environment `run` gives mpirun (root allowed, oversubscription), for
    scripts that start softbody themselves (signals, pseudo-terminals)."""
    env = dict(os.environ)
    env.setdefault("OMPI_MCA_rmaps_base_oversubscribe", "1")
    if os.geteuid() == 0:
        env["OMPI_ALLOW_RUN_AS_ROOT"] = "1"
        env["OMPI_ALLOW_RUN_AS_ROOT_CONFIRM"] = "1"
    return env


def read_all_datasets(path):
    """Every dataset of an HDF5 file as {name: numpy array}."""
    import h5py
    found = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, item: found.__setitem__(name, item[()]) if isinstance(item, h5py.Dataset)
                     else None)
    return found


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
