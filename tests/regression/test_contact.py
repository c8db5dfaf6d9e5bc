"""Contact inside the implicit step: ground, restitution, free-free and fixed
obstacles, friction, impulse spreading, -dt_schedule, and what a scene without
contact leaves out.

Every figure is recomputed here from the result file (positions, velocities,
energies, the mesh) and compared with something independent of the program:
geometry (the ground plane, barycentric coordinates in the other body's tets),
conservation laws (energy, momentum), closed forms (a column under its own
weight, Coulomb deceleration mu g, the backward-Euler decay of Rayleigh mass
damping) or a second run that differs in one option.

The body: a 0.5 m cube (tools/box_mesh.py, 4 x 4 x 4 cells, 125 vertices, 384
tets), density 1000, E 1e6, nu 0.3; its centroid starts at y = 1 m (bottom face
at 0.75 m, a 0.75 m fall to the ground).

(a) Drop on the ground (-gravity 0,-9.81,0 -ground 0 -restitution 0 -dt 0.01
    -steps 300): penetration below 1 % of the body size at every frame; final
    kinetic energy below 1 % of its peak; kinetic + elastic + gravitational
    never increases by more than 1e-9 of the initial total; rests on the ground
    (min y within 1e-6 of 0, height within 2 % of 0.5 m); resting elastic
    energy within a factor 3 of the uniaxial column estimate.
(b) Restitution 0, 0.4, 0.8: 0.8 bounces (centroid rises after the first
    impact by more than 5 % of the fall height above its resting height), 0 does
    not (below 1 %), the rebound grows with e; every run completes; once the
    body lies still its recorded velocities match its motion (1e-3 m/s).
(c) Two free cubes thrown at each other (no gravity): no vertex deeper than
    0.01 (barycentric) in the other's tets, kinetic energy lost, momentum kept
    to 5 % of one body's, they separate or rest; the moving obstacles' grids
    were built (run summary). Thrown apart instead, their boxes never meet: no
    grid is built, and the first cube moves bit for bit as with the other 100 m
    away.
(d) A cube dropped onto a fixed cube (no ground): rests on it, no penetration,
    the fixed cube bit-for-bit still; the fixed cube's sharp edges met it (run
    summary). A coarse plank (1 x 0.125 x 0.75 m, 2 x 1 x 1 cells) dropped across
    the fixed cube with none of its vertices over the cube's top face: held by
    the cube's top edges alone, it rests on them, no edge point ever inside it
    (0.01 barycentric); with -sharp_edges 0 it falls past the cube. Dropped beside a fixed cube 5 m away onto the ground: no
    sharp-edge contact and the free body's grids never built (its state is
    gathered only while its box meets a fixed body with sharp edges).
(e) Sliding with Coulomb friction 0.5: decelerates at mu g (+ mass damping,
    10 %) while sliding and stops (centroid speed < 1 % of the start) within
    1 s, never sooner than Coulomb's law allows (0.9 x the rigid stopping time
    with mass damping). Against the rigid block's backward-Euler history
    v_{n+1} = (v_n - mu g dt) / (1 + a dt): stopping distance within 5 %
    (measured -0.4 %) and the time to fall below 1 % of the start speed within
    5 % (measured 0 %). (Friction applied only after the solve: 47 % late;
    sliding contacts' friction after the solve: +12.5 %; test_friction.py has
    the closed forms.) Frictionless sliding decays only by the mass damping,
    v0 / (1 + a dt)^n (1e-6).
(f) -impulse_spreading changes the top face's velocity at the impact frame.
(g) -dt_schedule 0.5:0.005: the /time increments, the summary's count, and the
    drop of (a) stays correct.
(h) A scene without ground or obstacles leaves the collision structures out.
"""
import os
import re
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()

SIZE = 0.5            # cube edge (m)
RHO, YOUNG, NU = 1000.0, 1e6, 0.3
G = 9.81
DROP = ["-gravity", "0,-9.81,0", "-ground", "0", "-dt", "0.01", "-steps", "300"]
PENETRATION = 0.01 * SIZE      # 1 % of the body size
# Contacts end -contact_gap (1e-4) of the body's mean boundary edge outside the
# obstacle: a vertex resting on the ground lies within 1e-3 of the body's size above it.
RESTING_GAP = 1e-3 * SIZE
DEPTH = 0.01                   # barycentric depth tolerance
ALPHA = 0.1                    # default Rayleigh mass damping (1/s)


def box_mesh(name, size, cells):
    return harness.box_mesh(args, name, size, cells)


