#!/usr/bin/python3
"""Headless renderer for softbody results: one PNG per frame, optionally a GIF/MP4.

Reads a softbody HDF5 result (/time, /positions, /velocities, /mesh/...) and draws
the boundary triangles of every body as a shaded 3-D surface with matplotlib
(Agg back end, no display needed):

- faces coloured by the per-face mean of the vertex displacement magnitude
  |x - X| (m) or speed |v| (m/s), on ONE colour scale fixed over all frames of
  the file (0 .. the largest face value of any frame), with a colour bar;
- fixed bodies in flat grey (see body_fixed());
- simple Lambert shading, colour = colormap(value) * (ambient + diffuse max(0, n.l)),
  with the light fixed relative to the camera (above, left, in front);
- back faces culled (boundary triangles are outward oriented) and the rest drawn
  far to near (painter's order), one collection for all bodies so that bodies
  occlude each other correctly;
- orthographic camera; axis limits framing every vertex over ALL frames and
  equal aspect (ax.set_box_aspect), so frames are directly comparable;
- a time stamp "t = 0.120 s" and an optional title.

Usage:
  render.py RESULT.h5 [--out DIR] [--frames all|N|0,10,50] [--color displacement|speed]
            [--size 960x720] [--gif] [--mp4] [--view ELEV,AZIM] [--up x|y|z] [--title TEXT]

From another script:
  import sys; sys.path.insert(0, "tools"); import render
  render.render_frame("r.h5", 10, "f10.png", color="speed")
  render.render("r.h5", frames=[0, 5, 10], out_dir="frames")   # returns the files written

Needs Debian's /usr/bin/python3 with python3-numpy, python3-h5py,
python3-matplotlib; python3-pil for --gif; ffmpeg for --mp4.
"""
import argparse
import math
import os
import shutil
import sys
import time as _time

try:
    import numpy as np
    import h5py
except ImportError as _error:  # pragma: no cover - depends on the interpreter
    sys.exit(f"render.py: {_error}: run with Debian's /usr/bin/python3 "
             "(apt-get install python3-numpy python3-h5py python3-matplotlib)")

try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import animation, cm, colors as mcolors
    from matplotlib.ticker import MaxNLocator
    from mpl_toolkits.mplot3d import Axes3D  # noqa: F401  (registers the 3d projection)
    from mpl_toolkits.mplot3d import proj3d
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
except ImportError:  # pragma: no cover
    sys.exit("render.py: matplotlib is missing: apt-get install -y --no-install-recommends "
             "python3-matplotlib (and run with /usr/bin/python3)")

DPI = 100
DEFAULT_SIZE = (960, 720)
DEFAULT_VIEW = (20.0, -60.0)
FIXED_GREY = np.array([0.72, 0.72, 0.72])
AMBIENT = 0.4
DIFFUSE = 0.6
CMAP = "Spectral_r"
COLOR_LABELS = {"displacement": "displacement |x - X| (m)", "speed": "speed |v| (m/s)"}
CHUNK_VALUES = 30_000_000  # floats read at a time when scanning all frames


# --------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------

def infer_body_fixed(positions, rest, vertex_body, nbodies, chunk=None):
    """Heuristic used until every result holds /mesh/body_fixed: a body is fixed
    when none of its vertices ever moves (positions equal the rest positions in
    every frame). positions: an h5py dataset or array [F][V][3]. Returns bool[nbodies]."""
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
            raise ValueError(f"/mesh/body_fixed has {flags.size} entries for {nbodies} bodies")
        return flags[:nbodies] != 0
    return infer_body_fixed(h5["positions"], rest, vertex_body, nbodies)


def vertex_values(positions, velocities, rest, color):
    """Per-vertex magnitude [..., V] of the chosen colour quantity."""
    if color == "displacement":
        return np.linalg.norm(positions - rest, axis=-1)
    if color == "speed":
        return np.linalg.norm(velocities, axis=-1)
    raise ValueError(f"unknown colour quantity {color!r} (displacement or speed)")


