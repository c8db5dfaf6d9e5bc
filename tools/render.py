#!/usr/bin/python3
"""Renders a softbody HDF5 result with VTK: PNG frames, and a GIF and an MP4 of the run.

    ./run render RESULT.h5 [options]          (runs /usr/bin/python3 tools/render.py)

What a frame shows (docs/rendering.md has pictures and the reasons behind each choice):
- the boundary triangles (/mesh/boundary_triangles) of every body, lit and smooth shaded
  (point normals; creases sharper than FEATURE_ANGLE stay sharp, so a cube keeps its edges);
- free bodies coloured by one of
    deformation  |x - (c + R (X - C))| (m): the displacement LEFT AFTER removing the body's
                 best-fit rigid motion (mass-weighted centroid translation C -> c plus the
                 rotation R of a Kabsch fit of the positions x to the rest positions X), so
                 a falling or spinning body that does not deform stays at 0 (default);
    speed        |v| (m/s);
    displacement |x - X| (m), rigid motion included;
  on ONE colour scale for all frames (0 .. -vmax, default the largest vertex value of the
  rendered frames rounded up to a short number), shown by a colour bar with units;
- fixed bodies grey and translucent (-fixed_opacity), so they do not hide the action;
- the ground plane y = y0 with a grid when the file records it (root attribute "ground_y")
  or -ground y0 is given;
- a time stamp "t = 1.240 s" and an optional -title.

Camera (-camera): follow (default) frames the free bodies of each frame, the framing
smoothed over -smooth seconds so the view glides after a falling body instead of jumping;
fixed frames the free bodies of all rendered frames at once; scene frames everything,
fixed bodies included; -zoom scales the framed bodies. The view direction is -view
ELEV,AZIM (degrees, about the up axis -up; auto: against gravity when the file records
it, y when the scene has a ground, else z).

Options are PETSc style, -name_with_underscores, each with a --name-with-dashes alias:
  -render_dir DIR (--render-dir, --out)   output folder (default RESULT_frames/ beside RESULT)
  -frames all|N|A:B|0,10,50   -every k   -size 960x720   -color deformation|speed|displacement
  -camera follow|fixed|scene   -view 20,-60   -up auto|x|y|z   -ground y0   -smooth 0.3
  -gif  -mp4  -fps 20  -gif_width 480   -title TEXT   -vmax V   -colormap coolwarm
  -zoom 1   -fixed_opacity 0.3   -background R,G,B[:R,G,B]   -antialias fxaa|none
(-help lists them all.) Errors (missing file, bad option, bad frame) print one line
"render.py: error: ..." and exit non-zero.

Off-screen: Debian's python3-vtk9 renders through GLX only (no EGL/OSMesa build), so without
a usable $DISPLAY this script starts its own Xvfb (Debian package xvfb) on a free display
number and stops it at the end; Mesa's llvmpipe does the drawing on the CPU.

From another script:
  import sys; sys.path.insert(0, "tools"); import render
  render.render_frame("r.h5", 10, "f10.png", color="speed")
  render.render("r.h5", frames=[0, 5, 10], out_dir="frames")   # returns the files written

Needs Debian's /usr/bin/python3 with python3-numpy, python3-h5py, python3-vtk9, the xvfb
package when there is no X display, ffmpeg for -mp4 and -gif (python3-pil is the GIF
fallback), and python3-matplotlib only for colour maps other than the built-in ones.
"""
import argparse
import atexit
import math
import os
import shutil
import signal
import subprocess
import sys
import time as _time

try:
    import numpy as np
    import h5py
except ImportError as _error:  # pragma: no cover - depends on the interpreter
    sys.exit(f"render.py: error: {_error}: run with Debian's /usr/bin/python3 "
             "(apt-get install python3-numpy python3-h5py)")

DEFAULT_SIZE = (960, 720)
PR_SET_PDEATHSIG = 1  # prctl(2) option: signal this process when its parent dies
# Camera elevation above the horizontal plane and azimuth about the up axis (degrees):
# a three-quarter view from slightly above, the classic view of a 3-D scene.
DEFAULT_VIEW = (20.0, -60.0)
COLOR_LABELS = {"deformation": "deformation (m)", "speed": "speed (m/s)",
                "displacement": "displacement (m)"}
CHUNK_VALUES = 30_000_000  # floats read at a time when scanning all frames
# Vertical field of view of the perspective camera (degrees): a normal lens, little distortion.
VIEW_ANGLE = 30.0
# Fraction of the image (height, and width left of the colour bar) the framed bodies
# may fill: the rest is a margin so that the smoothed camera never cuts a body off.
FILL = 0.78
# At most this many vertices (spread over the mesh) decide the framing of each frame.
FRAMING_POINTS = 20000
# Normals of faces meeting at more than this angle (degrees) are not averaged, so the
# edges of a cube stay sharp while a curved surface is shaded smoothly.
FEATURE_ANGLE = 75.0
# Default time window (s) over which the follow camera's framing is smoothed: long
# enough to hide the jitter of a bouncing body, short enough to keep up with a fall.
DEFAULT_SMOOTH = 0.3
FIXED_GREY = (0.62, 0.63, 0.66)
DEFAULT_FIXED_OPACITY = 0.3
GROUND_COLOR = (0.80, 0.78, 0.72)
GRID_COLOR = (0.55, 0.53, 0.48)
DEFAULT_BACKGROUND = ((0.97, 0.97, 0.98), (0.78, 0.82, 0.88))  # top, bottom
# Fraction of the image width kept free on the right for the colour bar and its labels.
BAR_ROOM = 0.16
BAR_LABELS = 6  # labels on the colour bar, 0 and the top included
# Built-in colour maps (position 0..1, r, g, b), no matplotlib needed: coolwarm is
# Moreland's diverging map (blue at rest, red at the most) with its dark blue end
# lightened, since a lit surface at rest otherwise looks nearly black in its shadows.
BUILTIN_COLORMAPS = {
    "coolwarm": [(0.0, 0.340, 0.460, 0.860), (0.25, 0.552, 0.690, 0.996),
                 (0.5, 0.865, 0.865, 0.865), (0.75, 0.958, 0.604, 0.482),
                 (1.0, 0.706, 0.016, 0.150)],
    "blue-red": [(0.0, 0.0, 0.2, 1.0), (1.0, 1.0, 0.0, 0.0)],
}


class RenderError(ValueError):
    """A problem with the input or the environment, reported as one line."""


# --------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------