read = harness.read_frames


def simulate(name, scene, options, ranks=2, check=True):
    """Runs softbody; returns (frames or None, stdout, stderr, returncode, seconds)."""
    out = os.path.join(args.work, name + ".h5")
    if os.path.exists(out):
        os.remove(out)
    start = time.time()
    result = harness.run(args, ranks, ["-scene", scene, "-output", out, *options], check=check)
    seconds = time.time() - start
    print(f"  run {name}: {seconds:.1f} s, exit {result.returncode}")
    if result.returncode != 0:
        print("  stderr: " + result.stderr.strip().splitlines()[0] if result.stderr.strip() else "")
    frames = read(out) if os.path.exists(out) else None
    return frames, result.stdout, result.stderr, result.returncode, seconds


def lumped_masses(r, densities):
    """Lumped vertex masses of a result's mesh (rho V / 4 per tet corner)."""
    return harness.lumped_masses(r["mesh/tets"], r["mesh/rest_positions"], r["mesh/vertex_body"], densities)


def depth_inside(points, positions, tets):
    """Largest over tets of the smallest barycentric coordinate, per point
    (> 0: strictly inside some tet; its value says how deep)."""
    a = positions[tets[:, 0]]
    edges = np.stack([positions[tets[:, k]] - a for k in (1, 2, 3)], axis=2)  # T x 3 x 3 (columns)
    inverse = np.linalg.inv(edges)
    rel = points[:, None, :] - a[None, :, :]                                  # P x T x 3
    lam = np.einsum("tij,ptj->pti", inverse, rel)
    bary = np.concatenate([1.0 - lam.sum(axis=2, keepdims=True), lam], axis=2)
    return bary.min(axis=2).max(axis=1)


def first_contact_frame(r, ground=0.0):
    touching = r["positions"][:, :, 1].min(axis=1) <= ground + RESTING_GAP
    return int(np.argmax(touching)) if touching.any() else None


cube = box_mesh("cube.mesh", (SIZE, SIZE, SIZE), (4, 4, 4))
drop_scene = harness.write_scene(os.path.join(args.work, "drop.txt"),
                                 [("cube.mesh", RHO, YOUNG, NU, 0, (0, 1.0, 0), (1, 0, 0, 0))])

# ---------------------------------------------------------------- (a) drop
print("(a) drop on the ground, restitution 0")
a, out_a, _, _, _ = simulate("drop_e0", drop_scene, DROP + ["-restitution", "0"])
P, t = a["positions"], a["time"]
penetration = (0.0 - P[:, :, 1]).max(axis=1)
worst = int(penetration.argmax())
checks.check(a["complete"] == 1 and penetration.max() < PENETRATION,
             f"(a) penetration below the ground {penetration.max():.3e} m (worst at t = {t[worst]:.2f} s) "
             f"< 1 % of the body size ({PENETRATION:g} m) at every frame")
ke = a["energy/kinetic"]
checks.check(ke[-1] < 0.01 * ke.max(),
             f"(a) final kinetic energy {ke[-1]:.3e} J < 1 % of its peak {ke.max():.4g} J "
             f"(at t = {t[ke.argmax()]:.2f} s)")
total = ke + a["energy/elastic"] + a["energy/gravitational"]
gain = np.diff(total)
checks.check(gain.max() <= 1e-9 * abs(total[0]),
             f"(a) total energy never increases: largest frame-to-frame change {gain.max():+.3e} J "
             f"= {gain.max() / abs(total[0]):+.2e} of the initial {total[0]:.4g} J (limit 1e-9); "
             f"{total[0] - total[-1]:.4g} J dissipated")
# Gravitational energy recomputed: -sum m g.x with g = (0, -9.81, 0).
masses = lumped_masses(a, [RHO])
grav = G * (P[:, :, 1] * masses).sum(axis=1)
rel = np.abs(grav - a["energy/gravitational"]).max() / abs(grav[0])
checks.check(rel < 1e-12 and abs(masses.sum() - RHO * SIZE ** 3) < 1e-9,
             f"(a) gravitational energy = sum m g y recomputed to {rel:.1e}; mass {masses.sum():.6g} kg")
final_min = P[-1, :, 1].min()
height = P[-1, :, 1].max() - final_min
checks.check(0 < final_min <= RESTING_GAP and abs(height - SIZE) < 0.02 * SIZE,
             f"(a) rests on the ground: final min y {final_min:.2e} m (in (0, {RESTING_GAP:g}]), height {height:.5f} m "
             f"(within 2 % of {SIZE} m)")