def select_frames(spec, nframes):
    """'all', 'N' (N frames evenly spaced, first and last included) or a list
    '0,10,50' (a trailing comma makes a one-frame list: '7,'; negative indices
    count from the end). Returns a list of frame indices."""
    if isinstance(spec, (list, tuple, range)):
        items = [int(s) for s in spec]
    else:
        spec = str(spec).strip()
        if spec == "all":
            return list(range(nframes))
        if "," not in spec:
            try:
                count = int(spec)
            except ValueError:
                raise ValueError(f"--frames {spec!r}: expected all, a count N, or a list like 0,10,50")
            if count < 1:
                raise ValueError(f"--frames {spec}: the count must be at least 1")
            if count >= nframes:
                return list(range(nframes))
            picks = np.round(np.linspace(0, nframes - 1, count)).astype(int)
            return sorted(set(int(p) for p in picks))
        try:
            items = [int(s) for s in spec.split(",") if s.strip()]
        except ValueError:
            raise ValueError(f"--frames {spec!r}: expected all, a count N, or a list like 0,10,50")
    frames = []
    for i in items:
        j = i + nframes if i < 0 else i
        if not 0 <= j < nframes:
            raise ValueError(f"frame {i} out of range (the file has {nframes} frames, 0..{nframes - 1})")
        frames.append(j)
    return frames


def boundary_orientation(rest, tris, vertex_body, nbodies):
    """Signed volume enclosed by each body's boundary triangles at rest (positive
    when they are outward oriented)."""
    a, b, c = rest[tris[:, 0]], rest[tris[:, 1]], rest[tris[:, 2]]
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    return np.bincount(vertex_body[tris[:, 0]], weights=vol, minlength=nbodies)[:nbodies]


