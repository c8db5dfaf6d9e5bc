#!/usr/bin/env python3
"""tools/render.py draws a result: PNG frames of the requested size that show something
and change as the body moves.

Runs softbody (2 ranks, 10 steps) on a scene of its own in the work folder: a free
unit cube (8 vertices, 6 Kuhn tets) with an initial velocity of 0.5 m/s on vertex 0,
and a fixed copy of the cube beside it. Then renders 3 frames through the command
line (tools/render.py RESULT --frames 3 --size 320x240 --out DIR) and checks:
- the command exits 0, lists the files it wrote, and writes frame_00000.png,
  frame_00005.png, frame_00010.png;
- every PNG has the PNG signature and the requested size (IHDR width/height,
  big-endian at bytes 16..24), decodes with matplotlib.image.imread, is not
  blank (more than a handful of distinct colours) and shows the coloured body
  (saturated pixels in the left half, where the free cube is drawn);
- the first and last frames differ (the body moves, so shape and colours change);
- the free body is found free and the fixed one fixed (render.Result.fixed), and
  /mesh/body_fixed, when the file has it, takes precedence over the inference;
- render.render_frame() (the function other scripts use) writes one PNG of the
  requested size, with --color speed;
- a frame index out of range fails with a one-line error, not a traceback.
Needs Debian's python3-matplotlib: without it the test fails (./run installs it).
"""
import os
import shutil
import struct
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

TOOLS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "tools")
RENDER = os.path.join(TOOLS, "render.py")
SIZE = (320, 240)


def write_cube_mesh(path):
    """Unit cube, 8 vertices, 6 positively oriented Kuhn tets around the 0-6 diagonal."""
    import numpy as np
    verts = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]  # index x + 2y + 4z
    tets = [(0, 1, 3, 7), (0, 1, 5, 7), (0, 2, 3, 7), (0, 2, 6, 7), (0, 4, 5, 7), (0, 4, 6, 7)]
    oriented = []
    for t in tets:
        a, b, c, d = (np.array(verts[i], float) for i in t)
        det = np.linalg.det(np.array([b - a, c - a, d - a]))
        oriented.append(t if det > 0 else (t[0], t[2], t[1], t[3]))
    with open(path, "w") as f:
        f.write("MeshVersionFormatted 2\nDimension 3\nVertices\n8\n")
        for v in verts:
            f.write("%d %d %d 0\n" % v)
        f.write("Tetrahedra\n6\n")
        for t in oriented:
            f.write(" ".join(str(i + 1) for i in t) + " 0\n")
        f.write("End\n")


def png_size(path):
    with open(path, "rb") as f:
        head = f.read(24)
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return struct.unpack(">II", head[16:24])


def distinct_colours(image):
    import numpy as np
    pixels = np.round(np.asarray(image)[..., :3] * 255).astype(np.int64).reshape(-1, 3)
    return len(np.unique(pixels[:, 0] * 65536 + pixels[:, 1] * 256 + pixels[:, 2]))