# Column under its own weight, uniaxial: strain at depth s below the top is
# rho g s / E, energy density (rho g s)^2 / (2E), integrated over the height:
# (rho g)^2 h^3 A / (6 E). The bottom is free to slide sideways (frictionless),
# so the uniaxial estimate holds up to Poisson effects; a factor 3 either way.
column = (RHO * G) ** 2 * SIZE ** 3 * SIZE ** 2 / (6 * YOUNG)
elastic = a["energy/elastic"][-1]
checks.check(column / 3 < elastic < 3 * column,
             f"(a) resting elastic energy {elastic:.4f} J vs column estimate (rho g)^2 h^3 A / (6E) = "
             f"{column:.4f} J (ratio {elastic / column:.3f}, accepted 1/3..3)")
rest_centroid = P[-1, :, 1] @ masses / masses.sum()

# ---------------------------------------------------------------- (b) restitution
print("(b) restitution 0, 0.4, 0.8")
fall = 1.0 - SIZE / 2  # centroid fall height to first touch (m)
rebound = {}
for e in (0.0, 0.4, 0.8):
    r = a if e == 0.0 else simulate(f"drop_e{e}", drop_scene, DROP + ["-restitution", str(e)], check=False)[0]
    if r is None:
        checks.check(False, f"(b) e = {e}: no result file")
        continue
    checks.check(r["complete"] == 1, f"(b) e = {e}: run complete ({len(r['time'])} of 301 frames written)")
    cy = r["positions"][:, :, 1] @ masses / masses.sum()
    first = first_contact_frame(r)
    if first is None:
        checks.check(False, f"(b) e = {e}: never touches the ground")
        continue
    low = first + int(np.argmin(cy[first:first + 20]))  # end of the first compression
    rise = cy[low:].max() - rest_centroid
    rebound[e] = rise / fall
    # While the body lies still on the ground its recorded velocities must be
    # those of the motion (x1 = x0 + dt v1): on every frame where no vertex moved
    # faster than 1e-3 m/s since the previous one, |v - (x1 - x0) / dt| < 1e-3 m/s.
    motion = np.abs(np.diff(r["positions"], axis=0)).max(axis=(1, 2)) / 0.01
    mismatch = np.abs(r["velocities"][1:] - np.diff(r["positions"], axis=0) / 0.01).max(axis=(1, 2))
    still = np.where(motion < 1e-3)[0]
    if len(still):
        worst = still[int(np.argmax(mismatch[still]))]
        checks.check(mismatch[still].max() < 1e-3,
                     f"(b) e = {e}: on the {len(still)} frames where the body lies still (motion < 1e-3 m/s) the "
                     f"recorded velocities match the motion to {mismatch[worst]:.2e} m/s (worst t = "
                     f"{r['time'][worst + 1]:.2f} s; < 1e-3)")
    else:
        print(f"  e = {e}: the body never lies still in this run (no resting-velocity check)")
    print(f"  e = {e}: first contact t = {r['time'][first]:.2f} s, centroid lowest {cy[low]:.5f} m, highest "
          f"after {cy[low:].max():.5f} m, resting {rest_centroid:.5f} m: rebound {rise:+.4e} m = "
          f"{rebound[e]:+.4f} of the fall {fall} m (ideal rigid bounce e^2 = {e * e:.2f})")
if 0.8 in rebound:
    checks.check(rebound[0.8] > 0.05,
                 f"(b) e = 0.8 bounces: centroid rises {rebound[0.8] * fall:.4f} m above its resting height "
                 f"after the first impact ({rebound[0.8]:.4f} of the fall; required > 0.05)")
checks.check(rebound[0.0] < 0.01,
             f"(b) e = 0 does not bounce: rise {rebound[0.0] * fall:.2e} m ({rebound[0.0]:.2e} of the fall; < 0.01)")
if len(rebound) == 3:
    checks.check(rebound[0.0] + 0.005 < rebound[0.4] < rebound[0.8] - 0.005,
                 f"(b) rebound grows with e: {rebound[0.0]:.4f} < {rebound[0.4]:.4f} < {rebound[0.8]:.4f} "
                 f"(steps of at least 0.005)")

