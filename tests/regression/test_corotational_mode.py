"""Corotational mode against linear mode and against exact expectations.

(a) A body rigidly rotated from its rest shape (by 180 degrees about z, which is
    -deform 0:0:-1,-1,1) feels no elastic force in corotational mode and stays
    put; linear mode sees a large spurious force.
(b) A spinning cube (omega x r on every vertex): after one turn the corotational
    volume changes by less than 2 %, linear mode's by far more.
(c) Small deformations: corotational and linear trajectories agree to the order
    of the strain, and the difference falls with it.
(d) A body inverted in its initial state (-deform 0:0:1,1,-1) recovers: volume
    positive again, no NaN.
(e) 1 rank and 2 ranks give the same corotational trajectory (-ksp_rtol 1e-12).
(f) A solve that does not converge stops the run with the KSP reason, and the
    partial result file is not marked complete.
"""
import os

import numpy as np

import harness

args = harness.arguments()
checks = harness.Checks()


def box_mesh(name, size, cells):
    return harness.box_mesh(args, name, size, cells)


def rest_vertices(mesh):
    tokens = open(mesh).read().split()
    i = tokens.index("Vertices")
    n = int(tokens[i + 1])
    return np.array(tokens[i + 2:i + 2 + 4 * n], float).reshape(n, 4)[:, :3]


