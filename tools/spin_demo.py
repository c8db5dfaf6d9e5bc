#!/usr/bin/python3
"""The spinning-cube demonstration of linear vs corotational elasticity.

Meshes a 1 m cube (750 tets), gives every vertex the velocity omega x r of one
turn per second about z, runs one turn in both modes and renders the cube at
quarter turns, with one colour scale for both modes. Writes into --out
(default docs/spin): spin-linear.h5, spin-corotational.h5 and
{linear,corotational}-tNNN.png, and prints the volume change of each mode.

  /usr/bin/python3 tools/spin_demo.py [--softbody build/softbody] [--ranks 2] [--out docs/spin]
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


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--softbody", default="build/softbody", help="the softbody executable")
    parser.add_argument("--ranks", type=int, default=2, help="MPI ranks")
    parser.add_argument("--out", default="docs/spin", help="output folder")
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)

    mesh = os.path.join(args.out, "cube.mesh")
    subprocess.run([sys.executable, os.path.join(HERE, "box_mesh.py"), mesh, "--size", "1", "1", "1",
                    "--cells", "5", "5", "5"], check=True, capture_output=True)
    tokens = open(mesh).read().split()
    i = tokens.index("Vertices")
    n = int(tokens[i + 1])
    X = np.array(tokens[i + 2:i + 2 + 4 * n], float).reshape(n, 4)[:, :3]
    velocity = np.cross([0.0, 0.0, 2 * np.pi], X - X.mean(axis=0))  # one turn per second
    scene = os.path.join(args.out, "spin-scene.txt")
    with open(scene, "w") as f:
        f.write("1\ncube.mesh 1000 1e7 0.3 0  0 0 0  1 0 0 0\n%d\n" % n)
        f.writelines("0 %d %.17g %.17g %.17g\n" % (k, *velocity[k]) for k in range(n))

    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    results = {}
    for mode in ("linear", "corotational"):
        out = os.path.join(args.out, f"spin-{mode}.h5")
        subprocess.run(["mpirun", "-n", str(args.ranks), args.softbody, "-scene", scene, "-mode", mode,
                        "-dt", "0.01", "-steps", "100", "-alpha", "0", "-beta", "0.01", "-output", out],
                       check=True, env=env, stdout=subprocess.DEVNULL)
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