# ---------------------------------------------------------------- (c) two free bodies
print("(c) two cubes thrown at each other")
half = SIZE / 2
gap = 0.6
left, right = (-(gap / 2 + half), 0.0, 0.0), (gap / 2 + half, 0.1, 0.0)
X = a["mesh/rest_positions"] - a["mesh/rest_positions"].mean(axis=0)  # any placement; only counts matter
nv = len(X)
velocities = [(0, k, (2.0, 0.0, 0.0)) for k in range(nv)] + [(1, k, (-2.0, 0.0, 0.0)) for k in range(nv)]
pair_scene = harness.write_scene(os.path.join(args.work, "pair.txt"),
                                 [("cube.mesh", RHO, YOUNG, NU, 0, left, (1, 0, 0, 0)),
                                  ("cube.mesh", RHO, YOUNG, NU, 0, right, (1, 0, 0, 0))], velocities)
c, out_c, _, _, _ = simulate("pair", pair_scene, ["-restitution", "0", "-dt", "0.01", "-steps", "100"])
body = c["mesh/vertex_body"]
tets, P = c["mesh/tets"], c["positions"]
tet_body = body[tets[:, 0]]
depth = np.zeros(len(P))
for f in range(len(P)):
    d0 = depth_inside(P[f][body == 0], P[f], tets[tet_body == 1]).max()
    d1 = depth_inside(P[f][body == 1], P[f], tets[tet_body == 0]).max()
    depth[f] = max(d0, d1)
worst = int(depth.argmax())
checks.check(c["complete"] == 1 and depth.max() < DEPTH,
             f"(c) deepest vertex of one cube in the other's tets: barycentric {depth.max():+.2e} at "
             f"t = {c['time'][worst]:.2f} s (< {DEPTH})")
m = lumped_masses(c, [RHO, RHO])
V = c["velocities"]
centroid = np.stack([(P[:, body == b] * m[body == b][None, :, None]).sum(axis=1) / m[body == b].sum()
                     for b in (0, 1)])  # 2 x F x 3
cvel = np.stack([(V[:, body == b] * m[body == b][None, :, None]).sum(axis=1) / m[body == b].sum()
                 for b in (0, 1)])
# The impact: the first frame where the bounding boxes overlap in x.
xmax0 = P[:, body == 0, 0].max(axis=1)
xmin1 = P[:, body == 1, 0].min(axis=1)
impact = int(np.argmax(xmax0 >= xmin1 - 1e-9))
ke = c["energy/kinetic"]
checks.check(ke[-1] < ke[impact - 1],
             f"(c) inelastic: kinetic energy {ke[impact - 1]:.4g} J before impact (t = {c['time'][impact - 1]:.2f} s),"
             f" {ke[-1]:.4g} J at the end")
momentum = (V * m[None, :, None]).sum(axis=1)  # F x 3
one_body = m[body == 0].sum() * 2.0
drift = np.linalg.norm(momentum - momentum[0], axis=1).max()
checks.check(drift < 0.05 * one_body,
             f"(c) total momentum kept: largest change {drift:.3e} kg m/s < 5 % of one body's {one_body:.4g} kg m/s")
builds = re.search(r"grids built in (\d+) passes", out_c)
checks.check(builds is not None and int(builds.group(1)) > 0,
             f"(c) the moving obstacles' grids were built for the impact: {builds.group(0) if builds else None}")
# The same cubes thrown apart: their boxes never meet, so no grid is built and
# the run equals one in which they are 100 m apart to the last bit.
apart_v = [(0, k, (-2.0, 0.0, 0.0)) for k in range(nv)] + [(1, k, (2.0, 0.0, 0.0)) for k in range(nv)]
apart_scene = harness.write_scene(os.path.join(args.work, "apart.txt"),
                                  [("cube.mesh", RHO, YOUNG, NU, 0, left, (1, 0, 0, 0)),
                                   ("cube.mesh", RHO, YOUNG, NU, 0, right, (1, 0, 0, 0))], apart_v)
ap, out_ap, _, _, _ = simulate("apart", apart_scene, ["-dt", "0.01", "-steps", "20"])
builds = re.search(r"grids built in (\d+) passes", out_ap)
checks.check(builds is not None and int(builds.group(1)) == 0,
             f"(c) thrown apart: no grid built ({builds.group(0) if builds else None})")
far_scene = harness.write_scene(os.path.join(args.work, "far.txt"),
                                [("cube.mesh", RHO, YOUNG, NU, 0, left, (1, 0, 0, 0)),
                                 ("cube.mesh", RHO, YOUNG, NU, 0, (100.0, 0.1, 0.0), (1, 0, 0, 0))], apart_v)
