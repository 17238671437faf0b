"""Convex hulls with qhull's triangles merged back into planar faces.

qhull triangulates every facet; a face of a box comes back as two triangles. `planar_faces`
groups triangles whose outward normals agree, refits each group's plane through its exact
points, and orders each face's vertices counter-clockwise seen from outside.
"""

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from bilba_dist.errors import GeometryError

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
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else "qhull failed"
        raise GeometryError(f"{what}: degenerate (flat or repeated points): {reason}") from None
    scale = float(np.ptp(points, axis=0).max())
    if hull.volume <= 1e-12 * scale**3:
        raise GeometryError(f"{what}: degenerate, its volume is {hull.volume:.3g} m^3")
    return hull


def planar_faces(points: np.ndarray, hull: ConvexHull) -> list[HullFace]:
    """Merge the hull's coplanar triangles into faces, in the order of each face's first
    triangle. (Vectorised: the planner builds a C-obs slice per particle per contact, and
    this was most of a slice's time.)"""
    normals = hull.equations[:, :3]
    close = normals @ normals.T > 1.0 - NORMAL_TOL
    first = close.argmax(axis=1)  # the first triangle facing the same way (at worst itself)
    first = first[first]  # a chain of near-equal normals joins its first's face
    faces = []
    for leader in np.unique(first):
        group = np.flatnonzero(first == leader)
        ids = np.unique(hull.simplices[group])
        normal = normals[group].mean(axis=0)
        normal /= math.sqrt(normal @ normal)
        offset = float((points[ids] @ normal).max())
        faces.append(HullFace(normal, offset, _ccw(points, ids, normal)))
    return faces


def _ccw(points: np.ndarray, ids: np.ndarray, normal: np.ndarray) -> tuple[int, ...]:
    """Order the face's vertices counter-clockwise around ``normal``."""
    p = points[ids]
    d = p - p.mean(axis=0)
    u = d[0] if d[0] @ d[0] > 0 else _cross(normal, np.array([1.0, 0.0, 0.0]))
    u = u / math.sqrt(u @ u)
    angles = np.arctan2(d @ _cross(normal, u), d @ u)
    return tuple(ids[np.argsort(angles)].tolist())


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a × b`` for two 3-vectors, without np.cross's per-call set-up (~20 µs)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def face_edges(rings: Iterable[tuple[int, ...]]) -> np.ndarray:
    """The edges of faces given as vertex rings, as sorted (E, 2) index pairs, each once."""
    edges = set()
    for ring in rings:
        for a, b in zip(ring, ring[1:] + ring[:1], strict=True):
            edges.add((min(a, b), max(a, b)))
    return np.array(sorted(edges), dtype=int).reshape(-1, 2)
