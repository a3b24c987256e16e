"""The closest point of a triangle to a point, compiled (numba): the kernels of
:func:`colourhs.common.raycast.closest_on_triangles` and
:func:`colourhs.common.raycast.closest_points`.

A module of its own so that importing :mod:`colourhs.common.raycast` (and so the
evaluation) does not import numba; the evaluation loads it on its first
distance query. Compiled, the float64 re-check over the triangles around
each point's first hit needs no NumPy arrays of candidates, and so runs in
less time than the vectorised form, numba's start included.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, inline="always")
def closest_on_triangle(p, a, b, c, out):
    """Closest point of triangle (a, b, c) to point p (3-vectors, float64),
    written to ``out``; returns its squared distance. NaN (``out`` and the
    distance) where an input is not finite. See
    :func:`colourhs.common.raycast.closest_on_triangles`."""
    out[0], out[1], out[2] = np.nan, np.nan, np.nan
    e0, e1, e2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    f0, f1, f2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    n0, n1, n2 = e1 * f2 - e2 * f1, e2 * f0 - e0 * f2, e0 * f1 - e1 * f0
    nn = n0 * n0 + n1 * n1 + n2 * n2
    best = np.inf
    if nn > 0:
        h = ((p[0] - a[0]) * n0 + (p[1] - a[1]) * n1 + (p[2] - a[2]) * n2) / nn
        q0, q1, q2 = p[0] - h * n0, p[1] - h * n1, p[2] - h * n2
        inside = True
        for s, e in ((a, b), (b, c), (c, a)):
            u0, u1, u2 = e[0] - s[0], e[1] - s[1], e[2] - s[2]
            w0, w1, w2 = q0 - s[0], q1 - s[1], q2 - s[2]
            x0, x1, x2 = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
            inside &= x0 * n0 + x1 * n1 + x2 * n2 >= 0
        if inside:
            d0, d1, d2 = p[0] - q0, p[1] - q1, p[2] - q2
            best = d0 * d0 + d1 * d1 + d2 * d2
            out[0], out[1], out[2] = q0, q1, q2
    for s, e in ((a, b), (b, c), (c, a)):
        u0, u1, u2 = e[0] - s[0], e[1] - s[1], e[2] - s[2]
        ll = u0 * u0 + u1 * u1 + u2 * u2
        t = ((p[0] - s[0]) * u0 + (p[1] - s[1]) * u1 + (p[2] - s[2]) * u2) / (ll if ll > 0 else 1.0)
        t = min(max(t, 0.0), 1.0)
        x0, x1, x2 = s[0] + t * u0, s[1] + t * u1, s[2] + t * u2
        d0, d1, d2 = p[0] - x0, p[1] - x1, p[2] - x2
        d2s = d0 * d0 + d1 * d1 + d2 * d2
        if d2s < best:
            best = d2s
            out[0], out[1], out[2] = x0, x1, x2
    return best if np.isfinite(out[0]) else np.nan


@nb.njit(cache=True)
def closest_each(p, a, b, c, out):
    """:func:`closest_on_triangle` of point i and triangle i, for every i, into ``out`` (N, 3)."""
    for i in range(len(p)):
        closest_on_triangle(p[i], a[i], b[i], c[i], out[i])


@nb.njit(cache=True)
def closest_near(p, v, tri, first, start, around, out, dist):
    """Per point: the closest point on the triangles around the corners of its
    ``first`` triangle (``around[start[k]:start[k + 1]]``: the triangles at
    vertex k, in increasing order), the first of the nearest on a tie; NaN
    where no candidate gives a finite distance or there is no first triangle."""
    x = np.empty(3)
    for i in range(len(p)):
        best = np.inf
        out[i, 0], out[i, 1], out[i, 2] = np.nan, np.nan, np.nan
        if not 0 <= first[i] < len(tri):  # no hit (open3d's invalid id: a point not finite)
            dist[i] = np.nan
            continue
        for corner in range(3):
            k = tri[first[i], corner]
            for j in range(start[k], start[k + 1]):
                t = around[j]
                d2 = closest_on_triangle(p[i], v[tri[t, 0]], v[tri[t, 1]], v[tri[t, 2]], x)
                d = np.sqrt(d2)
                if d < best:
                    best = d
                    out[i, 0], out[i, 1], out[i, 2] = x[0], x[1], x[2]
        dist[i] = best if best < np.inf else np.nan