far, _, _, _, _ = simulate("far", far_scene, ["-dt", "0.01", "-steps", "20"])
same = ap is not None and far is not None and np.array_equal(ap["positions"][:, body == 0], far["positions"][:, body == 0])
checks.check(same, "(c) thrown apart: the first cube moves bit for bit as with the other 100 m away")
normal = centroid[1, -1] - centroid[0, -1]
normal /= np.linalg.norm(normal)
separating = (cvel[1, -1] - cvel[0, -1]) @ normal
checks.check(separating >= -1e-3,
             f"(c) at the end they separate or rest: relative normal velocity of the centroids {separating:+.3e} m/s "
             f"(>= -1e-3)")

# ---------------------------------------------------------------- (d) fixed obstacle
print("(d) a cube dropped onto a fixed cube")
fixed_scene = harness.write_scene(os.path.join(args.work, "fixed.txt"),
                                  [("cube.mesh", RHO, YOUNG, NU, 1, (0, 0, 0), (1, 0, 0, 0)),
                                   ("cube.mesh", RHO, YOUNG, NU, 0, (0.05, 1.0, 0.0), (1, 0, 0, 0))])
d, out_d, _, _, _ = simulate("fixed", fixed_scene, ["-gravity", "0,-9.81,0", "-restitution", "0", "-dt", "0.01",
                                                "-steps", "300"])
body, tets, P = d["mesh/vertex_body"], d["mesh/tets"], d["positions"]
tet_body = body[tets[:, 0]]
depth = np.array([depth_inside(P[f][body == 1], P[f], tets[tet_body == 0]).max() for f in range(len(P))])
top = half  # top face of the fixed cube
# Below the top face only counts over the fixed cube's footprint (the free cube
# overhangs it by 0.05 m in x, and the overhang may sag past the edge).
over = (np.abs(P[:, :, 0]) < half - 1e-9) & (np.abs(P[:, :, 2]) < half - 1e-9) & (body == 1)[None, :]
below = np.where(over, top - P[:, :, 1], -np.inf).max(axis=1)
checks.check(d["complete"] == 1 and depth.max() < DEPTH and below.max() < PENETRATION,
             f"(d) no penetration: barycentric depth {depth.max():+.2e} (< {DEPTH}), deepest below the fixed "
             f"top face over its footprint {below.max():.2e} m (< {PENETRATION} m)")
ke = d["energy/kinetic"]
lowest = np.where(over[-1], P[-1, :, 1], np.inf).min()
checks.check(ke[-1] < 0.01 * ke.max() and abs(lowest - top) < PENETRATION,
             f"(d) rests on it: final KE {ke[-1]:.2e} J < 1 % of peak {ke.max():.4g} J, lowest vertex over the "
             f"fixed cube at y = {lowest:.6f} m (top face {top} m)")
still = bool(np.array_equal(P[:, body == 0], np.broadcast_to(d["mesh/rest_positions"][body == 0],
                                                              P[:, body == 0].shape)))
checks.check(still and d["mesh/body_fixed"][0] == 1,
             f"(d) the fixed cube is bit-for-bit at its rest positions in all {len(P)} frames")

# Sharp edges cost nothing while no free body comes near a fixed one: the same
# cube dropped beside the fixed cube (5 m away) onto the ground builds no grid
# of the free body (nor exchanges its state); over it, the grids are built.
builds = re.search(r"(\d+) sharp-edge contacts; moving obstacles' grids built in (\d+) passes", out_d)
checks.check(builds is not None and int(builds.group(1)) > 0 and int(builds.group(2)) > 0,
             f"(d) the fixed cube's sharp edges met the falling cube: {builds.group(0) if builds else None}")
beside_scene = harness.write_scene(os.path.join(args.work, "beside.txt"),
                                   [("cube.mesh", RHO, YOUNG, NU, 1, (5.0, 0, 0), (1, 0, 0, 0)),
                                    ("cube.mesh", RHO, YOUNG, NU, 0, (0.05, 1.0, 0.0), (1, 0, 0, 0))])
_, out_beside, _, _, _ = simulate("beside", beside_scene, ["-gravity", "0,-9.81,0", "-ground", "0", "-dt", "0.01",
                                                           "-steps", "100"])
builds = re.search(r"grids built in (\d+) passes", out_beside)
checks.check(builds is not None and int(builds.group(1)) == 0 and "free state exchanged" not in out_beside
             and "sharp-edge contacts" not in out_beside,
             f"(d) a fixed cube 5 m away: no sharp-edge contact, {builds.group(0) if builds else None}")