def infer_body_fixed(positions, rest, vertex_body, nbodies, chunk=None):
    """Heuristic for files without /mesh/body_fixed: a body is fixed when none of its
    vertices ever moves (positions equal the rest positions in every frame).
    positions: an h5py dataset or array [F][V][3]. Returns bool[nbodies]."""
    moved = np.zeros(nbodies, dtype=bool)
    nframes = positions.shape[0]
    step = chunk or max(1, CHUNK_VALUES // max(1, positions.shape[1] * 3))
    for start in range(0, nframes, step):
        block = np.asarray(positions[start:start + step])
        vertex_moved = np.any(block != rest[None], axis=(0, 2))
        moved |= np.bincount(vertex_body[vertex_moved], minlength=nbodies)[:nbodies] > 0
    return ~moved


def body_fixed(h5, rest, vertex_body, nbodies):
    """bool[nbodies]: which bodies are fixed. Reads /mesh/body_fixed (int per body)
    when the file has it, else falls back to infer_body_fixed()."""
    if "mesh/body_fixed" in h5:
        flags = np.asarray(h5["mesh/body_fixed"][()]).astype(np.int64).ravel()
        if flags.size < nbodies:
            raise RenderError(f"/mesh/body_fixed has {flags.size} entries for {nbodies} bodies")
        return flags[:nbodies] != 0
    return infer_body_fixed(h5["positions"], rest, vertex_body, nbodies)


def select_frames(spec, nframes, every=1):
    """'all', 'N' (N frames evenly spaced, first and last included), a range 'A:B' (A to B,
    both included) or a list '0,10,50' (a trailing comma makes a one-frame list: '7,';
    negative indices count from the end); then every k-th of those. Returns a list of
    frame indices."""
    if isinstance(spec, (list, tuple, range)):
        items = [int(s) for s in spec]
    else:
        spec = str(spec).strip()
        if spec == "all":
            items = list(range(nframes))
        elif ":" in spec:
            try:
                first, last = (int(s) for s in spec.split(":"))
            except ValueError:
                raise RenderError(f"-frames {spec!r}: a range is FIRST:LAST, e.g. 100:200")
            items = list(range(first, last + 1))
        elif "," not in spec:
            try:
                count = int(spec)
            except ValueError:
                raise RenderError(f"-frames {spec!r}: expected all, a count N, or a list like 0,10,50")
            if count < 1:
                raise RenderError(f"-frames {spec}: the count must be at least 1")
            if count >= nframes:
                items = list(range(nframes))
            else:
                picks = np.round(np.linspace(0, nframes - 1, count)).astype(int)
                items = sorted(set(int(p) for p in picks))
        else:
            try:
                items = [int(s) for s in spec.split(",") if s.strip()]
            except ValueError:
                raise RenderError(f"-frames {spec!r}: expected all, a count N, or a list like 0,10,50")
    frames = []
    for i in items:
        j = i + nframes if i < 0 else i
        if not 0 <= j < nframes:
            raise RenderError(f"frame {i} out of range (the file has {nframes} frames, 0..{nframes - 1})")
        frames.append(j)
    if every < 1:
        raise RenderError(f"-every {every}: must be at least 1")
    return frames[::every]


def boundary_orientation(rest, tris, vertex_body, nbodies):
    """Signed volume enclosed by each body's boundary triangles at rest (positive
    when they are outward oriented)."""
    a, b, c = rest[tris[:, 0]], rest[tris[:, 1]], rest[tris[:, 2]]
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    return np.bincount(vertex_body[tris[:, 0]], weights=vol, minlength=nbodies)[:nbodies]


def lumped_masses(rest, tets, vertex_body, density):
    """Vertex masses (kg): each tet's mass rho |det| / 6 shared equally by its 4 vertices.
    Falls back to unit masses (centroid = vertex mean) without tets or densities."""
    nvertices = len(rest)
    if tets is None or len(tets) == 0 or density is None:
        return np.ones(nvertices)
    a, b, c, d = (rest[tets[:, k]] for k in range(4))
    volume = np.abs(np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)) / 6.0
    mass = volume * density[vertex_body[tets[:, 0]]]
    masses = np.bincount(tets.ravel(), weights=np.repeat(mass / 4.0, 4), minlength=nvertices)
    masses[masses <= 0] = 1e-300  # vertices in no tet: no weight in the fit
    return masses


def rigid_fit(positions, rest, masses, vertex_body, nbodies):
    """Best-fit rigid motion of every body, x ~ c + R (X - C): C and c the mass-weighted
    centroids of the rest and current positions, R the rotation of the Kabsch fit (polar
    factor of the mass-weighted covariance sum m (x - c)(X - C)^T, reflection removed).
    Returns (R [B][3][3], c [B][3], C [B][3])."""
    weight = np.bincount(vertex_body, weights=masses, minlength=nbodies)[:nbodies]
    weight[weight <= 0] = 1.0

    def centroid(points):
        return np.stack([np.bincount(vertex_body, weights=masses * points[:, k], minlength=nbodies)
                         [:nbodies] for k in range(3)], axis=1) / weight[:, None]

    rest_centroid, centroid_now = centroid(rest), centroid(positions)
    q = (rest - rest_centroid[vertex_body]) * masses[:, None]
    p = positions - centroid_now[vertex_body]
    covariance = np.zeros((nbodies, 3, 3))
    for i in range(3):
        for j in range(3):
            covariance[:, i, j] = np.bincount(vertex_body, weights=p[:, i] * q[:, j],
                                              minlength=nbodies)[:nbodies]
    u, _, vt = np.linalg.svd(covariance)
    sign = np.sign(np.linalg.det(u @ vt))
    sign[sign == 0] = 1.0
    u[:, :, 2] *= sign[:, None]
    return u @ vt, centroid_now, rest_centroid


def deformation(positions, rest, masses, vertex_body, nbodies):
    """Per-vertex |x - (c + R (X - C))| (m): displacement without the body's rigid motion."""
    rotation, centroid_now, rest_centroid = rigid_fit(positions, rest, masses, vertex_body, nbodies)
    rigid = centroid_now[vertex_body] + np.einsum(
        "vij,vj->vi", rotation[vertex_body], rest - rest_centroid[vertex_body])
    return np.linalg.norm(positions - rigid, axis=1)


def read_attribute(h5, names):
    """First of the root or /mesh attributes `names` the file has, else None."""
    for holder in (h5, h5.get("mesh")):
        if holder is None:
            continue
        for name in names:
            if name in holder.attrs:
                return np.asarray(holder.attrs[name]).ravel()
    return None


