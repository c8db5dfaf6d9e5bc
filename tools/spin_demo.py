#!/usr/bin/python3
"""The spinning-cube demonstration of linear vs corotational elasticity.

Meshes a 1 m cube (750 tets), gives every vertex the velocity omega x r of one
turn per second about z, runs one turn in both modes and renders the cube at
quarter turns, with one colour scale for both modes. Writes into -spin_dir
(default docs/spin): spin-linear.h5, spin-corotational.h5 and
{linear,corotational}-tNNN.png, and prints the volume change of each mode.

  /usr/bin/python3 tools/spin_demo.py [-softbody build/softbody] [-mpiexec mpirun] [-spin_ranks 2]
                                      [-spin_dir docs/spin]
(--spin-ranks, --spin-dir and the older --ranks, --out work too.)
"""
import argparse
import os
import subprocess
import sys

import h5py
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import render  # noqa: E402
from softbody_tools import ToolParser, add_option, mpi_environment, read_medit, softbody_command  # noqa: E402


def main():
    parser = ToolParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                     allow_abbrev=False)
    add_option(parser, "softbody", default="build/softbody", help="the softbody executable")
    add_option(parser, "mpiexec", default="mpirun", help="MPI launcher (default mpirun)")
    add_option(parser, "spin_ranks", "--ranks", dest="ranks", type=int, default=2, help="MPI ranks (default 2)")
    add_option(parser, "spin_dir", "--out", dest="out", default="docs/spin", help="output folder (default docs/spin)")
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)

    mesh = os.path.join(args.out, "cube.mesh")
    subprocess.run([sys.executable, os.path.join(HERE, "box_mesh.py"), mesh, "-box_size", "1", "1", "1",
                    "-box_cells", "5", "5", "5"], check=True, capture_output=True)
    X = read_medit(mesh)[0]
    n = len(X)
    velocity = np.cross([0.0, 0.0, 2 * np.pi], X - X.mean(axis=0))  # one turn per second
    scene = os.path.join(args.out, "spin-scene.txt")
    with open(scene, "w") as f:
        f.write("1\ncube.mesh 1000 1e7 0.3 0  0 0 0  1 0 0 0\n%d\n" % n)
        f.writelines("0 %d %.17g %.17g %.17g\n" % (k, *velocity[k]) for k in range(n))

    results = {}
    for mode in ("linear", "corotational"):
        out = os.path.join(args.out, f"spin-{mode}.h5")
        options = ["-scene", scene, "-mode", mode, "-dt", "0.01", "-steps", "100", "-alpha", "0", "-beta", "0.01",
                   "-output", out]
        subprocess.run(softbody_command(args.mpiexec, args.ranks, args.softbody, options), check=True,
                       env=mpi_environment(), stdout=subprocess.DEVNULL)
        results[mode] = out

    vmax = 0.0
    for mode, path in results.items():
        with h5py.File(path, "r") as f:
            P, T = f["positions"][()], f["mesh/tets"][()]
            vmax = max(vmax, np.linalg.norm(P - f["mesh/rest_positions"][()], axis=2).max())
            a, b, c, d = (P[:, T[:, k]] for k in range(4))
            volume = (np.einsum("fij,fij->fi", np.cross(b - a, c - a), d - a) / 6).sum(axis=1)
        print(f"{mode}: volume change after one turn {100 * (volume[-1] / volume[0] - 1):+.2f} %")
    for mode, path in results.items():
        for frame in (0, 25, 50, 100):
            png = os.path.join(args.out, f"{mode}-t{frame:03d}.png")
            render.render_frame(path, frame, png, size=(480, 400), view=(35, -60), vmax=vmax,
                                title=f"{mode}, t = {frame / 100:.2f} s")
            print("wrote", png)


if __name__ == "__main__":
    main()