def volume(positions, tets):
    a, b, c, d = (positions[tets[:, k]] for k in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def simulate(name, scene, ranks=2, options=()):
    out = os.path.join(args.work, name + ".h5")
    harness.run(args, ranks, ["-scene", scene, "-output", out, *options])
    return harness.read_frames(out)


cube = box_mesh("cube.mesh", (1, 1, 1), (5, 5, 5))
X = rest_vertices(cube)
centre = X.mean(axis=0)  # the box's volume centroid

# (a) rigid rotation of the rest shape
scene = harness.write_scene(os.path.join(args.work, "still.txt"),
                            [("cube.mesh", 1000.0, 1e6, 0.3, 0, (0, 0, 0), (1, 0, 0, 0))])
rotate = ["-deform", "0:0:-1,-1,1", "-steps", "10", "-alpha", "0", "-beta", "0"]
corot = simulate("still_corot", scene, options=rotate + ["-mode", "corotational"])
linear = simulate("still_linear", scene, options=rotate + ["-mode", "linear"])
rotated = corot["mesh/rest_positions"] * np.array([-1, -1, 1])  # 180 deg about z, centroid at 0
checks.check(np.abs(corot["positions"][0] - rotated).max() < 1e-12,
             "(a) frame 0 is the rest shape turned by 180 degrees about z")
scale = linear["energy/elastic"][0]
drift = np.abs(corot["positions"] - corot["positions"][0]).max()
checks.check(scale > 1.0 and corot["energy/elastic"].max() < 1e-9 * scale,
             f"(a) corotational elastic energy {corot['energy/elastic'].max():.2e} J vs linear "
             f"{scale:.3e} J")
checks.check(drift < 1e-9, f"(a) corotational body stays put: max drift {drift:.2e} m")
moved = np.abs(linear["positions"] - linear["positions"][0]).max()
checks.check(moved > 1e-2, f"(a) linear body is pushed by spurious forces: moves {moved:.3f} m")

# (b) spinning cube: omega x r, one turn
omega = np.array([0.0, 0.0, 2 * np.pi])
velocities = [(0, k, np.cross(omega, X[k] - centre)) for k in range(len(X))]
scene = harness.write_scene(os.path.join(args.work, "spin.txt"),
                            [("cube.mesh", 1000.0, 1e7, 0.3, 0, (0, 0, 0), (1, 0, 0, 0))], velocities)
spin = ["-dt", "0.01", "-steps", "100", "-alpha", "0", "-beta", "0.01"]
change = {}
for mode in ("linear", "corotational"):
    r = simulate("spin_" + mode, scene, options=spin + ["-mode", mode])
    tets = r["mesh/tets"]
    change[mode] = volume(r["positions"][-1], tets).sum() / volume(r["positions"][0], tets).sum() - 1
    checks.check(np.isfinite(r["positions"]).all(), f"(b) {mode}: finite after one turn")
print(f"volume change after one turn: linear {100 * change['linear']:+.2f} %, "
      f"corotational {100 * change['corotational']:+.3f} %")
checks.check(abs(change["corotational"]) < 0.02,
             f"(b) corotational volume change {100 * change['corotational']:+.3f} % < 2 %")
checks.check(abs(change["linear"]) > 0.5, f"(b) linear volume change {100 * change['linear']:+.1f} % is far larger")

# (c) small deformations: strike one end face gently
end = np.where(np.isclose(X[:, 0], X[:, 0].max()))[0]
difference = {}
for eps in (1e-2, 1e-3):
    scene = harness.write_scene(os.path.join(args.work, f"small_{eps}.txt"),
                                [("cube.mesh", 1000.0, 1e5, 0.3, 0, (0, 0, 0), (1, 0, 0, 0))],
                                [(0, k, (0.0, eps * 10.0, 0.0)) for k in end])
    small = ["-dt", "0.01", "-steps", "40", "-ksp_rtol", "1e-13"]
    lin = simulate(f"small_lin_{eps}", scene, options=small + ["-mode", "linear"])
    cor = simulate(f"small_cor_{eps}", scene, options=small + ["-mode", "corotational"])
    u_lin = lin["positions"] - lin["mesh/rest_positions"]
    strain = np.abs(u_lin).max()  # of the order of the strain for a unit cube
    difference[eps] = np.abs(cor["positions"] - lin["positions"]).max() / strain
    print(f"eps {eps:g}: max displacement {strain:.3e} m, relative corotational-linear difference "
          f"{difference[eps]:.3e}")
    checks.check(difference[eps] < 20 * strain,
                 f"(c) eps {eps:g}: difference {difference[eps]:.2e} of the order of the strain {strain:.2e}")
checks.check(difference[1e-3] < 0.2 * difference[1e-2],
             f"(c) the difference falls with the strain: {difference[1e-2]:.2e} -> {difference[1e-3]:.2e}")

# (d) inverted initial state
tet = os.path.join(args.work, "tet.mesh")
with open(tet, "w") as f:
    f.write("MeshVersionFormatted 1\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n"
            "Tetrahedra\n1\n1 2 3 4 0\nEnd\n")
scene = harness.write_scene(os.path.join(args.work, "tet.txt"),
                            [("tet.mesh", 1000.0, 1e5, 0.3, 0, (0, 0, 0), (1, 0, 0, 0))])
r = simulate("inverted", scene, options=["-mode", "corotational", "-deform", "0:0:1,1,-1",
                                          "-steps", "200", "-dt", "0.01"])
v = np.array([volume(p, r["mesh/tets"])[0] for p in r["positions"]])
rest = volume(r["mesh/rest_positions"], r["mesh/tets"])[0]
checks.check(v[0] < 0, f"(d) frame 0 inverted: volume {v[0]:.4f} (rest {rest:.4f})")
checks.check(np.isfinite(r["positions"]).all() and np.isfinite(r["energy/elastic"]).all(), "(d) no NaN")
first_positive = int(np.argmax(v > 0))
checks.check(v[-1] > 0 and abs(v[-1] / rest - 1) < 0.05,
             f"(d) recovered: volume positive from frame {first_positive}, final {v[-1]:.4f}")

# (e) 1 rank vs 2 ranks
scene = harness.write_scene(os.path.join(args.work, "ranks.txt"),
                            [("cube.mesh", 1000.0, 1e5, 0.45, 0, (0, 0, 0), (1, 0, 0, 0)),
                             ("cube.mesh", 500.0, 3e5, 0.3, 0, (1.5, 0, 0), (0.9, 0.1, 0.3, 0))],
                            [(0, k, (0.0, 5.0, 2.0)) for k in end] + [(1, 0, (-3.0, 0.0, 1.0))])
tight = ["-mode", "corotational", "-steps", "30", "-ksp_rtol", "1e-12"]
one = simulate("ranks1", scene, ranks=1, options=tight)
two = simulate("ranks2", scene, ranks=2, options=tight)
for name in ("positions", "velocities"):
    rel = harness.relative_difference(two[name], one[name])
    checks.check(rel < 1e-8, f"(e) 1 vs 2 ranks, {name}: relative difference {rel:.2e} < 1e-8")

# (f) non-convergence is flagged, not carried on
partial = os.path.join(args.work, "unconverged.h5")
result = harness.run(args, 2, ["-scene", scene, "-mode", "corotational", "-ksp_max_it", "2",
                               "-steps", "5", "-output", partial], check=False)
checks.check(result.returncode != 0 and "did not converge (DIVERGED_ITS" in result.stderr,
             f"(f) unconverged solve stops the run: {result.stderr.splitlines()[0] if result.stderr else ''}")
import h5py  # noqa: E402
with h5py.File(partial, "r") as f:
    checks.check(f.attrs["complete"] == 0, "(f) the partial result file is marked incomplete")
with h5py.File(os.path.join(args.work, "ranks2.h5"), "r") as f:
    checks.check(f.attrs["complete"] == 1, "(f) a finished run's file is marked complete")
checks.exit()
