"""What a rank holds of the whole scene with contact, as the run summary counts it.

Two free boxes (tools/box_mesh.py, 4 x 0.5 x 0.5 m of 32 x 4 x 4 cells each)
stacked above the ground, under gravity, 2 steps, on 1 and 4 ranks. Contact is
set up from the ranks' shares of the meshes (src/contact/contact_meshes.hpp): no
body's mesh is ever whole on a rank (a fixed body's tets are held where a rank's
vertices are, src/contact/fixed_tets.hpp); the free bodies' tets and triangles a rank holds are those
listed under its own vertices and its halo's (src/contact/free_items.hpp); the
free state keeps one natural-indexed array, the slot of each vertex
(src/contact/free_state.hpp), and the numbering one, its PETSc vertex
(src/fem/partition.hpp).

Expected, from the mesh file alone (V vertices and T tets per box, F boundary
triangles per box counted here as the faces that one tet only names):
(a) the "scene" line says the meshes were held in slabs (4 ranks), also with a
    fixed body; the "whole scene" line counts 0 MB of meshes on every rank at
    the end, and 0 MB during contact's set-up (1 and 4 ranks, and with a third
    box, fixed, under the two: its mesh is not whole either); with
    -scene_replicate (4 ranks) every mesh is whole during the set-up, 24 V + 16 T
    (positions 24 B per vertex, tets 16 B; the initial velocities take 32 B per
    line of the velocity section, and these scenes have none);
(b) the obstacles' lists on 1 rank: every tet (its 4 vertices and body, its key
    vertex and its index: 28 B) and boundary triangle (3 vertices and body, key and
    index: 24 B), once: 28 T + 24 F over the scene, within the summary's 3 digits
    (1 %). On 4 ranks the largest rank holds less than 3/4 of that: a quarter as
    its own, and the items listed under the vertices within the halo's reach of
    its part. Lists replicated on every rank would hold the same on any rank
    count;
(c) the free state: 4 B per scene vertex (the slot; positions, velocities and
    masses are kept per slot, for this rank's own and received vertices only;
    a vertex's body comes from the bodies' first vertices, whether it moves from
    the numbering), within 1 %; the numbering: 4 B per scene vertex (its PETSc
    vertex; 32-bit PetscInt, Debian's build);
(d) overlap separation holds nothing at the end: no pair starts overlapping, and
    its surfaces are released after the first check;
(e) the collision guard's part of the surfaces (src/contact/held_surface.hpp): on
    1 rank the whole surface, 81 B per surface vertex (natural vertex, body and
    whole index 12 B; start and end positions 48 B, mass 8 B, owned and local
    vertex 8 B, five flags 5 B), 16 B per boundary triangle (its vertices and
    index) and 8 B per boundary edge, within 1 %; on 4 ranks the largest rank
    holds less than 0.85 of that (its own vertices' triangles and edges, and the
    halo's). A surface replicated on every rank would hold the same on any rank
    count.
"""
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                                "tools"))
from softbody_tools import read_medit  # noqa: E402

BOX = ((4.0, 0.5, 0.5), (32, 4, 4))
RANKS = (1, 4)
# The largest rank's lists on 4 ranks over the scene's, at most: the obstacles'
# (measured 0.65) and the guard's part of the surfaces (measured 0.74: with
# these thin boxes a rank's halo reaches far along them, and the guard keeps
# the halo's pending primitives and the vertices it sent). Lists replicated on
# every rank hold 1.0.
HELD_FRACTION = {"obstacles": 0.75, "guard": 0.85}
TOLERANCE = 0.01  # relative: the summary prints 3 significant digits
IN_SLABS = "meshes read on rank 0, then held in slabs"
SETUP = r"meshes during contact's set-up (?P<setup>[0-9.e+-]+) MB"
PART = r"{} (?P<{}>[0-9.e+-]+) MB"


def boundary_triangles(tets):
    """The faces that one tet only names."""
    faces = np.sort(np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]],
                                    tets[:, [0, 1, 2]]]), axis=1)
    _, counts = np.unique(faces, axis=0, return_counts=True)
    return int(np.count_nonzero(counts == 1))


def boundary_edges(tets):
    """The edges of the faces that one tet only names."""
    faces = np.sort(np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]],
                                    tets[:, [0, 1, 2]]]), axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    boundary = unique[counts == 1]
    edges = np.sort(np.concatenate([boundary[:, [0, 1]], boundary[:, [1, 2]], boundary[:, [0, 2]]]), axis=1)
    return np.unique(edges, axis=0)


def line(stdout, start):
    return next((l.strip() for l in stdout.splitlines() if l.strip().startswith(start)), "")


def scene_bytes(text):
    """The "whole scene" line's parts (bytes), or {} when it is missing."""
    parts = {}
    for label, key in (("meshes", "meshes"), ("numbering", "numbering"), ("free state", "free_state"),
                       ("obstacles", "obstacles"), ("guard", "guard"), ("overlap separation", "separation")):
        match = re.search(PART.format(label, key), text)
        if match:
            parts[key] = float(match.group(key)) * 1e6
    match = re.search(SETUP, text)
    if match:
        parts["setup"] = float(match.group("setup")) * 1e6
    return parts