def main():
    args = harness.arguments()
    checks = harness.Checks()
    try:
        import matplotlib  # noqa: F401
        import matplotlib.image
        import numpy as np
        import h5py
    except ImportError as error:
        print(f"FAIL: {error}: tools/render.py needs Debian's python3-matplotlib "
              "(apt-get install -y --no-install-recommends python3-matplotlib; ./run installs it) "
              "with /usr/bin/python3")
        sys.exit(1)
    sys.path.insert(0, TOOLS)
    import render  # noqa: E402

    work = os.path.abspath(args.work)
    write_cube_mesh(os.path.join(work, "cube.mesh"))
    scene = os.path.join(work, "scene.txt")
    with open(scene, "w") as f:
        f.write("2\n"
                "cube.mesh 1000 1e5 0.3 0 0 0 0 1 0 0 0\n"
                "cube.mesh 1000 1e5 0.3 1 2 0 0 1 0 0 0\n"
                "1\n"
                "0 0 0.5 0 0\n")
    result = os.path.join(work, "r.h5")
    if os.path.exists(result):
        os.remove(result)
    harness.run(args, 2, ["-scene", scene, "-steps", 10, "-output", result])
    checks.check(os.path.isfile(result), f"softbody wrote {result}")
    data = harness.read_frames(result)
    nframes = len(data["time"])
    checks.check(nframes == 11, f"the result has 11 frames (has {nframes})")

    # Command line: 3 frames evenly spaced.
    out = os.path.join(work, "frames")
    shutil.rmtree(out, ignore_errors=True)
    command = [sys.executable, RENDER, result, "--frames", "3", "--size", "%dx%d" % SIZE,
               "--out", out, "--title", "test_render"]
    run = subprocess.run(command, capture_output=True, text=True, timeout=300)
    checks.check(run.returncode == 0, f"render.py exits 0 (got {run.returncode})"
                 + ("" if run.returncode == 0 else ": " + run.stderr.strip()[-2000:]))
    print(run.stdout.strip())
    expected = [os.path.join(out, f"frame_{k:05d}.png") for k in (0, 5, 10)]
    images = []
    for path in expected:
        name = os.path.basename(path)
        if not checks.check(os.path.isfile(path), f"{name} written"):
            images.append(None)
            continue
        checks.check(path in run.stdout, f"{name} listed in the output")
        size = png_size(path)
        checks.check(size == SIZE, f"{name} is a PNG of {SIZE[0]}x{SIZE[1]} pixels (header says {size})")
        image = matplotlib.image.imread(path)
        checks.check(image.shape[:2] == (SIZE[1], SIZE[0]),
                     f"{name} decodes to {SIZE[1]}x{SIZE[0]} pixels (got {image.shape[:2]})")
        colours = distinct_colours(image)
        checks.check(colours > 3, f"{name} is not blank ({colours} distinct colours)")
        # The free cube is drawn in the left half (the colour bar is on the right):
        # coloured (saturated) pixels there are the body, not text or grid.
        left = image[:, : SIZE[0] // 2, :3]
        saturated = float(np.mean(left.max(axis=-1) - left.min(axis=-1) > 0.2))
        checks.check(saturated > 0.01, f"{name} shows the coloured body "
                     f"({100 * saturated:.1f}% of the left half is coloured)")
        images.append(image)
    if images[0] is not None and images[-1] is not None and images[0].shape == images[-1].shape:
        changed = float(np.mean(np.any(np.abs(images[0] - images[-1]) > 1e-6, axis=-1)))
        checks.check(changed > 0.001, f"frames 0 and 10 differ ({100 * changed:.2f}% of the pixels)")

    # Fixed bodies: inferred from motion, or read from /mesh/body_fixed.
    fixed = render.Result(result).fixed
    checks.check(list(fixed) == [False, True], f"free body found free, fixed body fixed ({list(fixed)})")
    flagged = os.path.join(work, "flagged.h5")
    shutil.copyfile(result, flagged)
    with h5py.File(flagged, "a") as f:
        if "mesh/body_fixed" in f:
            del f["mesh/body_fixed"]
        f["mesh/body_fixed"] = np.array([1, 0], dtype=np.int32)
    fixed = render.Result(flagged).fixed
    checks.check(list(fixed) == [True, False], f"/mesh/body_fixed takes precedence ({list(fixed)})")

    # The function other scripts use.
    single = os.path.join(work, "single.png")
    if os.path.exists(single):
        os.remove(single)
    render.render_frame(result, 7, single, color="speed", size=(200, 150))
    size = png_size(single) if os.path.isfile(single) else None
    checks.check(size == (200, 150), f"render_frame(..., color='speed') wrote a 200x150 PNG (got {size})")
    if size:
        colours = distinct_colours(matplotlib.image.imread(single))
        checks.check(colours > 3, f"render_frame's PNG is not blank ({colours} distinct colours)")

    # A bad frame index: one clear line, no traceback.
    bad = subprocess.run([sys.executable, RENDER, result, "--frames", "0,99", "--out", out],
                         capture_output=True, text=True, timeout=300)
    checks.check(bad.returncode != 0 and "out of range" in bad.stderr and "Traceback" not in bad.stderr,
                 f"--frames 0,99 fails cleanly (exit {bad.returncode}: {bad.stderr.strip()})")
    checks.exit()


if __name__ == "__main__":
    main()
