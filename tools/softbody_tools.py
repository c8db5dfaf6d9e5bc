"""Helpers shared by the tools (tools/*.py) and the scripted tests (tests/regression/).

Import it with the tools folder on the path:
    sys.path.insert(0, os.path.join(ROOT, "tools"))
    import softbody_tools

What is here:
- add_option: one option in the tools' convention (PETSc style -tool_name, the
  GNU spelling --tool-name and older spellings as aliases), add_run_options
  for -softbody, -mpiexec and -study_dir, comma_list and
  flatten for options that take lists, parse_with_passthrough for a command
  line whose part after `--` goes to softbody;
- running softbody under MPI: mpi_environment, softbody_command, one_line_error;
- softbody's files: write_scene (the scene format of src/io/scene.hpp),
  read_frames / read_all_datasets (the HDF5 result), read_medit (MEDIT .mesh),
  read_petsc_aij (the matrices of -export_matrices);
- lumped_masses: rho V / 4 per vertex, computed here from the mesh alone.

Needs Debian's /usr/bin/python3 with python3-numpy (and python3-h5py for the
HDF5 readers, imported when used).
"""
import argparse
import os

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG_DIR = os.path.join(ROOT, "config")


# ----------------------------------------------------------------------------- options

class ToolParser(argparse.ArgumentParser):
    """The tools' argparse: -help (PETSc's spelling), --help and -h print the help.

    argparse's own -h would read "-help" as -h with the argument "elp" and fail."""

    def __init__(self, **kwargs):
        super().__init__(add_help=False, **kwargs)
        self.add_argument("-help", "--help", "-h", action="help", help="show this help and exit")


def option_spellings(name, *aliases):
    """The spellings of option `name` (letters, digits, underscores): PETSc's
    -name first, then GNU's --name-with-dashes, then the aliases (older spellings
    kept working), without repeats."""
    spellings = ["-" + name, "--" + name.replace("_", "-")]
    for alias in aliases:
        if alias not in spellings:
            spellings.append(alias)
    return spellings


def add_option(parser, name, *aliases, **kwargs):
    """parser.add_argument for option `name` under all its spellings
    (option_spellings); the parsed value is args.<dest>, dest defaulting to name.
    Example: add_option(parser, "study_dir", dest="study_dir", default="study")
    accepts -study_dir DIR, --study-dir DIR, -study_dir=DIR and --study-dir=DIR.
    Build the parser with allow_abbrev=False so that no prefix of a name is
    taken for the option."""
    kwargs.setdefault("dest", name)
    return parser.add_argument(*option_spellings(name, *aliases), **kwargs)


def add_run_options(parser, study_dir=None, study_dir_help="output folder"):
    """The options every tool that runs softbody shares: -softbody PATH (default
    build/softbody of this project), -mpiexec CMD (default mpirun) and, with a
    default folder `study_dir`, -study_dir DIR."""
    add_option(parser, "softbody", metavar="PATH", default=os.path.join(ROOT, "build", "softbody"),
               help="softbody executable (default: build/softbody of this project)")
    add_option(parser, "mpiexec", metavar="CMD", default="mpirun", help="MPI launcher (default: mpirun)")
    if study_dir is not None:
        add_option(parser, "study_dir", metavar="DIR", default=study_dir,
                   help=f"{study_dir_help} (default: {study_dir})")


def parse_with_passthrough(parser, argv):
    """Parses argv up to a `--`; what follows it is returned in args.extra (the
    softbody options study.py and bench.py pass to every run). An unknown option
    before `--` is an error that says where softbody options go."""
    if "--" in argv:
        cut = argv.index("--")
        argv, passthrough = argv[:cut], argv[cut + 1:]
    else:
        passthrough = []
    args, unknown = parser.parse_known_args(argv)
    if unknown:
        parser.error(f"unrecognized arguments: {' '.join(unknown)} (softbody options go after `--`)")
    args.extra = passthrough
    return args


def comma_list(kind):
    """argparse type: comma-separated values of `kind`; with nargs='+' an option
    also takes them separated by spaces (flatten joins the pieces)."""
    def parse(text):
        try:
            return [kind(item) for item in text.split(",") if item.strip()]
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error))
    return parse


def flatten(lists):
    """The values of a list of lists in order, each once."""
    out = []
    for item in lists:
        for value in item:
            if value not in out:
                out.append(value)
    return out


# ----------------------------------------------------------------------------- running softbody

def mpi_environment():
    """The environment for mpirun that ./run sets: Open MPI allowed to run as
    root, and more ranks than cores allowed (oversubscription)."""
    env = dict(os.environ)
    env.setdefault("OMPI_MCA_rmaps_base_oversubscribe", "1")
    if os.geteuid() == 0:
        env["OMPI_ALLOW_RUN_AS_ROOT"] = "1"
        env["OMPI_ALLOW_RUN_AS_ROOT_CONFIRM"] = "1"
    return env


def softbody_command(mpiexec, ranks, softbody, options):
    """The command line `MPIEXEC -n RANKS SOFTBODY OPTIONS...` (options as strings)."""
    return [mpiexec, "-n", str(ranks), softbody] + [str(o) for o in options]


def error_lines(text):
    """softbody's own error lines ("softbody: error: ...") in a run's output."""
    return [line.strip() for line in text.splitlines() if line.strip().startswith("softbody: error:")]