# Held by edges alone: a plank across the fixed cube whose vertices all lie beside
# its top face (x = -0.5, 0, 0.5 and z = +-0.375 around a face of |x|, |z| <= 0.25):
# only the cube's top edges can catch it. With sharp edges it comes to rest on them
# and no point of those edges (sampled every 2.5 cm) is ever inside a plank tet;
# with -sharp_edges 0 the collision guard alone holds it the same way, and with the
# guard off too nothing holds it and it falls past the cube.
box_mesh("plank.mesh", (1.0, 0.125, 0.75), (2, 1, 1))
plank_scene = harness.write_scene(os.path.join(args.work, "plank.txt"),
                                  [("cube.mesh", RHO, YOUNG, NU, 1, (0, 0, 0), (1, 0, 0, 0)),
                                   ("plank.mesh", RHO, 2e4, NU, 0, (0, 0.6, 0), (1, 0, 0, 0))])
z = np.linspace(-half, half, 21)
top_edges = np.concatenate([np.c_[np.full_like(z, x), np.full_like(z, half), z] for x in (-half, half)]
                           + [np.c_[z, np.full_like(z, half), np.full_like(z, c)] for c in (-half, half)])
for sharp, guard in ((1, 1), (0, 1), (0, 0)):
    e, out_e, _, _, _ = simulate(f"plank_sharp{sharp}_guard{guard}", plank_scene,
                                 ["-gravity", "0,-9.81,0", "-dt", "0.01", "-steps", "200",
                                  "-sharp_edges", str(sharp), "-contact_guard", str(guard)])
    body, tets, P = e["mesh/vertex_body"], e["mesh/tets"], e["positions"]
    plank_tets = tets[body[tets[:, 0]] == 1]
    edge_depth = max(depth_inside(top_edges, P[f], plank_tets).max() for f in range(len(P)))
    ke, lowest = e["energy/kinetic"], P[-1, body == 1, 1].min()
    held_by = "sharp-edge points and the guard" if sharp else "the collision guard alone"
    # Held by the guard alone, the plank's overhanging ends sag further (frozen zones at the edges).
    floor = half - (1 if sharp else 5) * PENETRATION
    if guard:
        checks.check(edge_depth < DEPTH and ke[-1] < 0.01 * ke.max() and lowest > floor,
                     f"(d) a plank held only by the fixed cube's edges rests on them ({held_by}): edge points "
                     f"at most {edge_depth:+.1e} (barycentric) inside it (< {DEPTH}), final KE {ke[-1]:.2e} J < "
                     f"1 % of peak {ke.max():.4g} J, lowest plank vertex y = {lowest:.4f} m > {floor:g} (top face {half} m)")
    else:
        checks.check(lowest < -1.0 and "sharp-edge contacts" not in out_e,
                     f"(d) with -sharp_edges 0 -contact_guard 0 nothing holds the plank: it falls to "
                     f"y = {lowest:.2f} m (edge points up to {edge_depth:+.2f} inside it on the way)")

# ---------------------------------------------------------------- (e) friction
print("(e) sliding on the ground")
V0 = 2.0
slide_scene = harness.write_scene(os.path.join(args.work, "slide.txt"),
                                  [("cube.mesh", RHO, YOUNG, NU, 0, (0, half, 0), (1, 0, 0, 0))],
                                  [(0, k, (V0, 0.0, 0.0)) for k in range(nv)])
SLIDE = ["-gravity", "0,-9.81,0", "-ground", "0", "-restitution", "0", "-dt", "0.01", "-steps", "100"]
e1, _, _, _, _ = simulate("slide_mu05", slide_scene, SLIDE + ["-friction", "0.5"])
mu = 0.5
vx = e1["velocities"][:, :, 0] @ masses / masses.sum()
t = e1["time"]
checks.check(abs(vx[0] - V0) < 1e-12 and abs(e1["positions"][0, :, 1].min()) < 1e-12,
             f"(e) starts on the ground (min y {e1['positions'][0, :, 1].min():g}) at {vx[0]:g} m/s")
# Sliding phase (first 0.3 s, speed still > 0.5 m/s): Coulomb plus mass damping,
# backward Euler v_{n+1} = (v_n - mu g dt) / (1 + a dt).
expected = [V0]
for _ in range(30):
    expected.append((expected[-1] - mu * G * 0.01) / (1 + ALPHA * 0.01))
decel, decel_expected = (vx[0] - vx[30]) / t[30], (V0 - expected[30]) / t[30]
checks.check(abs(decel / decel_expected - 1) < 0.1,
             f"(e) mu = 0.5, sliding phase (0..{t[30]:.2f} s): mean deceleration {decel:.3f} m/s^2 vs "
             f"mu g + mass damping {decel_expected:.3f} m/s^2 ({100 * (decel / decel_expected - 1):+.1f} %, within 10 %)")