class Result:
    """The static data of a result file plus what is the same for every frame."""

    def __init__(self, path, color="deformation", vmax=None):
        if color not in COLOR_LABELS:
            raise RenderError(f"unknown colour quantity {color!r} ({', '.join(COLOR_LABELS)})")
        if not os.path.isfile(path):
            raise RenderError(f"{path}: no such file")
        self.path = path
        self.color = color
        self.user_vmax = vmax
        if vmax is not None and not vmax > 0:
            raise RenderError(f"the colour scale maximum must be positive (got {vmax})")
        try:
            f = h5py.File(path, "r")
        except OSError as error:
            raise RenderError(f"{path}: not an HDF5 file ({error})")
        with f:
            self._read(f)

    def _read(self, f):
        path = self.path
        for name in ("time", "positions", "mesh/boundary_triangles", "mesh/vertex_body",
                     "mesh/rest_positions"):
            if name not in f:
                raise RenderError(f"{path}: no /{name} dataset (not a softbody result?)")
        if self.color == "speed" and "velocities" not in f:
            raise RenderError(f"{path}: no /velocities dataset (needed by -color speed)")
        self.time = np.asarray(f["time"][()], dtype=float).ravel()
        self.tris = np.asarray(f["mesh/boundary_triangles"][()], dtype=np.int64).reshape(-1, 3)
        self.vertex_body = np.asarray(f["mesh/vertex_body"][()], dtype=np.int64).ravel()
        self.rest = np.asarray(f["mesh/rest_positions"][()], dtype=float).reshape(-1, 3)
        pos = f["positions"]
        self.nframes, self.nvertices = pos.shape[0], pos.shape[1]
        if self.nframes == 0 or len(self.time) == 0:
            raise RenderError(f"{path}: no frames")
        self.nframes = min(self.nframes, len(self.time))
        if self.rest.shape[0] != self.nvertices or self.vertex_body.size != self.nvertices:
            raise RenderError(f"{path}: /positions has {self.nvertices} vertices, "
                              f"/mesh/rest_positions {self.rest.shape[0]}, "
                              f"/mesh/vertex_body {self.vertex_body.size}")
        if self.tris.size and (self.tris.min() < 0 or self.tris.max() >= self.nvertices):
            raise RenderError(f"{path}: /mesh/boundary_triangles indexes outside 0..{self.nvertices - 1}")
        self.nbodies = int(self.vertex_body.max()) + 1 if self.vertex_body.size else 0
        if "mesh/body_fixed" in f:
            self.nbodies = max(self.nbodies, int(f["mesh/body_fixed"].shape[0]))
        self.fixed = body_fixed(f, self.rest, self.vertex_body, self.nbodies)
        self.face_body = self.vertex_body[self.tris[:, 0]]
        self.face_fixed = self.fixed[self.face_body]
        self.free_vertices = np.unique(self.tris[~self.face_fixed]) if self.tris.size else np.zeros(0, int)
        self.all_vertices = np.unique(self.tris) if self.tris.size else np.zeros(0, int)
        tets = np.asarray(f["mesh/tets"][()], dtype=np.int64).reshape(-1, 4) if "mesh/tets" in f else None
        density = (np.asarray(f["mesh/body_material"][()], dtype=float).reshape(-1, 3)[:, 0]
                   if "mesh/body_material" in f else None)
        if density is not None and len(density) < self.nbodies:
            density = None
        self.masses = lumped_masses(self.rest, tets, self.vertex_body, density)
        ground = read_attribute(f, ("ground_y", "ground"))
        self.ground = float(ground[0]) if ground is not None and ground.size else None
        gravity = read_attribute(f, ("gravity",))
        self.gravity = gravity if gravity is not None and gravity.size == 3 else None
        self.warnings = []
        # Boundary triangles should be outward oriented; flip a body whose are not
        # (and say so: that is a bug of the program that wrote the file).
        orientation = boundary_orientation(self.rest, self.tris, self.vertex_body, self.nbodies)
        inward = np.nonzero(orientation < 0)[0]
        if inward.size:
            self.warnings.append("boundary triangles of bodies %s are inward oriented "
                                 "(flipped for drawing)" % ", ".join(map(str, inward)))
            flip = np.isin(self.face_body, inward)
            self.tris[flip] = self.tris[flip][:, [0, 2, 1]]

    def positions(self, frames):
        """positions [len(frames)][V][3] of the listed frames, read in chunks."""
        frames = list(frames)
        out = np.empty((len(frames), self.nvertices, 3))
        with h5py.File(self.path, "r") as f:
            data = f["positions"]
            for i, k in enumerate(frames):
                out[i] = data[k]
        return out

    def frame(self, k):
        """(positions [V][3], per-vertex colour values [V]) of frame k."""
        with h5py.File(self.path, "r") as f:
            p = np.asarray(f["positions"][k], dtype=float)
            v = np.asarray(f["velocities"][k], dtype=float) if self.color == "speed" else None
        return p, self.values(p, v)

    def values(self, positions, velocities=None):
        """Per-vertex colour quantity [V] at these positions (velocities for speed)."""
        if self.color == "speed":
            return np.linalg.norm(velocities, axis=1)
        if self.color == "displacement":
            return np.linalg.norm(positions - self.rest, axis=1)
        return deformation(positions, self.rest, self.masses, self.vertex_body, self.nbodies)

    def colour_scale(self, frames):
        """Top of the colour scale: -vmax, else the largest over `frames` of each frame's
        SCALE_PERCENTILE-th percentile of the free vertices' values (a few flapping tips
        would otherwise leave the rest of the body one colour; values above the top are
        drawn in the top colour)."""
        if self.user_vmax is not None:
            return float(self.user_vmax)
        top = 0.0
        with h5py.File(self.path, "r") as f:
            for k in frames:
                p = np.asarray(f["positions"][k], dtype=float)
                v = np.asarray(f["velocities"][k], dtype=float) if self.color == "speed" else None
                values = self.values(p, v)[self.free_vertices]
                values = values[np.isfinite(values)]
                if values.size:
                    top = max(top, float(np.percentile(values, SCALE_PERCENTILE)))
        return top if top > 0 else 1.0


# --------------------------------------------------------------------------------------
# Camera
# --------------------------------------------------------------------------------------

UP_AXES = {"x": 0, "y": 1, "z": 2}


def view_basis(elev, azim, up):
    """Unit vectors (toward the viewer, camera up, camera right) in data coordinates for a
    camera at elevation `elev` and azimuth `azim` (degrees) about the axis `up`."""
    k = UP_AXES[up]
    a1, a2 = (k + 1) % 3, (k + 2) % 3  # the horizontal axes, right-handed with the up axis
    e, a = math.radians(elev), math.radians(azim)
    toward = np.zeros(3)
    toward[a1] = math.cos(e) * math.cos(a)
    toward[a2] = math.cos(e) * math.sin(a)
    toward[k] = math.sin(e)
    vertical = np.zeros(3)
    vertical[k] = 1.0
    right = np.cross(vertical, toward)
    if np.linalg.norm(right) < 1e-9:  # looking straight along the up axis
        right = np.zeros(3)
        right[a2] = 1.0
    right /= np.linalg.norm(right)
    camup = np.cross(toward, right)
    return toward, camup, right


def framing(points, basis, aspect, fill=FILL):
    """(focal point, distance) of a perspective camera looking along -toward that shows all
    `points` [N][3] within the fraction `fill` of the image: point p (relative to the focal point) needs
    the distance |p . right| / tan(half width) + p . toward, and likewise vertically."""
    toward, camup, right = basis
    sx, sy = points @ right, points @ camup
    lo, hi = points.min(axis=0), points.max(axis=0)
    # Centre the focal point on the points' projection, not on their 3-D box.
    centre = 0.5 * (lo + hi)
    centre = centre + right * (0.5 * (sx.min() + sx.max()) - centre @ right) \
        + camup * (0.5 * (sy.min() + sy.max()) - centre @ camup)
    tan_v = math.tan(math.radians(VIEW_ANGLE) / 2) * fill
    tan_h = tan_v * aspect
    rel = points - centre
    need = np.maximum(np.abs(rel @ right) / tan_h, np.abs(rel @ camup) / tan_v) + rel @ toward
    size = float(np.linalg.norm(hi - lo))
    return centre, max(float(need.max()), 0.05 * size, 1e-6)


