"""softbody-convert and the softbody mesh file (.h5; docs/scenes-and-output.md,
"Mesh files").

(a) Converting tests/data's cube.mesh gives its vertices and tets as this
    script's own MEDIT reader reads them (tools/softbody_tools.py), bit for bit,
    with the format attributes and chunked datasets.
(b) A scene naming the converted .h5 files gives the same result file (every
    dataset byte for byte) as the scene naming the sources, at 1 and 2 ranks: the
    mixed scene (.off through TetGen, .mesh, gmsh 4.1 and 2.2) and the torus .off.
(c) Bad input (missing file, malformed file, unwritable output, unknown input or
    output extension, no file names) gives one line on stderr naming the file and
    a non-zero exit, at 1 and 2 ranks, and leaves no output file, complete or
    partial, behind.
(d) A mesh file written by h5py (variable-length string attributes, its own
    chunks) runs as the .mesh it was made from.
"""
import argparse
import glob
import os
import shutil
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402
import test_bad_input  # noqa: E402

args = harness.arguments()
checks = harness.Checks()
work = os.path.abspath(args.work)
convert = os.path.join(os.path.dirname(os.path.abspath(args.softbody)), "softbody-convert")
meshes = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "meshes")
bad_input = os.path.join(meshes, "..", "bad_input")
TIMEOUT = 120  # seconds for one conversion (TetGen on the torus takes well under one)


def run_convert(options, ranks=1):
    command = [args.mpiexec, "-n", str(ranks), convert, *options]
    return subprocess.run(command, capture_output=True, text=True, timeout=TIMEOUT,
                          env=harness.mpi_environment())


def converted(source, name):
    out = os.path.join(work, name)
    result = run_convert([os.path.join(meshes, source), out])
    if result.returncode != 0:
        print(result.stdout, result.stderr)
    checks.check(result.returncode == 0 and os.path.exists(out), f"softbody-convert {source} {name}")
    return out


# (a) the .mesh converted, against an independent reader of the source
import h5py  # noqa: E402

cube = converted("cube.mesh", "cube.h5")
reference = harness.read_medit(os.path.join(meshes, "cube.mesh"))
with h5py.File(cube, "r") as f:
    vertices, tets = f["vertices"], f["tets"]
    checks.check(vertices.dtype == np.float64 and tets.dtype == np.int64 and
                 vertices.chunks is not None and tets.chunks is not None,
                 f"(a) /vertices {vertices.dtype} and /tets {tets.dtype}, chunked")
    checks.check(vertices[()].tobytes() == np.asarray(reference[0], dtype=np.float64).tobytes(),
                 f"(a) /vertices {vertices.shape} equal the .mesh's bit for bit")
    checks.check(np.array_equal(tets[()], reference[3]), f"(a) /tets {tets.shape} equal the .mesh's")
    attributes = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    checks.check(attributes.get("format") == "softbody-mesh" and attributes.get("version") == 1 and
                 attributes.get("source", "").endswith("cube.mesh"),
                 f"(a) root attributes identify the file: {attributes}")


# (b) scenes naming the .h5 files run as the scenes naming the sources
def h5_scene(scene, sources):
    text = open(os.path.join(meshes, scene)).read()
    for source in sources:
        h5 = converted(source, source.replace(".", "_") + ".h5")
        text = text.replace(source + " ", h5 + " ")
    path = os.path.join(work, scene)
    with open(path, "w") as f:
        f.write(text)
    return path


def result_of(scene, name, ranks):
    out = harness.fresh_result(work, name)
    harness.run(args, ranks, ["-scene", scene, "-steps", 5, "-output", out, "-quiet"])
    return harness.read_all_datasets(out)


for scene, sources in (("mixed-scene.txt", ["box_quads.off", "cube.mesh", "cube-4.1.msh", "cube-2.2.msh"]),
                       ("torus-scene.txt", ["torus.off"])):
    converted_scene = h5_scene(scene, sources)
    for ranks in (1, 2):
        ours = result_of(converted_scene, f"h5_{scene}_{ranks}", ranks)
        theirs = result_of(os.path.join(meshes, scene), f"source_{scene}_{ranks}", ranks)
        different = sorted(name for name in set(ours) | set(theirs)
                           if name not in ours or name not in theirs
                           or ours[name].tobytes() != theirs[name].tobytes())
        checks.check(not different and len(ours) > 0,
                     f"(b) {scene} with .h5 meshes, {ranks} rank(s): {len(ours)} datasets byte-identical"
                     + (f"; differing: {different}" if different else ""))