stopped = np.abs(vx) < 0.01 * V0
stop_frame = int(np.argmax(stopped)) if stopped.any() else None
analytic = V0 / (mu * G)
with_damping = np.log(1 + ALPHA * V0 / (mu * G)) / ALPHA
if stop_frame is None:
    checks.check(False, f"(e) mu = 0.5: never below 1 % of the start speed within 1 s (final {vx[-1]:.3f} m/s)")
else:
    t_stop = t[stop_frame]
    checks.check(t_stop <= 1.0 and np.all(stopped[stop_frame:]),
                 f"(e) mu = 0.5 stops: centroid speed {abs(vx[stop_frame]):.2e} m/s < 1 % of {V0} m/s from "
                 f"t = {t_stop:.2f} s on (final {vx[-1]:.1e} m/s)")
    checks.check(t_stop >= 0.9 * with_damping,
                 f"(e) stopping time {t_stop:.2f} s, not sooner than Coulomb allows: rigid v / (mu g) = "
                 f"{analytic:.3f} s, with the mass damping ln(1 + a v / (mu g)) / a = {with_damping:.3f} s "
                 f"({100 * (t_stop / analytic - 1):+.1f} % of the rigid time)")
    # The rigid block's discrete history: speed and distance until it stops,
    # and the time it first falls below 1 % of the start speed.
    v, distance, below = V0, 0.0, None
    for step in range(1, 1000):
        v = (v - mu * G * 0.01) / (1 + ALPHA * 0.01)
        if v <= 0:
            break
        distance += v * 0.01
        if below is None and v < 0.01 * V0:
            below = step * 0.01
    below = below if below is not None else step * 0.01
    cx = e1["positions"][:, :, 0] @ masses / masses.sum()
    slid = cx[-1] - cx[0]
    checks.check(abs(slid / distance - 1) < 0.05,
                 f"(e) stopping distance {slid:.4f} m vs the rigid block's backward-Euler {distance:.4f} m "
                 f"({100 * (slid / distance - 1):+.1f} %, within 5 %; continuous v^2 / (2 mu g) = "
                 f"{V0 ** 2 / (2 * mu * G):.4f} m)")
    checks.check(abs(t_stop / below - 1) < 0.05,
                 f"(e) below 1 % of the start speed at t = {t_stop:.2f} s vs the rigid block's backward-Euler "
                 f"{below:.2f} s ({100 * (t_stop / below - 1):+.1f} %, within 5 %)")
    # Diagnosis: once the contact face sticks, the speed decays by a constant
    # factor per step instead of stopping; compare it with the contact layer's mass.
    Xr = e1["mesh/rest_positions"]
    base = np.isclose(Xr[:, 1], Xr[:, 1].min())
    base_speed = e1["velocities"][:, base, 0].mean(axis=1)
    stuck = int(np.argmax(np.abs(base_speed) < 1e-6))
    if 0 < stuck < len(vx) - 3:
        ratio = vx[stuck + 1:stuck + 4] / vx[stuck:stuck + 3]
        print(f"  contact face stops slipping at t = {t[stuck]:.2f} s with the centroid still at {vx[stuck]:.4f} m/s;"
              f" then the centroid speed falls by a factor {ratio.mean():.3f} per step (1 - contact-face mass "
              f"fraction = {1 - masses[base].sum() / masses.sum():.3f})")
e0, _, _, _, _ = simulate("slide_mu0", slide_scene, SLIDE + ["-friction", "0"])
vx = e0["velocities"][:, :, 0] @ masses / masses.sum()
n = np.arange(len(vx))
discrete = V0 / (1 + ALPHA * 0.01) ** n
continuous = V0 * np.exp(-ALPHA * e0["time"])
rel = np.abs(vx - discrete).max() / V0
checks.check(rel < 1e-6 and vx[-1] > 0.85 * V0,
             f"(e) mu = 0: keeps {vx[-1] / V0:.4f} of its speed after 1 s; v0 / (1 + a dt)^n = "
             f"{discrete[-1] / V0:.4f} (agree to {rel:.1e}, < 1e-6), exp(-a t) = {continuous[-1] / V0:.4f}")

# ---------------------------------------------------------------- (f) impulse spreading
print("(f) impulse spreading")
s, _, _, _, _ = simulate("drop_spread", drop_scene, DROP + ["-restitution", "0", "-impulse_spreading"])
X = a["mesh/rest_positions"]
top_face = np.where(np.isclose(X[:, 1], X[:, 1].max()))[0]
first_a, first_s = first_contact_frame(a), first_contact_frame(s)
checks.check(first_a == first_s and first_a is not None,
             f"(f) both runs first touch the ground at frame {first_a} (t = {a['time'][first_a]:.2f} s) / {first_s}")