def one_line_error(text, returncode):
    """The run's own error line (softbody: error: ...), else the last informative
    line that is not part of mpirun's banners, else the exit status."""
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    for line in lines:
        if line.startswith("softbody: error"):
            return line
    noise = ("---", "Primary job", "a non-zero exit code", "mpirun detected", "the job to be",
             "Process name", "Exit code", "Per user-direction")
    informative = [l for l in lines if not any(l.startswith(n) or n in l for n in noise)]
    for line in informative:
        if "error" in line.lower() or "signal" in line.lower():
            return line
    if informative:
        return informative[-1]
    return f"exit status {returncode}"


# ----------------------------------------------------------------------------- softbody's files

def write_scene(path, bodies, velocities=None):
    """Writes a scene file; returns its path.
    bodies: list of (mesh, density, young, poisson, fixed, (px, py, pz), (qw, qx, qy, qz));
    velocities: list of (mesh index, vertex index, (vx, vy, vz)), or None for no section."""
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


# The datasets with one row per frame (the others hold the mesh).
PER_FRAME = ("time", "positions", "velocities", "energy/")
FRAME_DATASETS = ("time", "positions", "velocities", "energy/kinetic", "energy/elastic",
                  "energy/gravitational", "mesh/tets", "mesh/boundary_triangles", "mesh/vertex_body",
                  "mesh/rest_positions", "mesh/body_fixed")


def read_frames(path, first_frames=None):
    """The datasets of a softbody HDF5 result (FRAME_DATASETS) as a dict of numpy
    arrays, its "complete" attribute (0 or 1) under "complete" and the frames the
    file holds (the datasets' extent) under "stored_frames". With first_frames = n
    only the first n frames of the per-frame datasets are read: after a SIGKILL
    the frame being written may have its chunk listed in the file but not
    written (HDF5 evicts metadata between flushes), so reading it fails, while
    the frames the .xdmf lists were flushed whole."""
    import h5py
    with h5py.File(path, "r") as f:
        frames = {name: f[name][()] if first_frames is None or not name.startswith(PER_FRAME)
                  else f[name][:first_frames] for name in FRAME_DATASETS}
        frames["complete"] = int(f.attrs["complete"])
        frames["stored_frames"] = int(f["time"].shape[0])
    return frames


def read_all_datasets(path):
    """Every dataset of an HDF5 file as {name: numpy array}."""
    import h5py
    found = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, item: found.__setitem__(name, item[()]) if isinstance(item, h5py.Dataset)
                     else None)
    return found


def read_medit(path):
    """A MEDIT .mesh file: vertices (#V x 3), triangles (#B x 3, 0-based), their
    refs (#B), tets (#T x 4, 0-based). Reads the sections Vertices, Triangles and
    Tetrahedra (a missing section gives an empty array); any other keyword is an error."""
    tokens = open(path).read().split()
    widths = {"Vertices": 4, "Triangles": 4, "Tetrahedra": 5}
    sections = {word: np.zeros((0, width)) for word, width in widths.items()}
    pos = 0
    while pos < len(tokens):
        word = tokens[pos]
        pos += 1
        if word == "End":
            break
        if word in ("MeshVersionFormatted", "Dimension"):
            pos += 1
        elif word in widths:
            n = int(tokens[pos])
            pos += 1
            sections[word] = np.array(tokens[pos:pos + n * widths[word]], dtype=float).reshape(n, widths[word])
            pos += n * widths[word]
        else:
            raise ValueError(f"{path}: unexpected keyword {word}")
    vertices = sections["Vertices"][:, :3]
    triangles = sections["Triangles"][:, :3].astype(np.int64) - 1
    refs = sections["Triangles"][:, 3].astype(np.int64)
    tets = sections["Tetrahedra"][:, :4].astype(np.int64) - 1
    return vertices, triangles, refs, tets


def read_petsc_aij(path):
    """A PETSc binary AIJ matrix file (as -export_matrices writes them) as the
    triple-plus-shape (rows, cols, values, (m, n)). Big-endian int32 header."""
    with open(path, "rb") as f:
        header = np.fromfile(f, dtype=">i4", count=4)
        assert header[0] == 1211216, f"{path}: not a PETSc Mat file"
        m, n, nnz = int(header[1]), int(header[2]), int(header[3])
        row_lengths = np.fromfile(f, dtype=">i4", count=m)
        cols = np.fromfile(f, dtype=">i4", count=nnz)
        values = np.fromfile(f, dtype=">f8", count=nnz)
    rows = np.repeat(np.arange(m), row_lengths)
    return rows, cols.astype(np.int64), values.astype(np.float64), (m, n)


# ----------------------------------------------------------------------------- mechanics

def lumped_masses(tets, rest, vertex_body, densities):
    """Lumped vertex masses (kg): a quarter of rho |V_t| of every tet to each of its
    corners. tets #T x 4 (0-based), rest #V x 3 (m), vertex_body #V (body index),
    densities per body (kg/m^3)."""
    corners = rest[tets]
    volumes = np.abs(np.linalg.det(corners[:, 1:] - corners[:, :1])) / 6.0
    rho = np.asarray(densities)[vertex_body[tets[:, 0]]]
    masses = np.zeros(len(rest))
    for corner in range(4):
        np.add.at(masses, tets[:, corner], rho * volumes / 4.0)
    return masses