def close(measured, expected):
    return abs(measured - expected) <= TOLERANCE * expected


def main():
    args = harness.arguments()
    checks = harness.Checks()
    mesh = harness.box_mesh(args, "box.mesh", *BOX)
    vertices, _, _, tets = read_medit(mesh)
    T, F, V = 2 * len(tets), 2 * boundary_triangles(tets), 2 * len(vertices)
    edges = boundary_edges(tets)
    E, S = 2 * len(edges), 2 * len(np.unique(edges))
    guard = 81 * S + 16 * F + 8 * E
    scene = os.path.join(args.work, "two-boxes.txt")
    with open(scene, "w") as f:
        f.write("2\n")
        for y in (0.3, 0.85):
            f.write(f"box.mesh 1000 1e5 0.3 0 0 {y} 0 1 0 0 0\n")
    expected = 28 * T + 24 * F
    run = ["-steps", "2", "-dt", "0.01", "-ground", "0", "-gravity", "0,-9.81,0"]
    for ranks in RANKS:
        stdout = harness.run(args, ranks, ["-scene", scene] + run).stdout
        whole = line(stdout, "whole scene")
        parts = scene_bytes(whole)
        checks.check(len(parts) == 7, f"{ranks} ranks: the summary counts the whole-scene arrays: {whole!r}")
        if len(parts) != 7:
            continue
        if ranks > 1:
            checks.check(IN_SLABS in line(stdout, "scene "), f"{ranks} ranks: {line(stdout, 'scene ')!r}")
        checks.check(parts["meshes"] == 0, f"{ranks} ranks: no rank keeps the meshes ({parts['meshes']:.0f} B)")
        checks.check(parts["setup"] == 0,
                     f"{ranks} ranks: no rank holds a free body's mesh whole during contact's set-up "
                     f"({parts['setup']:.0f} B)")
        check_held(checks, ranks, "obstacles", parts["obstacles"], expected, "the scene's 28 T + 24 F",
                   f"T {T}, F {F}")
        check_held(checks, ranks, "guard", parts["guard"], guard, "the whole surface's 81 S + 16 F + 8 E",
                   f"S {S}, F {F}, E {E}")
        checks.check(close(parts["free_state"], 4 * V),
                     f"{ranks} ranks: free state {parts['free_state']:.0f} B, expected 4 V = {4 * V} B")
        checks.check(close(parts.get("numbering", -1), 4 * V),
                     f"{ranks} ranks: numbering {parts['numbering']:.0f} B, expected 4 V = {4 * V} B")
        checks.check(parts["separation"] == 0,
                     f"{ranks} ranks: overlap separation {parts['separation']:.0f} B, expected 0 (released)")
    check_setup_meshes(args, checks, scene, run, V, T)
    checks.exit()


def check_held(checks, ranks, label, held, whole, formula, counts):
    """(b), (e): the lists of a part on 1 rank hold the whole, on more ranks less than HELD_FRACTION."""
    fraction = HELD_FRACTION[label]
    if ranks == 1:
        checks.check(close(held, whole), f"1 rank: {label} {held:.0f} B, expected {formula} = {whole} B ({counts})")
    else:
        checks.check(held <= fraction * whole,
                     f"{ranks} ranks: {label} {held:.0f} B on the largest rank, {held / whole:.2f} of {formula} "
                     f"(at most {fraction})")


def check_setup_meshes(args, checks, scene, run, V, T):
    """(a): the meshes held during contact's set-up: whole with -scene_replicate, else none."""
    whole = scene_bytes(line(harness.run(args, 4, ["-scene", scene, "-scene_replicate"] + run).stdout,
                             "whole scene")).get("setup", -1)
    checks.check(close(whole, 24 * V + 16 * T),
                 f"4 ranks, -scene_replicate: meshes during contact's set-up {whole:.0f} B, expected "
                 f"24 V + 16 T = {24 * V + 16 * T} B")
    with_fixed = os.path.join(args.work, "two-boxes-on-a-fixed-one.txt")
    with open(scene) as f, open(with_fixed, "w") as g:
        lines = f.read().splitlines()
        g.write("3\n" + "\n".join(lines[1:]) + "\nbox.mesh 1000 1e5 0.3 1 0 -0.3 0 1 0 0 0\n")
    stdout = harness.run(args, 4, ["-scene", with_fixed] + run).stdout
    checks.check(line(stdout, "scene ").endswith(IN_SLABS),
                 f"4 ranks, a fixed box under the two: {line(stdout, 'scene ')!r}")
    fixed = scene_bytes(line(stdout, "whole scene")).get("setup", -1)
    checks.check(fixed == 0, f"4 ranks, a fixed box under the two: meshes during contact's set-up "
                 f"{fixed:.0f} B, expected 0")


if __name__ == "__main__":
    main()