class Result:
    """The static data of a result file plus the scene-wide quantities that must
    be the same for every frame: colour scale and bounding box."""

    def __init__(self, path, color="displacement", vmax=None):
        if color not in COLOR_LABELS:
            raise ValueError(f"unknown colour quantity {color!r} (displacement or speed)")
        self.path = path
        self.color = color
        with h5py.File(path, "r") as f:
            for name in ("time", "positions", "mesh/boundary_triangles", "mesh/vertex_body",
                         "mesh/rest_positions"):
                if name not in f:
                    raise ValueError(f"{path}: no /{name} dataset (not a softbody result?)")
            if color == "speed" and "velocities" not in f:
                raise ValueError(f"{path}: no /velocities dataset (needed by --color speed)")
            self.time = np.asarray(f["time"][()], dtype=float).ravel()
            self.tris = np.asarray(f["mesh/boundary_triangles"][()], dtype=np.int64).reshape(-1, 3)
            self.vertex_body = np.asarray(f["mesh/vertex_body"][()], dtype=np.int64).ravel()
            self.rest = np.asarray(f["mesh/rest_positions"][()], dtype=float).reshape(-1, 3)
            pos = f["positions"]
            self.nframes, self.nvertices = pos.shape[0], pos.shape[1]
            if self.nframes == 0:
                raise ValueError(f"{path}: no frames")
            if self.rest.shape[0] != self.nvertices or self.vertex_body.size != self.nvertices:
                raise ValueError(f"{path}: /positions has {self.nvertices} vertices, "
                                 f"/mesh/rest_positions {self.rest.shape[0]}, "
                                 f"/mesh/vertex_body {self.vertex_body.size}")
            if self.tris.size and (self.tris.min() < 0 or self.tris.max() >= self.nvertices):
                raise ValueError(f"{path}: /mesh/boundary_triangles indexes outside 0..{self.nvertices - 1}")
            self.nbodies = int(self.vertex_body.max()) + 1 if self.vertex_body.size else 0
            if "mesh/body_fixed" in f:
                self.nbodies = max(self.nbodies, int(f["mesh/body_fixed"].shape[0]))
            self.fixed = body_fixed(f, self.rest, self.vertex_body, self.nbodies)
            self.face_body = self.vertex_body[self.tris[:, 0]]
            self.face_fixed = self.fixed[self.face_body]
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
            self._scan(f)
        if vmax is not None:
            if not vmax > 0:
                raise ValueError(f"the colour scale maximum must be positive (got {vmax})")
            self.vmax = float(vmax)

    def _scan(self, f):
        """One pass over all frames: bounding box of every vertex and the largest
        per-face colour value of the free bodies."""
        pos = f["positions"]
        vel = f["velocities"] if self.color == "speed" else None
        step = max(1, CHUNK_VALUES // max(1, self.nvertices * 3 * (2 if vel is not None else 1)))
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        vmax = 0.0
        free = ~self.face_fixed
        nonfinite = 0
        for start in range(0, self.nframes, step):
            p = np.asarray(pos[start:start + step], dtype=float)
            finite = np.isfinite(p).all(axis=2)
            nonfinite += int((~finite).sum())
            if finite.any():
                pts = p[finite]
                lo = np.minimum(lo, pts.min(axis=0))
                hi = np.maximum(hi, pts.max(axis=0))
            if free.any():
                v = np.asarray(vel[start:start + step], dtype=float) if vel is not None else None
                values = vertex_values(p, v, self.rest, self.color)[:, self.tris[free]].mean(axis=2)
                values = values[np.isfinite(values)]
                if values.size:
                    vmax = max(vmax, float(values.max()))
        if nonfinite:
            self.warnings.append(f"{nonfinite} vertex positions (over all frames) are not finite")
        if not np.all(np.isfinite(lo)):
            lo, hi = self.rest.min(axis=0), self.rest.max(axis=0)
        self.lo, self.hi = lo, hi
        self.vmax = vmax if vmax > 0 else 1.0

    def frame(self, k):
        """(positions [V][3], per-face colour values [B]) of frame k."""
        with h5py.File(self.path, "r") as f:
            p = np.asarray(f["positions"][k], dtype=float)
            v = np.asarray(f["velocities"][k], dtype=float) if self.color == "speed" else None
        values = vertex_values(p, v, self.rest, self.color)[self.tris].mean(axis=1)
        return p, values


# --------------------------------------------------------------------------------------
# Drawing
# --------------------------------------------------------------------------------------

# Plot coordinates are a cyclic permutation of the data coordinates that puts the
# chosen up axis on matplotlib's z (vertical) axis; matplotlib's own
# view_init(vertical_axis=...) is not used because set_box_aspect ignores it
# before matplotlib 3.9 (issue #24328), which distorts the scene.
UP_PERMUTATION = {"z": [0, 1, 2], "y": [2, 0, 1], "x": [1, 2, 0]}


def view_vectors(elev, azim):
    """Unit vectors (toward the viewer, camera up, camera right) in plot coordinates
    (z up), as mplot3d's get_proj() places the eye (orthographic projection)."""
    e, a = math.radians(elev), math.radians(azim)
    toward = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    vertical = np.array([0.0, 0.0, -1.0 if abs(((elev + 180) % 360) - 180) > 90 else 1.0])
    right = np.cross(-toward, vertical)
    if np.linalg.norm(right) < 1e-9:  # looking straight along the vertical axis
        right = np.array([-math.sin(a), math.cos(a), 0.0])
    right /= np.linalg.norm(right)
    camup = np.cross(right, -toward)
    return toward, camup, right


class Renderer:
    """One matplotlib figure reused for every frame of one result file."""

    def __init__(self, result, size=DEFAULT_SIZE, view=DEFAULT_VIEW, up="z", title=None,
                 cmap=CMAP, cull=True, axes=True):
        self.result = result
        self.size = (int(size[0]), int(size[1]))
        self.elev, self.azim = float(view[0]), float(view[1])
        self.up = up
        self.perm = UP_PERMUTATION[up]
        self.cull = cull
        self.show_axes = axes
        toward, camup, right = view_vectors(self.elev, self.azim)
        self.toward = toward
        light = toward + 0.7 * camup + 0.25 * right  # from above and a little right of the viewer
        self.light = light / np.linalg.norm(light)
        self.cmap = plt.get_cmap(cmap)
        self.norm = mcolors.Normalize(vmin=0.0, vmax=result.vmax)

        w, h = self.size
        font = float(np.clip(min(w / 960, h / 720), 0.6, 2.0))  # font scale for small/big images
        # A hair over the pixel count: Agg truncates size * dpi (4.81 * 100 = 480.999...).
        self.fig = plt.figure(figsize=((w + 0.01) / DPI, (h + 0.01) / DPI), dpi=DPI)
        self.fig.patch.set_facecolor("white")
        # Room on the right for the colour bar, at the top for time and title.
        rect = [0.0, 0.0, 0.84, 0.93]
        self.ax = self.fig.add_axes(rect, projection="3d")
        ax = self.ax
        ax.set_proj_type("ortho")
        ax.view_init(elev=self.elev, azim=self.azim)
        lo, hi = result.lo[self.perm], result.hi[self.perm]
        span = hi - lo
        biggest = float(span.max()) if span.max() > 0 else 1.0
        span = np.maximum(span, 0.02 * biggest)
        centre = 0.5 * (lo + hi)
        half = 0.5 * span * 1.02
        ax.set_xlim(centre[0] - half[0], centre[0] + half[0])
        ax.set_ylim(centre[1] - half[1], centre[1] + half[1])
        ax.set_zlim(centre[2] - half[2], centre[2] + half[2])
        names = "xyz"
        ax.set_xlabel(f"{names[self.perm[0]]} (m)")
        ax.set_ylabel(f"{names[self.perm[1]]} (m)")
        ax.set_zlabel(f"{names[self.perm[2]]} (m)")
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_pane_color((0.95, 0.95, 0.97, 1.0))
            axis.label.set_fontsize(8 * font)
        ax.tick_params(labelsize=7 * font, pad=0)
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_major_locator(MaxNLocator(nbins=7 if font >= 0.8 else 4))
        if not axes:
            ax.set_axis_off()
        self._fit(2 * half, rect)
        # Centre drawing + colour bar in the figure (a tall scene leaves room at the sides).
        w, h = self.size
        lo_px, hi_px = self._extent()
        bar_block = 0.13 * w  # colour bar, its ticks and label
        gap = 0.02 * w
        shift = max((w - (hi_px[0] - lo_px[0] + gap + bar_block)) / 2 - lo_px[0], -lo_px[0])
        rect[0] += shift / w
        self.ax.set_position(rect)
        bar_left = min((hi_px[0] + shift + gap) / w, 1.0 - 0.12)

        self.poly = Poly3DCollection(np.zeros((0, 3, 3)), linewidths=0.25, zsort="average")
        ax.add_collection3d(self.poly)

        cax = self.fig.add_axes([bar_left, 0.12, 0.025, 0.72])
        mappable = cm.ScalarMappable(norm=self.norm, cmap=self.cmap)
        mappable.set_array([])
        bar = self.fig.colorbar(mappable, cax=cax)
        bar.set_label(COLOR_LABELS[result.color], fontsize=9 * font)
        bar.ax.tick_params(labelsize=8 * font)
        if result.fixed.any():
            self.fig.text(0.02, 0.02, "grey: fixed bodies", fontsize=8 * font, color="0.35")

        self.time_text = self.fig.text(0.02, 0.965, "", fontsize=11 * font, family="monospace",
                                       va="top", ha="left")
        if title:
            self.fig.text(0.5, 0.965, title, fontsize=12 * font, va="top", ha="center")
        dt = np.diff(result.time)
        dt = dt[dt > 0]
        self.time_digits = 3 if dt.size == 0 else min(9, max(3, math.ceil(-math.log10(dt.min()) - 1e-9)))

    def _extent(self):
        """Pixel bounding box [x0, y0, x1, y1] of what the 3-D axes draws: the
        projected box (panes) and the three axes with their ticks and labels."""
        ax, fig = self.ax, self.fig
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        lims = (ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d())
        corners = np.array([[x, y, z] for x in lims[0] for y in lims[1] for z in lims[2]])
        px, py, _ = proj3d.proj_transform(corners[:, 0], corners[:, 1], corners[:, 2], ax.get_proj())
        points = ax.transData.transform(np.column_stack([px, py]))
        lo, hi = points.min(axis=0), points.max(axis=0)
        if self.show_axes:
            for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
                b = axis.get_tightbbox(renderer)
                if b is not None and np.all(np.isfinite(b.extents)):
                    lo = np.minimum(lo, [b.x0, b.y0])
                    hi = np.maximum(hi, [b.x1, b.y1])
        return lo, hi

    def _fit(self, box, rect):
        """Zoom so that the drawing fills the figure rectangle rect (fractions)
        given to the 3-D axes: mplot3d scales the box by its diagonal, whatever
        the view, so without this a long thin scene comes out small or cut off."""
        w, h = self.size
        region_lo = np.array([rect[0] * w, rect[1] * h])
        region_hi = np.array([(rect[0] + rect[2]) * w, (rect[1] + rect[3]) * h])
        centre = 0.5 * (region_lo + region_hi)
        zoom = 1.0
        for _ in range(5):
            self.ax.set_box_aspect(tuple(box), zoom=zoom)
            lo, hi = self._extent()
            # The drawing is centred on the axes centre: the side that sticks out
            # most (relative to the room on that side) decides.
            reach = np.maximum(centre - lo, hi - centre)
            ratio = float(np.min(0.5 * (region_hi - region_lo) / np.maximum(reach, 1e-9)))
            if 0.97 <= ratio <= 1.0:
                break
            zoom = float(np.clip(zoom * 0.99 * ratio, 0.1, 10.0))
        self.ax.set_box_aspect(tuple(box), zoom=zoom)

    def draw(self, k):
        """Update the figure for frame k."""
        r = self.result
        positions, values = r.frame(k)
        tri = positions[:, self.perm][r.tris]  # [B][3][3], plot coordinates
        normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(normals, axis=1)
        ok = np.isfinite(tri).all(axis=(1, 2)) & (length > 0)
        normals[ok] /= length[ok, None]
        keep = ok & ((normals @ self.toward) > 0) if self.cull else ok
        tri, normals, values, fixed = tri[keep], normals[keep], values[keep], r.face_fixed[keep]
        # Painter's order: far faces first (mplot3d sorts again by the same depth).
        depth = tri.mean(axis=1) @ self.toward
        order = np.argsort(depth, kind="stable")
        tri, normals, values, fixed = tri[order], normals[order], values[order], fixed[order]
        base = self.cmap(self.norm(np.nan_to_num(values)))[:, :3]
        base[fixed] = FIXED_GREY
        shade = AMBIENT + DIFFUSE * np.clip(normals @ self.light, 0.0, None)
        rgba = np.empty((len(tri), 4))
        rgba[:, :3] = np.clip(base * shade[:, None], 0.0, 1.0)
        rgba[:, 3] = 1.0
        self.poly.set_verts(tri)
        self.poly.set_facecolor(rgba)
        self.poly.set_edgecolor(rgba)  # same colour: hides the seams between faces
        self.time_text.set_text(f"t = {r.time[k]:.{self.time_digits}f} s")

    def save(self, k, png_path):
        self.draw(k)
        self.fig.savefig(png_path, dpi=DPI, facecolor=self.fig.get_facecolor())
        return png_path

    def close(self):
        plt.close(self.fig)


# --------------------------------------------------------------------------------------
# Entry points
# --------------------------------------------------------------------------------------

def render_frame(h5_path, frame, png_path, color="displacement", size=DEFAULT_SIZE,
                 view=DEFAULT_VIEW, up="z", title=None, vmax=None):
    """Renders one frame (index; negative counts from the end) of a softbody result
    to png_path. The colour scale and camera are those of the whole file, as for
    render(). Returns png_path."""
    result = Result(h5_path, color, vmax=vmax)
    k = select_frames([frame], result.nframes)[0]
    renderer = Renderer(result, size=size, view=view, up=up, title=title)
    try:
        return renderer.save(k, png_path)
    finally:
        renderer.close()


def render(h5_path, frames="all", out_dir=None, color="displacement", size=DEFAULT_SIZE,
           view=DEFAULT_VIEW, up="z", title=None, gif=False, mp4=False, fps=10, vmax=None,
           log=print):
    """Renders the chosen frames to out_dir/frame_%05d.png (default: RESULT_frames/
    beside the file) and optionally animation.gif / animation.mp4. Returns the list
    of files written."""
    result = Result(h5_path, color, vmax=vmax)
    for w in result.warnings:
        log(f"render.py: warning: {w}")
    chosen = select_frames(frames, result.nframes)
    if out_dir is None:
        out_dir = os.path.splitext(os.path.abspath(h5_path))[0] + "_frames"
    os.makedirs(out_dir, exist_ok=True)
    renderer = Renderer(result, size=size, view=view, up=up, title=title)
    writers = []
    if gif:
        try:
            import PIL  # noqa: F401
        except ImportError:
            log("render.py: python3-pil is missing, no GIF written "
                "(apt-get install -y --no-install-recommends python3-pil)")
        else:
            writers.append((animation.PillowWriter(fps=fps), os.path.join(out_dir, "animation.gif")))
    if mp4:
        if shutil.which("ffmpeg") is None:
            log("render.py: ffmpeg is missing (not on PATH), no MP4 written "
                "(apt-get install -y --no-install-recommends ffmpeg)")
        else:
            # H.264 needs even sizes: the writer rounds the figure size down to even
            # pixels at setup; the PNGs and the GIF keep the requested size.
            writers.append((animation.FFMpegWriter(fps=fps), os.path.join(out_dir, "animation.mp4")))
    written = []
    started = _time.perf_counter()
    try:
        fig = renderer.fig
        inches = fig.get_size_inches().copy()
        sizes = []
        for writer, path in writers:
            writer.setup(fig, path, dpi=DPI)
            sizes.append(fig.get_size_inches().copy())
            fig.set_size_inches(inches)
        for k in chosen:
            png = os.path.join(out_dir, f"frame_{k:05d}.png")
            renderer.save(k, png)
            written.append(png)
            for (writer, _), size in zip(writers, sizes):
                fig.set_size_inches(size)
                writer.grab_frame(facecolor=fig.get_facecolor())
                fig.set_size_inches(inches)
        for writer, path in writers:
            writer.finish()
            written.append(path)
    finally:
        renderer.close()
    elapsed = _time.perf_counter() - started
    log(f"render.py: {len(chosen)} frames in {elapsed:.2f} s "
        f"({elapsed / max(1, len(chosen)):.3f} s per frame, {len(result.tris)} boundary triangles)")
    return written


def parse_size(text):
    try:
        w, h = (int(s) for s in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected WxH in pixels, e.g. 960x720")
    if not (16 <= w <= 10000 and 16 <= h <= 10000):
        raise argparse.ArgumentTypeError(f"{text!r}: width and height must be 16..10000 pixels")
    return w, h


def parse_view(text):
    try:
        elev, azim = (float(s) for s in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected ELEV,AZIM in degrees, e.g. 20,-60")
    return elev, azim


def main(argv=None):
    parser = argparse.ArgumentParser(
        description="Render a softbody HDF5 result to PNG frames (and optionally a GIF/MP4): "
                    "boundary surfaces, shaded, coloured by displacement or speed on one colour "
                    "scale for all frames, fixed bodies in grey.")
    parser.add_argument("result", metavar="RESULT.h5", help="softbody result file")
    parser.add_argument("--out", metavar="DIR",
                        help="output folder (default: RESULT_frames/ beside the result file)")
    parser.add_argument("--frames", default="all",
                        help="'all' (default), N (N frames evenly spaced, first and last "
                             "included) or a list like 0,10,50 (negative counts from the end; "
                             "'7,' is the single frame 7)")
    parser.add_argument("--color", choices=sorted(COLOR_LABELS), default="displacement",
                        help="colour faces by displacement |x - X| (m, default) or speed |v| (m/s)")
    parser.add_argument("--size", type=parse_size, default=DEFAULT_SIZE, metavar="WxH",
                        help="image size in pixels (default 960x720)")
    parser.add_argument("--gif", action="store_true",
                        help="also write DIR/animation.gif (needs python3-pil)")
    parser.add_argument("--mp4", action="store_true",
                        help="also write DIR/animation.mp4 (needs ffmpeg on PATH)")
    parser.add_argument("--fps", type=float, default=10,
                        help="frames per second of the GIF/MP4 (default 10)")
    parser.add_argument("--view", type=parse_view, default=DEFAULT_VIEW, metavar="ELEV,AZIM",
                        help="camera elevation and azimuth in degrees (default 20,-60; write a negative "
                             "elevation as --view=-10,30)")
    parser.add_argument("--up", choices=("x", "y", "z"), default="z",
                        help="axis drawn vertical (default z; the cggs-cw2 scenes are y-up)")
    parser.add_argument("--title", help="title printed at the top of every frame")
    parser.add_argument("--vmax", type=float,
                        help="top of the colour scale (m or m/s; default: the largest face value "
                             "over all frames of the file)")
    args = parser.parse_args(argv)
    if not os.path.isfile(args.result):
        parser.error(f"{args.result}: no such file")
    try:
        written = render(args.result, frames=args.frames, out_dir=args.out, color=args.color,
                         size=args.size, view=args.view, up=args.up, title=args.title,
                         gif=args.gif, mp4=args.mp4, fps=args.fps, vmax=args.vmax)
    except (ValueError, OSError) as error:
        print(f"render.py: error: {error}", file=sys.stderr)
        return 1
    print("written:")
    for path in written:
        print("  " + path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
