"""Convex hulls with qhull's triangles merged back into planar faces.

qhull triangulates every facet; a face of a box comes back as two triangles. `planar_faces`
groups triangles whose outward normals agree, refits each group's plane through its exact
points, and orders each face's vertices counter-clockwise seen from outside.
"""

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from bilba_dist.errors import GeometryError, first_line

#: Two unit normals closer than this (1 - cos angle) belong to one face.
NORMAL_TOL = 1e-9


@dataclass(frozen=True)
class HullFace:
    """One planar face of a convex hull: ``normal · x = offset`` on it, ``<`` inside."""

    normal: np.ndarray
    offset: float
    vertices: tuple[int, ...]  # indices into the input points, counter-clockwise from outside


def convex_hull(points: np.ndarray, what: str) -> ConvexHull:
    """qhull's hull of ``points`` (N, 3); a flat or degenerate set is a GeometryError."""
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 4:
        raise GeometryError(f"{what}: needs at least 4 points in 3-D, got shape {points.shape}")
    try:
        hull = ConvexHull(points)
    except QhullError as exc:
        reason = first_line(exc, "qhull failed")
        raise GeometryError(f"{what}: degenerate (flat or repeated points): {reason}") from None
    scale = float(np.ptp(points, axis=0).max())
    if hull.volume <= 1e-12 * scale**3:
        raise GeometryError(f"{what}: degenerate, its volume is {hull.volume:.3g} m^3")
    return hull


def planar_faces(points: np.ndarray, hull: ConvexHull) -> list[HullFace]:
    """Merge the hull's coplanar triangles into faces, in the order of each face's first
    triangle, each face's vertices counter-clockwise seen from outside. (Vectorised where
    the arithmetic allows: the planner builds a C-obs slice per particle per contact, and
    this was most of a slice's time. The dot products stay one BLAS call per face, as
    summing the products in numpy rounds differently, and a rounding changes which
    vertex a symmetric face's ring starts at.)"""
    normals = hull.equations[:, :3]
    close = normals @ normals.T > 1.0 - NORMAL_TOL
    first = close.argmax(axis=1)  # the first triangle facing the same way (at worst itself)
    first = first[first]  # a chain of near-equal normals joins its first's face
    leaders, face_of = np.unique(first, return_inverse=True)
    means = _mean_by(normals, face_of, len(leaders))
    member = np.zeros((len(leaders), len(points)), dtype=bool)
    member[face_of[:, None], hull.simplices] = True  # the points each face's triangles use
    face_of_point, ids = np.nonzero(member)  # face by face, each face's points ascending
    counts = np.bincount(face_of_point, minlength=len(leaders))
    starts = np.cumsum(counts) - counts
    p = points[ids]
    d = p - _mean_by(p, face_of_point, len(leaders))[face_of_point]  # from each face's centre
    cos, sin = np.empty(len(p)), np.empty(len(p))
    planes = []
    for k, mean in enumerate(means):
        rows = slice(starts[k], starts[k] + counts[k])
        normal = mean / math.sqrt(mean @ mean)
        planes.append((normal, float((p[rows] @ normal).max())))
        u = d[starts[k]] if d[starts[k]] @ d[starts[k]] > 0 else _cross(normal, _X)
        u = u / math.sqrt(u @ u)
        cos[rows], sin[rows] = d[rows] @ u, d[rows] @ _cross(normal, u)
    ring = ids[np.lexsort((np.arctan2(sin, cos), face_of_point))]
    return [
        HullFace(normal, offset, tuple(ring[start : start + count].tolist()))
        for (normal, offset), start, count in zip(planes, starts, counts, strict=True)
    ]


_X = np.array([1.0, 0.0, 0.0])


def _mean_by(values: np.ndarray, groups: np.ndarray, n: int) -> np.ndarray:
    """Per group 0..n-1, the mean of its rows of ``values``: rows added in order, then
    divided by their count — the arithmetic of ``values[rows].mean(axis=0)``, to the bit
    (np.add.reduceat adds in another order)."""
    order = np.argsort(groups, kind="stable")
    counts = np.bincount(groups, minlength=n)
    rank = np.arange(len(order)) - np.repeat(np.cumsum(counts) - counts, counts)
    sums = np.zeros((n, values.shape[1]))
    for r in range(int(rank.max()) + 1 if len(rank) else 0):
        rows = order[rank == r]  # at most one row per group
        sums[groups[rows]] += values[rows]
    return sums / counts[:, None]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a × b`` for two 3-vectors, without np.cross's per-call set-up (~20 µs)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def face_edges(rings: Iterable[Sequence[int]]) -> np.ndarray:
    """The edges of faces given as vertex rings, as sorted (E, 2) index pairs, each once."""
    pairs = np.array(
        [(a, b) for ring in rings for a, b in zip(ring, [*ring[1:], ring[0]], strict=True)],
        dtype=int,
    ).reshape(-1, 2)
    if not len(pairs):
        return pairs
    low, high = pairs.min(axis=1), pairs.max(axis=1)
    span = int(high.max()) + 1
    codes = np.unique(low * span + high)  # sorted by (low, high), each once
    return np.column_stack([codes // span, codes % span])