# (d) a mesh file written by another program (h5py: variable-length string
# attributes, h5py's own chunks) runs as the .mesh it was made from
with h5py.File(os.path.join(work, "by_h5py.h5"), "w") as f:
    f.create_dataset("vertices", data=np.asarray(reference[0], dtype=np.float64), chunks=True)
    f.create_dataset("tets", data=np.asarray(reference[3], dtype=np.int64), chunks=True)
    f.attrs["format"] = "softbody-mesh"
    f.attrs["version"] = np.int64(1)
scene_line = " 1000 1e5 0.3 0  0 0 0  1 0 0 0\n1\n0 1  0 0 1\n"
for name, mesh in (("h5py_scene.txt", os.path.join(work, "by_h5py.h5")),
                   ("medit_scene.txt", os.path.join(meshes, "cube.mesh"))):
    with open(os.path.join(work, name), "w") as f:
        f.write("1\n" + mesh + scene_line)
ours = result_of(os.path.join(work, "h5py_scene.txt"), "h5py", 2)
theirs = result_of(os.path.join(work, "medit_scene.txt"), "medit", 2)
checks.check(sorted(ours) == sorted(theirs) and all(ours[k].tobytes() == theirs[k].tobytes() for k in ours),
             f"(d) a mesh file written by h5py runs as its .mesh ({len(ours)} datasets byte-identical)")

# (c) bad input: one line naming the file, non-zero exit on every rank, no output
unwritable = os.path.join(work, "no_such_folder", "out.h5")
bad_cases = [
    ("missing input", [os.path.join(work, "missing.mesh"), "out.h5"], "missing.mesh"),
    ("malformed .mesh", [os.path.join(bad_input, "truncated.mesh"), "out.h5"], "truncated.mesh:"),
    ("malformed .off", [os.path.join(meshes, "bad_index.off"), "out.h5"], "bad_index.off:16:"),
    ("open .off surface", [os.path.join(meshes, "open_box.off"), "out.h5"], "open_box.off"),
    ("unwritable output", [os.path.join(meshes, "cube.mesh"), unwritable], unwritable),
    ("unknown input extension", [os.path.join(meshes, "cube.geo"), "out.h5"], "cube.geo"),
    ("unknown output extension", [os.path.join(meshes, "cube.mesh"), "out.vtk"], "out.vtk"),
    ("no file names", [], "usage: softbody-convert"),
    ("bad TetGen switches", [os.path.join(meshes, "torus.off"), "out.h5", "-tetgen_switches", "q"],
     "-tetgen_switches"),
]
folder = os.path.join(work, "bad")
wrapped = argparse.Namespace(**vars(args))
wrapped.softbody = convert
for label, options, named in bad_cases:
    for ranks in (1, 2):
        shutil.rmtree(folder, ignore_errors=True)
        os.makedirs(folder)
        options_here = [os.path.join(folder, o) if o.startswith("out.") else o for o in options]
        if ranks == 1:  # as it is usually run: no mpiexec
            result = subprocess.run([convert, *options_here], capture_output=True, text=True,
                                    timeout=TIMEOUT, env=harness.mpi_environment())
            codes, stderr = {"0": result.returncode}, result.stderr
        else:  # each rank's own exit code (test_bad_input.py's wrapper)
            outcome = test_bad_input.run(wrapped, ranks, options_here)
            codes, stderr = (outcome[0], outcome[2]) if outcome else ({}, "(time-out)")
        lines = [line for line in stderr.splitlines() if line.strip()]
        rank_codes = [c for r, c in codes.items() if r != "mpirun"]
        left = os.listdir(folder)
        checks.check(len(rank_codes) == ranks and all(0 < c < 124 for c in rank_codes) and len(lines) == 1
                     and named in lines[0] and not left and not os.path.exists(unwritable),
                     f"(c) {label}, {ranks} rank(s): exit codes {codes}, "
                     f"{len(lines)} line(s) {lines[:2]}, files left {left}")
checks.check(not glob.glob(os.path.join(work, "*.partial-*")), "(c) no partial files left in the work folder")

checks.exit()