def smooth_series(values, times, window):
    """Gaussian smoothing in time (standard deviation window / 2) of values [F][...]."""
    if window <= 0 or len(times) < 2:
        return values.copy()
    sigma = window / 2.0
    out = np.empty_like(values)
    for i, t in enumerate(times):
        w = np.exp(-0.5 * ((times - t) / sigma) ** 2)
        w /= w.sum()
        out[i] = np.tensordot(w, values, axes=(0, 0))
    return out


def running_max(values, times, window):
    """Largest value within +-window of each time (so smoothing never shrinks below it)."""
    return np.array([values[np.abs(times - t) <= window].max() for t in times])


def camera_path(result, frames, mode, basis, aspect, smooth, fill=FILL):
    """Per rendered frame: (focal points [F][3], distances [F])."""
    frames = list(frames)
    vertices = result.free_vertices if mode != "scene" and result.free_vertices.size else result.all_vertices
    if vertices.size == 0:
        vertices = np.arange(result.nvertices)
    if vertices.size > FRAMING_POINTS:  # a spread-out subset frames as well and costs less
        vertices = vertices[np.linspace(0, vertices.size - 1, FRAMING_POINTS).astype(int)]
    centres, distances, hulls = [], [], []
    with h5py.File(result.path, "r") as f:
        data = f["positions"]
        for k in frames:
            p = np.asarray(data[k], dtype=float)[vertices]
            p = p[np.isfinite(p).all(axis=1)]
            if not len(p):
                p = result.rest[vertices]
            c, d = framing(p, basis, aspect, fill)
            centres.append(c)
            distances.append(d)
            hulls.append(extreme_points(p, basis))
    if mode in ("fixed", "scene"):
        c, d = framing(np.concatenate(hulls), basis, aspect, fill)
        return np.repeat(c[None], len(frames), axis=0), np.full(len(frames), d)
    times = result.time[frames]
    centres, distances = np.array(centres), np.array(distances)
    distances = smooth_series(running_max(distances, times, smooth), times, smooth)
    return smooth_series(centres, times, smooth), distances


def extreme_points(points, basis):
    """The points that can decide the framing of a set containing them: the extremes
    along the camera axes and the diagonals between them."""
    toward, camup, right = basis
    picks = set()
    for axis in (right, camup, toward, right + camup, right - camup,
                 right + toward, right - toward, camup + toward, camup - toward):
        s = points @ axis
        picks.update((int(np.argmin(s)), int(np.argmax(s))))
    return points[sorted(picks)]


# --------------------------------------------------------------------------------------
# Off-screen display
# --------------------------------------------------------------------------------------

def _die_with_parent():
    """In the child, before exec: ask Linux to send SIGTERM when this script dies, so that a
    render killed by a signal (when atexit handlers do not run) leaves no Xvfb behind."""
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass


class VirtualDisplay:
    """An Xvfb server of our own when there is no X display (Debian's VTK renders through
    GLX only), on the first free display number from FIRST_DISPLAY up.

    Why not let Xvfb choose (-displayfd alone picks the lowest free number, usually :0):
    hwloc's GL plugin, loaded by every mpiexec and MPI rank on Debian, opens each of the
    displays :0 to :9 while it reads the machine's topology. A simulation started while a
    render's Xvfb holds one of those numbers connects to it, and if the render ends at that
    moment Xlib aborts the simulation ("X connection to :0 broken"). Displays from :20 up
    are never probed."""

    FIRST_DISPLAY = 20   # above hwloc's probe range :0..:9, and clear of the usual :10..:19
    LAST_DISPLAY = 199   # tried in turn; one render needs one

    def __init__(self):
        self.process = None

    def ensure(self):
        if os.environ.get("DISPLAY") and self._display_works():
            return
        xvfb = shutil.which("Xvfb")
        if xvfb is None:
            raise RenderError("no X display and no Xvfb: apt-get install -y --no-install-recommends xvfb "
                              "(Debian's VTK renders off-screen through GLX only)")
        for number in range(self.FIRST_DISPLAY, self.LAST_DISPLAY + 1):
            if not os.path.exists("/tmp/.X%d-lock" % number) and self._start(xvfb, number):
                os.environ["DISPLAY"] = ":%d" % number
                atexit.register(self.stop)
                return
        raise RenderError("Xvfb did not start on any display :%d to :%d"
                          % (self.FIRST_DISPLAY, self.LAST_DISPLAY))

    def _start(self, xvfb, number):
        """Starts Xvfb on :number; True once it accepts clients (it writes the number to the
        -displayfd pipe then), False when it exits first (the number was taken meanwhile).
        -noreset: by default Xvfb resets itself whenever its last client disconnects, and a
        client connecting during the reset (a child render reusing this display right after
        _display_works() closed its probe connection) dies with SIGABRT inside GLX, about one
        render in ten on a loaded machine."""
        read_end, write_end = os.pipe()
        self.process = subprocess.Popen(
            [xvfb, ":%d" % number, "-displayfd", str(write_end), "-screen", "0", "640x480x24",
             "-noreset", "-nolisten", "tcp"],
            pass_fds=(write_end,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            preexec_fn=_die_with_parent)
        os.close(write_end)
        ready = b""
        while not ready.endswith(b"\n"):
            byte = os.read(read_end, 1)
            if not byte:
                break
            ready += byte
        os.close(read_end)
        if ready.strip():
            return True
        self.stop()
        return False

    @staticmethod
    def _display_works():
        """True when libX11 can open $DISPLAY (VTK would abort on a dead one)."""
        try:
            import ctypes
            import ctypes.util
            xlib = ctypes.CDLL(ctypes.util.find_library("X11") or "libX11.so.6")
            xlib.XOpenDisplay.restype = ctypes.c_void_p
            xlib.XOpenDisplay.argtypes = [ctypes.c_char_p]
            xlib.XCloseDisplay.argtypes = [ctypes.c_void_p]
        except (OSError, AttributeError):
            return True  # cannot check: trust $DISPLAY
        display = xlib.XOpenDisplay(None)
        if not display:
            return False
        xlib.XCloseDisplay(display)
        return True

    def stop(self):
        if self.process is not None:
            self.process.terminate()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
            self.process = None


_DISPLAY = VirtualDisplay()


def import_vtk():
    """The VTK modules used here, with one clear line when python3-vtk9 is missing."""
    try:
        import vtkmodules.vtkInteractionStyle  # noqa: F401  (needed by some factories)
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (registers the OpenGL back end)
        import vtkmodules.all as vtk
        from vtkmodules.util import numpy_support
    except ImportError as error:
        raise RenderError(f"VTK is missing ({error}): apt-get install -y --no-install-recommends "
                          "python3-vtk9, and run with /usr/bin/python3")
    vtk.vtkObject.GlobalWarningDisplayOff()
    return vtk, numpy_support


# --------------------------------------------------------------------------------------
# Drawing
# --------------------------------------------------------------------------------------

def colormap_points(name):
    """[(position, r, g, b)] of a colour map: built in, or sampled from matplotlib."""
    if name in BUILTIN_COLORMAPS:
        return BUILTIN_COLORMAPS[name]
    try:
        import matplotlib
        cmap = matplotlib.colormaps[name]
    except ImportError:
        raise RenderError(f"-colormap {name}: needs python3-matplotlib "
                          f"(built in: {', '.join(BUILTIN_COLORMAPS)})")
    except KeyError:
        raise RenderError(f"-colormap {name}: no such colour map")
    return [(s, *cmap(s)[:3]) for s in np.linspace(0, 1, 33)]


SCALE_PERCENTILE = 99  # percent of a frame's free vertices below the top of the colour scale
NO_GROUND = "none"  # -ground none: no ground plane even when the file records one


def parse_ground(text):
    """-ground Y0 (m) or -ground none."""
    if text.strip().lower() == NO_GROUND:
        return NO_GROUND
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a height in m or 'none', got {text!r}")


def parse_background(text):
    """'R,G,B' (0..1) or 'R,G,B:R,G,B' (top:bottom gradient)."""
    if isinstance(text, tuple):
        return text
    parts = str(text).split(":")
    try:
        colours = [tuple(float(c) for c in part.split(",")) for part in parts]
    except ValueError:
        raise RenderError(f"-background {text!r}: expected R,G,B or R,G,B:R,G,B in 0..1")
    if not 1 <= len(colours) <= 2 or any(len(c) != 3 or min(c) < 0 or max(c) > 1 for c in colours):
        raise RenderError(f"-background {text!r}: expected R,G,B or R,G,B:R,G,B in 0..1")
    return (colours[0], colours[-1])


def nice_ceiling(value):
    """The smallest of 1, 1.5, 2, 2.5, 3, 4, 5, 6, 8, 10 times a power of ten >= value, so
    that the colour bar's BAR_LABELS - 1 intervals have short labels."""
    power = 10 ** math.floor(math.log10(value))
    for m in (1, 1.5, 2, 2.5, 3, 4, 5, 6, 8, 10):
        if m * power >= value * (1 - 1e-12):
            return m * power
    return 10 * power


def nice_step(span):
    """A round grid spacing (1, 2 or 5 times a power of ten) giving ~10 cells over span."""
    raw = max(span, 1e-9) / 10.0
    power = 10 ** math.floor(math.log10(raw))
    for m in (1, 2, 5, 10):
        if m * power >= raw:
            return m * power
    return 10 * power


class Renderer:
    """One VTK render window reused for every frame of one result file."""

    def __init__(self, result, frames, size=DEFAULT_SIZE, view=DEFAULT_VIEW, up="auto", title=None,
                 camera="follow", smooth=DEFAULT_SMOOTH, ground=None, colormap="coolwarm",
                 fixed_opacity=DEFAULT_FIXED_OPACITY, background=DEFAULT_BACKGROUND, zoom=1.0,
                 antialias=True):
        self.vtk, self.np2vtk = import_vtk()
        self.result = result
        self.frames = list(frames)
        self.size = (int(size[0]), int(size[1]))
        self.ground = None if ground == NO_GROUND else ground if ground is not None else result.ground
        self.up = self._up_axis(up)
        self.basis = view_basis(float(view[0]), float(view[1]), self.up)
        self.vmax = result.colour_scale(self.frames)
        if result.user_vmax is None:
            self.vmax = nice_ceiling(self.vmax)
        aspect = (1.0 - BAR_ROOM) * self.size[0] / self.size[1]
        self.centres, self.distances = camera_path(result, self.frames, camera, self.basis, aspect,
                                                    smooth, FILL * zoom)
        # Move the projection centre (normalised device x, -1..1) to the middle of the part
        # of the image left of the colour bar.
        self.window_centre_x = BAR_ROOM
        self._open_window(background, antialias)
        self.lut = self._lookup_table(colormap)
        self.free = self._surface(~result.face_fixed, colour=True)
        self.fixed = self._surface(result.face_fixed, colour=False, opacity=fixed_opacity)
        if self.ground is not None:
            self._ground()
        self._bar()
        self.time_text = self._text("", (0.02, 0.955), 18, bold=True)
        dt = np.diff(result.time)
        dt = dt[dt > 0]
        self.time_digits = 3 if dt.size == 0 else min(9, max(2, math.ceil(-math.log10(dt.min()) - 1e-9)))
        if title:
            self._text(title, (0.5, 0.955), 18, centred=True)

    def _up_axis(self, up):
        """'auto': against gravity when the file records it, y with a ground, else z."""
        if up != "auto":
            return up
        gravity = self.result.gravity
        if gravity is not None and np.linalg.norm(gravity) > 0:
            return "xyz"[int(np.argmax(np.abs(gravity)))]
        return "y" if self.ground is not None else "z"

    def _open_window(self, background, antialias):
        """Off-screen render window, renderer, lights, and the PNG writer reading it back."""
        vtk = self.vtk
        _DISPLAY.ensure()
        self.window = vtk.vtkRenderWindow()
        self.window.SetOffScreenRendering(1)
        self.window.SetMultiSamples(0)
        self.window.SetSize(*self.size)
        self.renderer = vtk.vtkRenderer()
        self.window.AddRenderer(self.renderer)
        self.renderer.GradientBackgroundOn()
        top, bottom = parse_background(background)
        self.renderer.SetBackground2(*top)
        self.renderer.SetBackground(*bottom)
        self.renderer.SetUseFXAA(bool(antialias))
        self.renderer.SetTwoSidedLighting(False)
        self._lights()
        self.grabber = vtk.vtkWindowToImageFilter()
        self.grabber.SetInput(self.window)
        self.grabber.ReadFrontBufferOff()
        self.grabber.ShouldRerenderOff()  # draw() has just rendered the frame
        self.grabber.SetInputBufferTypeToRGB()
        self.writer = vtk.vtkPNGWriter()
        self.writer.SetCompressionLevel(1)  # zlib level 1: 10x smaller than 0, as fast as it gets
        self.writer.SetInputConnection(self.grabber.GetOutputPort())

    # ---- scene set-up -------------------------------------------------------------
    def _lights(self):
        vtk = self.vtk
        kit = vtk.vtkLightKit()
        kit.SetKeyLightIntensity(0.85)
        kit.SetKeyToFillRatio(2.5)
        kit.SetKeyToHeadRatio(3.0)
        kit.AddLightsToRenderer(self.renderer)

    def _lookup_table(self, name):
        vtk = self.vtk
        ctf = vtk.vtkColorTransferFunction()
        ctf.SetColorSpaceToLab()
        for s, r, g, b in colormap_points(name):
            ctf.AddRGBPoint(s * self.vmax, r, g, b)
        lut = vtk.vtkLookupTable()
        lut.SetNumberOfTableValues(256)
        lut.SetTableRange(0.0, self.vmax)
        for i in range(256):
            lut.SetTableValue(i, *ctf.GetColor(self.vmax * i / 255.0), 1.0)
        lut.SetBelowRangeColor(*ctf.GetColor(0.0), 1.0)
        lut.SetAboveRangeColor(*ctf.GetColor(self.vmax), 1.0)
        lut.UseAboveRangeColorOn()
        lut.Build()
        return lut

    def _surface(self, face_mask, colour, opacity=1.0):
        """Actor of the boundary triangles face_mask, points updated each frame."""
        vtk = self.vtk
        r = self.result
        tris = r.tris[face_mask]
        if len(tris) == 0:
            return None
        vertices, local = np.unique(tris, return_inverse=True)
        local = local.reshape(-1, 3)
        cells = np.hstack([np.full((len(local), 1), 3), local]).astype(np.int64).ravel()
        polys = vtk.vtkCellArray()
        polys.SetCells(len(local), self.np2vtk.numpy_to_vtkIdTypeArray(cells, deep=True))
        poly = vtk.vtkPolyData()
        poly.SetPoints(vtk.vtkPoints())
        poly.SetPolys(polys)
        normals = vtk.vtkPolyDataNormals()
        normals.SetInputData(poly)
        normals.SetFeatureAngle(FEATURE_ANGLE)
        normals.SplittingOn()
        normals.ConsistencyOff()
        normals.AutoOrientNormalsOff()
        normals.ComputeCellNormalsOff()
        mapper = vtk.vtkPolyDataMapper()
        mapper.SetInputConnection(normals.GetOutputPort())
        actor = vtk.vtkActor()
        actor.SetMapper(mapper)
        prop = actor.GetProperty()
        prop.SetInterpolationToGouraud()
        if colour:
            mapper.SetLookupTable(self.lut)
            mapper.SetScalarRange(0.0, self.vmax)
            mapper.SetScalarModeToUsePointData()
            mapper.ScalarVisibilityOn()
            mapper.InterpolateScalarsBeforeMappingOn()
            prop.SetAmbient(0.15)
            prop.SetDiffuse(0.85)
            prop.SetSpecular(0.25)
            prop.SetSpecularPower(30)
        else:
            mapper.ScalarVisibilityOff()
            prop.SetColor(*FIXED_GREY)
            prop.SetOpacity(opacity)
            prop.SetSpecular(0.1)
            if opacity < 1:
                actor.ForceTranslucentOn()
        self.renderer.AddActor(actor)
        return {"poly": poly, "vertices": vertices, "actor": actor}

    def _ground(self):
        """The plane y = ground (in data coordinates) as a large quad with a grid."""
        vtk = self.vtk
        r = self.result
        pts = r.rest[r.all_vertices] if r.all_vertices.size else r.rest
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        free = r.free_vertices
        if free.size:
            last = self.result.positions([self.frames[-1]])[0][free]
            last = last[np.isfinite(last).all(axis=1)]
            if len(last):
                lo, hi = np.minimum(lo, last.min(axis=0)), np.maximum(hi, last.max(axis=0))
        span = float(np.max((hi - lo)[[0, 2]])) if np.all(np.isfinite(hi - lo)) else 1.0
        half = 3.0 * span + 1.0  # wide enough to reach the horizon of most views
        centre = 0.5 * (lo + hi)
        step = nice_step(2 * half)
        x0 = math.floor((centre[0] - half) / step) * step
        z0 = math.floor((centre[2] - half) / step) * step
        n = int(math.ceil(2 * half / step)) + 1
        y = float(self.ground)
        plane = vtk.vtkPlaneSource()
        plane.SetOrigin(x0, y, z0)
        plane.SetPoint1(x0 + n * step, y, z0)
        plane.SetPoint2(x0, y, z0 + n * step)
        plane.SetResolution(n, n)
        for style in ("surface", "grid"):
            mapper = vtk.vtkPolyDataMapper()
            mapper.SetInputConnection(plane.GetOutputPort())
            actor = vtk.vtkActor()
            actor.SetMapper(mapper)
            prop = actor.GetProperty()
            if style == "surface":
                prop.SetColor(*GROUND_COLOR)
                prop.SetAmbient(0.35)
                prop.SetDiffuse(0.65)
                # Push the filled plane back a little so that the grid lines win the depth test.
                mapper.SetResolveCoincidentTopologyToPolygonOffset()
                mapper.SetRelativeCoincidentTopologyPolygonOffsetParameters(1.0, 1.0)
            else:
                prop.SetRepresentationToWireframe()
                prop.SetColor(*GRID_COLOR)
                prop.LightingOff()
                prop.SetLineWidth(1.0)
            self.renderer.AddActor(actor)

    def _bar(self):
        """Colour bar right of the bodies, its title (quantity and unit) right-aligned above
        it so that a long title never leaves the image."""
        vtk = self.vtk
        bar = vtk.vtkScalarBarActor()
        bar.SetLookupTable(self.lut)
        bar.SetNumberOfLabels(BAR_LABELS)
        bar.SetLabelFormat("%-.3g")
        bar.SetMaximumNumberOfColors(256)
        bar.UnconstrainedFontSizeOn()
        scale = min(self.size[0] / 960, self.size[1] / 720)
        labels = bar.GetLabelTextProperty()
        labels.SetColor(0.1, 0.1, 0.12)
        labels.ShadowOff()
        labels.ItalicOff()
        labels.BoldOff()
        labels.SetFontSize(max(8, int(round(15 * scale))))
        bar.SetTextPad(max(2, int(4 * scale)))
        bar.GetPositionCoordinate().SetCoordinateSystemToNormalizedViewport()
        bar.GetPositionCoordinate().SetValue(1.0 - BAR_ROOM + 0.02, 0.10)
        bar.SetWidth(BAR_ROOM - 0.03)
        bar.SetHeight(0.74)
        bar.SetBarRatio(0.25)
        bar.SetTextPositionToSucceedScalarBar()
        self.renderer.AddActor2D(bar)
        title = self._text(COLOR_LABELS[self.result.color], (0.985, 0.885), 16, bold=True)
        title.GetTextProperty().SetJustificationToRight()
        if self.result.fixed.any():
            self._text("grey: fixed bodies", (0.02, 0.03), 13, colour=(0.3, 0.3, 0.33))

    def _text(self, text, where, points, bold=False, centred=False, colour=(0.1, 0.1, 0.12)):
        vtk = self.vtk
        actor = vtk.vtkTextActor()
        actor.SetInput(text)
        prop = actor.GetTextProperty()
        scale = min(self.size[0] / 960, self.size[1] / 720)
        prop.SetFontSize(max(8, int(round(points * scale))))
        prop.SetColor(*colour)
        prop.SetBold(bold)
        prop.SetFontFamilyToArial()
        prop.SetVerticalJustificationToTop()
        if centred:
            prop.SetJustificationToCentered()
        actor.GetPositionCoordinate().SetCoordinateSystemToNormalizedViewport()
        actor.GetPositionCoordinate().SetValue(*where)
        if where[1] < 0.5:
            prop.SetVerticalJustificationToBottom()
        self.renderer.AddActor2D(actor)
        return actor

    # ---- per frame ----------------------------------------------------------------
    def _update_surface(self, surface, positions, values=None):
        """New points (and colour values) of a surface; a surface whose points and values
        have not changed (fixed bodies) is left alone, so its normals are not recomputed."""
        if surface is None:
            return
        p = np.ascontiguousarray(positions[surface["vertices"]])
        p[~np.isfinite(p)] = 0.0
        if values is None and surface.get("last") is not None and np.array_equal(p, surface["last"]):
            return
        surface["last"] = p if values is None else None
        points = self.vtk.vtkPoints()
        points.SetData(self.np2vtk.numpy_to_vtk(p, deep=True))
        surface["poly"].SetPoints(points)
        if values is not None:
            scalars = self.np2vtk.numpy_to_vtk(np.nan_to_num(values[surface["vertices"]]), deep=True)
            scalars.SetName("value")
            surface["poly"].GetPointData().SetScalars(scalars)
        surface["poly"].Modified()

    def draw(self, index):
        """Updates the scene for the index-th rendered frame and renders it."""
        k = self.frames[index]
        positions, values = self.result.frame(k)
        self._update_surface(self.free, positions, values)
        self._update_surface(self.fixed, positions)
        toward, camup, _ = self.basis
        camera = self.renderer.GetActiveCamera()
        centre, distance = self.centres[index], self.distances[index]
        camera.SetFocalPoint(*centre)
        camera.SetPosition(*(centre + distance * toward))
        camera.SetViewUp(*camup)
        camera.SetViewAngle(VIEW_ANGLE)
        camera.SetWindowCenter(self.window_centre_x, 0.0)
        self.renderer.ResetCameraClippingRange()
        self.time_text.SetInput(f"t = {self.result.time[k]:.{self.time_digits}f} s")
        self.window.Render()

    def save(self, index, png_path):
        self.draw(index)
        self.grabber.Modified()
        self.writer.SetFileName(png_path)
        self.writer.Write()
        return png_path

    def close(self):
        """Releases the window and its X connection (before our Xvfb, if any, stops)."""
        if self.window is not None:
            self.window.Finalize()
        self.writer = self.grabber = self.renderer = self.window = None


# --------------------------------------------------------------------------------------
# Animations
# --------------------------------------------------------------------------------------

def write_mp4(pngs, path, fps):
    """H.264 MP4 of the PNGs through ffmpeg (sizes rounded down to even pixels)."""
    command = ["ffmpeg", "-y", "-loglevel", "error", "-f", "image2pipe", "-framerate", str(fps),
               "-i", "-", "-vf", "crop=trunc(iw/2)*2:trunc(ih/2)*2", "-c:v", "libx264",
               "-pix_fmt", "yuv420p", "-crf", "23", path]
    _pipe_pngs(command, pngs, "MP4")


def write_gif(pngs, path, fps, width):
    """GIF of the PNGs, scaled to `width` pixels, with ffmpeg's palette filters (else PIL)."""
    if shutil.which("ffmpeg"):
        scale = f"scale={int(width)}:-1:flags=lanczos," if width else ""
        command = ["ffmpeg", "-y", "-loglevel", "error", "-f", "image2pipe", "-framerate", str(fps),
                   "-i", "-", "-vf",
                   f"{scale}split[a][b];[a]palettegen=stats_mode=diff[p];[b][p]paletteuse=dither=bayer:bayer_scale=4",
                   "-loop", "0", path]
        _pipe_pngs(command, pngs, "GIF")
        return
    try:
        from PIL import Image
    except ImportError:
        raise RenderError("-gif needs ffmpeg or python3-pil")
    images = [Image.open(p).convert("RGB") for p in pngs]
    if width:
        images = [im.resize((int(width), max(1, round(im.height * width / im.width)))) for im in images]
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)