dv_plain = (a["velocities"][first_a, top_face, 1] - a["velocities"][first_a - 1, top_face, 1]).mean()
dv_spread = (s["velocities"][first_s, top_face, 1] - s["velocities"][first_s - 1, top_face, 1]).mean()
free_fall = -G * 0.01 / (1 + ALPHA * 0.01)  # roughly the change a free top face would see
print(f"  top face ({len(top_face)} vertices) vertical velocity change at the impact frame: without spreading "
      f"{dv_plain:+.4f} m/s, with {dv_spread:+.4f} m/s (free fall alone about {free_fall:+.4f} m/s); "
      f"before impact {a['velocities'][first_a - 1, top_face, 1].mean():+.4f} m/s")
checks.check(abs(dv_spread - dv_plain) > 1e-3 * abs(a["velocities"][first_a - 1, top_face, 1].mean()),
             f"(f) spreading changes the top face's response: {dv_plain:+.4f} vs {dv_spread:+.4f} m/s")
checks.check(dv_spread > dv_plain,
             f"(f) with spreading the top face is slowed more at the impact frame "
             f"(upward change {dv_spread:+.4f} > {dv_plain:+.4f} m/s)")
pen = (0.0 - s["positions"][:, :, 1]).max()
ke = s["energy/kinetic"]
checks.check(s["complete"] == 1 and pen < PENETRATION and ke[-1] < 0.01 * ke.max(),
             f"(f) with spreading the drop is still correct: penetration {pen:.1e} m, final KE {ke[-1]:.1e} J")

# ---------------------------------------------------------------- (g) -dt_schedule
print("(g) -dt_schedule 0.5:0.005")
g, out_g, _, _, _ = simulate("drop_schedule", drop_scene, DROP + ["-restitution", "0", "-dt_schedule", "0.5:0.005"])
t = g["time"]
steps = np.diff(t)
before, after = t[:-1] < 0.5 - 1e-9, t[:-1] >= 0.5 - 1e-9
err_before = np.abs(steps[before] - 0.01).max()
err_after = np.abs(steps[after] - 0.005).max()
checks.check(before.sum() == 50 and after.sum() == 250 and err_before < 1e-12 and err_after < 1e-12,
             f"(g) /time increments: {before.sum()} of 0.01 s before t = 0.5 (max error {err_before:.1e}), "
             f"{after.sum()} of 0.005 s after (max error {err_after:.1e}); ends at t = {t[-1]:.4f} s")
changes = re.search(r"(\d+) time step changes?", out_g)
checks.check(changes is not None and int(changes.group(1)) == 1,
             f"(g) the summary reports {changes.group(0) if changes else 'no time step change'}")
pen = (0.0 - g["positions"][:, :, 1]).max()
ke = g["energy/kinetic"]
total = ke + g["energy/elastic"] + g["energy/gravitational"]
gain = np.diff(total).max()
checks.check(g["complete"] == 1 and pen < PENETRATION and ke[-1] < 0.01 * ke.max()
             and gain <= 1e-9 * abs(total[0]) and 0 < g["positions"][-1, :, 1].min() <= RESTING_GAP,
             f"(g) the drop stays correct: penetration {pen:.1e} m, final KE {ke[-1]:.1e} J (peak {ke.max():.4g}), "
             f"largest energy increase {gain:+.1e} J, final min y {g['positions'][-1, :, 1].min():.1e} m")

# ---------------------------------------------------------------- (h) nothing to collide
print("(h) a scene without ground or obstacles")
h, out_h, _, _, _ = simulate("alone", drop_scene, ["-gravity", "0,-9.81,0", "-dt", "0.01", "-steps", "5"])
left_out = [line for line in out_h.splitlines() if line.strip().startswith("left out")]
contact_lines = [line for line in out_h.splitlines() if line.strip().startswith("contact")]
checks.check(len(left_out) == 1 and "collision structures and constraint pass" in left_out[0],
             f"(h) 'left out' names the collision structures and constraint pass: {left_out[0].strip() if left_out else None}")
checks.check(not contact_lines and "contact" in out_a,
             f"(h) no 'contact' line (the drop of (a) has one: "
             f"{[l.strip() for l in out_a.splitlines() if l.strip().startswith('contact')]})")
checks.exit()
