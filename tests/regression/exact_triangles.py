"""An independent exact count of crossing surface triangles, for the tests of
softbody-crossings (not a test itself).

Closed triangles, decided with exact arithmetic: every orientation is first
computed in floating point and trusted only when its magnitude exceeds a bound
on its rounding error (Shewchuk's orient3d bound is 7.8e-16 of the permanent;
FILTER = 1e-14 leaves a margin), otherwise recomputed with Python's Fraction,
which holds every double exactly. Two non-coplanar closed triangles meet iff an
edge of one meets the other (the ends of their common chord on the planes' line
lie on edges); coplanar ones likewise, tested in the plane. Candidate pairs come
from overlapping closed bounding boxes (numpy). The kinds are those of
src/crossings/crossing_count.hpp: free-free, free-fixed, self (same free body,
no shared vertex); fixed-fixed pairs are not counted. Triangles with collinear
corners are refused (the tests' meshes have none).
"""
from fractions import Fraction

import numpy as np

FILTER = 1e-14  # relative error bound under which a float orientation is recomputed exactly


def _sign(value):
    return int(value > 0) - int(value < 0)


def orient3d(a, b, c, d):
    """Sign of det[b - a, c - a, d - a] (exact)."""
    u = [b[i] - a[i] for i in range(3)]
    v = [c[i] - a[i] for i in range(3)]
    w = [d[i] - a[i] for i in range(3)]
    det = (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
           + u[2] * (v[0] * w[1] - v[1] * w[0]))
    permanent = (abs(u[0]) * (abs(v[1] * w[2]) + abs(v[2] * w[1]))
                 + abs(u[1]) * (abs(v[0] * w[2]) + abs(v[2] * w[0]))
                 + abs(u[2]) * (abs(v[0] * w[1]) + abs(v[1] * w[0])))
    if abs(det) > FILTER * permanent:
        return _sign(det)
    a, b, c, d = ([Fraction(x) for x in p] for p in (a, b, c, d))
    u = [b[i] - a[i] for i in range(3)]
    v = [c[i] - a[i] for i in range(3)]
    w = [d[i] - a[i] for i in range(3)]
    return _sign(u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
                 + u[2] * (v[0] * w[1] - v[1] * w[0]))


def orient2d(a, b, c):
    """Sign of det[b - a, c - a] in the plane (exact)."""
    det = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    permanent = abs((b[0] - a[0]) * (c[1] - a[1])) + abs((b[1] - a[1]) * (c[0] - a[0]))
    if abs(det) > FILTER * permanent:
        return _sign(det)
    a, b, c = ([Fraction(x) for x in p] for p in (a, b, c))
    return _sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _on_segment_2d(p, q, r):
    """r, collinear with p and q, lies on the closed segment pq."""
    return (min(p[0], q[0]) <= r[0] <= max(p[0], q[0])
            and min(p[1], q[1]) <= r[1] <= max(p[1], q[1]))


def segments_meet_2d(p, q, a, b):
    d1, d2 = orient2d(p, q, a), orient2d(p, q, b)
    d3, d4 = orient2d(a, b, p), orient2d(a, b, q)
    if d1 * d2 < 0 and d3 * d4 < 0:
        return True
    return ((d1 == 0 and _on_segment_2d(p, q, a)) or (d2 == 0 and _on_segment_2d(p, q, b))
            or (d3 == 0 and _on_segment_2d(a, b, p)) or (d4 == 0 and _on_segment_2d(a, b, q)))


def point_in_triangle_2d(p, a, b, c):
    signs = {orient2d(a, b, p), orient2d(b, c, p), orient2d(c, a, p)}
    return not (1 in signs and -1 in signs)


def _drop_axis(a, b, c):
    """The coordinate to drop when projecting the triangle's plane: the normal's largest."""
    normal = np.cross(np.subtract(b, a), np.subtract(c, a))
    return int(np.argmax(np.abs(normal)))


def segment_meets_triangle(p, q, a, b, c):
    """Closed segment pq against the closed, non-degenerate triangle abc."""
    s1, s2 = orient3d(a, b, c, p), orient3d(a, b, c, q)
    if s1 * s2 > 0:
        return False
    if s1 == 0 and s2 == 0:  # the segment lies in the triangle's plane
        drop = _drop_axis(a, b, c)
        keep = [i for i in range(3) if i != drop]
        p2, q2, a2, b2, c2 = ([pt[i] for i in keep] for pt in (p, q, a, b, c))
        return (point_in_triangle_2d(p2, a2, b2, c2) or point_in_triangle_2d(q2, a2, b2, c2)
                or any(segments_meet_2d(p2, q2, e, f) for e, f in ((a2, b2), (b2, c2), (c2, a2))))
    # The line pq crosses the plane within the segment: is the crossing inside abc?
    signs = {orient3d(p, q, a, b), orient3d(p, q, b, c), orient3d(p, q, c, a)}
    return not (1 in signs and -1 in signs)


def triangles_meet(s, t):
    """Closed triangles s and t (three points each) intersect."""
    s, t = ([tuple(float(x) for x in point) for point in triangle] for triangle in (s, t))
    for u, v in ((s, t), (t, s)):
        for i in range(3):
            if segment_meets_triangle(u[i], u[(i + 1) % 3], *v):
                return True
    return False


def _check_not_degenerate(points, triangles):
    for t in triangles:
        a, b, c = (tuple(points[v]) for v in t)
        n = np.cross(np.subtract(b, a), np.subtract(c, a))
        if not np.any(n):
            raise ValueError(f"triangle {tuple(t)} is degenerate (the reference refuses it)")


def candidate_pairs(points, triangles):
    """Pairs (i, j), i < j, of triangles whose closed bounding boxes overlap."""
    corners = points[triangles]  # [B][3][3]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    pairs = []
    chunk = 512
    for start in range(0, len(triangles), chunk):
        block = slice(start, start + chunk)
        overlap = np.all((lo[block, None, :] <= hi[None, :, :]) & (lo[None, :, :] <= hi[block, None, :]),
                         axis=2)
        rows, cols = np.nonzero(overlap)
        rows += start
        keep = rows < cols
        pairs.extend(zip(rows[keep].tolist(), cols[keep].tolist()))
    return pairs


def count_crossings(points, triangles, vertex_body, body_fixed, ground_y=None):
    """Counts of one frame: dict with free_free, free_fixed, self, below_ground.
    points [V][3], triangles [B][3] (vertex indices), vertex_body [V], body_fixed [bodies]."""
    points = np.asarray(points, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    _check_not_degenerate(points, triangles)
    body = np.asarray(vertex_body)[triangles[:, 0]]
    fixed = np.asarray(body_fixed)[body] != 0
    counts = {"free_free": 0, "free_fixed": 0, "self": 0, "below_ground": 0}
    for i, j in candidate_pairs(points, triangles):
        if fixed[i] and fixed[j]:
            continue
        same = body[i] == body[j]
        if same and set(triangles[i].tolist()) & set(triangles[j].tolist()):
            continue
        if not triangles_meet([tuple(points[v]) for v in triangles[i]],
                              [tuple(points[v]) for v in triangles[j]]):
            continue
        kind = "self" if same else ("free_fixed" if fixed[i] or fixed[j] else "free_free")
        counts[kind] += 1
    if ground_y is not None:
        free_vertices = np.unique(triangles[~fixed])
        counts["below_ground"] = int(np.sum(points[free_vertices, 1] < ground_y))
    return counts