def _pipe_pngs(command, pngs, what):
    process = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        for png in pngs:
            with open(png, "rb") as f:
                process.stdin.write(f.read())
        process.stdin.close()
    except BrokenPipeError:
        pass
    error = process.stderr.read().decode(errors="replace").strip()
    if process.wait() != 0:
        raise RenderError(f"ffmpeg could not write the {what}: {error.splitlines()[-1] if error else '?'}")


# --------------------------------------------------------------------------------------
# Entry points
# --------------------------------------------------------------------------------------

def render_frame(h5_path, frame, png_path, color="deformation", size=DEFAULT_SIZE,
                 view=DEFAULT_VIEW, up="auto", title=None, vmax=None, camera="follow", **options):
    """Renders one frame (index; negative counts from the end) of a softbody result to
    png_path. The follow camera frames this frame's free bodies; the colour scale is
    this frame's unless vmax is given. Returns png_path."""
    result = Result(h5_path, color, vmax=vmax)
    k = select_frames([frame], result.nframes)[0]
    renderer = Renderer(result, [k], size=size, view=view, up=up, title=title, camera=camera, **options)
    try:
        return renderer.save(0, png_path)
    finally:
        renderer.close()


def render(h5_path, frames="all", out_dir=None, color="deformation", size=DEFAULT_SIZE,
           view=DEFAULT_VIEW, up="auto", title=None, gif=False, mp4=False, fps=20, vmax=None,
           every=1, camera="follow", gif_width=480, log=print, **options):
    """Renders the chosen frames to out_dir/frame_%05d.png (default: RESULT_frames/ beside
    the file) and optionally animation.gif / animation.mp4. Returns the files written."""
    result = Result(h5_path, color, vmax=vmax)
    for w in result.warnings:
        log(f"render.py: warning: {w}")
    chosen = select_frames(frames, result.nframes, every)
    if out_dir is None:
        out_dir = os.path.splitext(os.path.abspath(h5_path))[0] + "_frames"
    os.makedirs(out_dir, exist_ok=True)
    started = _time.perf_counter()
    renderer = Renderer(result, chosen, size=size, view=view, up=up, title=title, camera=camera, **options)
    ready = _time.perf_counter()
    pngs = []
    try:
        for index, k in enumerate(chosen):
            pngs.append(renderer.save(index, os.path.join(out_dir, f"frame_{k:05d}.png")))
    finally:
        renderer.close()
    drawn = _time.perf_counter()
    written = list(pngs)
    if mp4:
        if shutil.which("ffmpeg") is None:
            log("render.py: ffmpeg is missing (not on PATH), no MP4 written "
                "(apt-get install -y --no-install-recommends ffmpeg)")
        else:
            write_mp4(pngs, os.path.join(out_dir, "animation.mp4"), fps)
            written.append(os.path.join(out_dir, "animation.mp4"))
    if gif:
        write_gif(pngs, os.path.join(out_dir, "animation.gif"), fps, gif_width)
        written.append(os.path.join(out_dir, "animation.gif"))
    per_frame = (drawn - ready) / max(1, len(chosen))
    log(f"render.py: {len(chosen)} frames of {len(result.tris)} boundary triangles at "
        f"{size[0]}x{size[1]}: {per_frame:.3f} s per frame ({1 / max(per_frame, 1e-9):.1f} frames/s) "
        f"after {ready - started:.2f} s of set-up")
    return written


def parse_size(text):
    try:
        w, h = (int(s) for s in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected WxH in pixels, e.g. 960x720")
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"{text!r}: width and height must be 16..8192 pixels")
    return w, h


def parse_view(text):
    try:
        elev, azim = (float(s) for s in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected ELEV,AZIM in degrees, e.g. 20,-60")
    return elev, azim


class OneLineParser(argparse.ArgumentParser):
    """argparse that reports a bad command line in one line (and exits 2)."""

    def error(self, message):
        self.exit(2, f"render.py: error: {message} (-help lists the options)\n")


def build_parser():
    p = OneLineParser(
        prog="render.py", allow_abbrev=False, add_help=False,
        description="Render a softbody HDF5 result with VTK (off-screen): PNG frames, a GIF and "
                    "an MP4; lit smooth surfaces coloured by deformation or speed, fixed bodies "
                    "grey and translucent, the ground, a colour bar and a time stamp.")
    p.add_argument("result", metavar="RESULT.h5", help="softbody result file")
    p.add_argument("-help", "--help", "-h", action="help", help="show this help and exit")
    p.add_argument("-render_dir", "--render-dir", "--out", dest="render_dir", metavar="DIR",
                   help="output folder (default: RESULT_frames/ beside the result file)")
    p.add_argument("-frames", "--frames", default="all",
                   help="'all' (default), N (N frames evenly spaced, first and last included), a "
                        "range A:B (both included) or a list like 0,10,50 ('7,' is frame 7 alone; "
                        "negative counts from the end: write -frames=-1,)")
    p.add_argument("-every", "--every", type=int, default=1, metavar="K",
                   help="render every K-th of the chosen frames (default 1)")
    p.add_argument("-color", "--color", "-colour", "--colour", dest="color",
                   choices=sorted(COLOR_LABELS), default="deformation", metavar="QUANTITY",
                   help="deformation: displacement without the body's best-fit rigid motion (m, "
                        "default); speed |v| (m/s); displacement |x - X| (m)")
    p.add_argument("-size", "--size", type=parse_size, default=DEFAULT_SIZE, metavar="WxH",
                   help="image size in pixels (default 960x720)")
    p.add_argument("-camera", "--camera", choices=("follow", "fixed", "scene"), default="follow",
                   metavar="MODE",
                   help="follow: frame the free bodies of each frame, smoothly (default); fixed: "
                        "frame the free bodies of all frames; scene: frame everything")
    p.add_argument("-zoom", "--zoom", type=float, default=1.0,
                   help="scale of the framed bodies in the image (default 1: they fill "
                        f"{FILL:.2f} of its height; 0.5 shows more of the surroundings)")
    p.add_argument("-smooth", "--smooth", type=float, default=DEFAULT_SMOOTH, metavar="SECONDS",
                   help=f"time window of the follow camera's smoothing (default {DEFAULT_SMOOTH} s; 0: none)")
    p.add_argument("-view", "--view", type=parse_view, default=DEFAULT_VIEW, metavar="ELEV,AZIM",
                   help="camera elevation and azimuth about the up axis in degrees (default 20,-60; "
                        "write a negative elevation as -view=-10,30)")
    p.add_argument("-up", "--up", choices=("auto", "x", "y", "z"), default="auto", metavar="AXIS",
                   help="vertical axis (default auto: against gravity if the file records it, "
                        "y when there is a ground, else z)")
    p.add_argument("-ground", "--ground", type=parse_ground, metavar="Y0",
                   help="draw the ground plane y = Y0, or none with -ground none (default: the "
                        "file's ground_y attribute, written when the run had -ground)")
    p.add_argument("-gif", "--gif", action="store_true", help="also write DIR/animation.gif")
    p.add_argument("-gif_width", "--gif-width", type=int, default=480, metavar="PIXELS",
                   help="width of the GIF (default 480, 0: the frames' width)")
    p.add_argument("-mp4", "--mp4", action="store_true",
                   help="also write DIR/animation.mp4 (needs ffmpeg)")
    p.add_argument("-fps", "--fps", type=float, default=20,
                   help="frames per second of the GIF/MP4 (default 20)")
    p.add_argument("-title", "--title", help="title printed at the top of every frame")
    p.add_argument("-vmax", "--vmax", type=float,
                   help="top of the colour scale (m or m/s; default: the largest over the "
                        f"rendered frames of the {SCALE_PERCENTILE}th percentile of the free vertices)")
    p.add_argument("-antialias", "--antialias", choices=("fxaa", "none"), default="fxaa", metavar="HOW",
                   help="smooth the edges with FXAA (default; on Mesa's CPU renderer it costs about "
                        "as much as drawing the frame) or not")
    p.add_argument("-colormap", "--colormap", default="coolwarm",
                   help="colour map: coolwarm (default), blue-red, or any matplotlib name")
    p.add_argument("-fixed_opacity", "--fixed-opacity", type=float, default=DEFAULT_FIXED_OPACITY,
                   metavar="ALPHA", help=f"opacity of fixed bodies (default {DEFAULT_FIXED_OPACITY})")
    p.add_argument("-background", "--background", default=None, metavar="R,G,B[:R,G,B]",
                   help="background colour, or top:bottom gradient (0..1; default light grey-blue)")
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    if not os.path.isfile(args.result):
        print(f"render.py: error: {args.result}: no such file", file=sys.stderr)
        return 1
    if not 0.0 <= args.fixed_opacity <= 1.0:
        print("render.py: error: -fixed_opacity must be in 0..1", file=sys.stderr)
        return 2
    if not args.fps > 0:
        print("render.py: error: -fps must be positive", file=sys.stderr)
        return 2
    if not args.zoom > 0:
        print("render.py: error: -zoom must be positive", file=sys.stderr)
        return 2
    options = dict(antialias=args.antialias == "fxaa", zoom=args.zoom, smooth=args.smooth, ground=args.ground,
                   colormap=args.colormap,
                   fixed_opacity=args.fixed_opacity)
    if args.background is not None:
        options["background"] = args.background
    try:
        written = render(args.result, frames=args.frames, out_dir=args.render_dir, color=args.color,
                         size=args.size, view=args.view, up=args.up, title=args.title,
                         gif=args.gif, mp4=args.mp4, fps=args.fps, vmax=args.vmax,
                         every=args.every, camera=args.camera, gif_width=args.gif_width, **options)
    except (RenderError, OSError) as error:
        print(f"render.py: error: {error}", file=sys.stderr)
        return 1
    finally:
        _DISPLAY.stop()
    print("written:")
    for path in written:
        print("  " + path)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except BrokenPipeError:  # output piped into a reader that stopped early (| head)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(1)
