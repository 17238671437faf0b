"""Convex hulls with qhull's triangles merged back into planar faces.

qhull triangulates every facet; a face of a box comes back as two triangles. `planar_faces`
groups triangles whose outward normals agree, refits each group's plane through its exact
points, and orders each face's vertices counter-clockwise seen from outside.
"""

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
    """Merge the hull's coplanar triangles into faces."""
    normals = hull.equations[:, :3]
    groups: list[list[int]] = []
    group_normals: list[np.ndarray] = []
    for i, n in enumerate(normals):
        for group, gn in zip(groups, group_normals, strict=True):
            if 1.0 - float(gn @ n) < NORMAL_TOL:
                group.append(i)
                break
        else:
            groups.append([i])
            group_normals.append(n)
    faces = []
    for group in groups:
        ids = np.unique(hull.simplices[group].ravel())
        normal = normals[group].mean(axis=0)
        normal /= np.linalg.norm(normal)
        offset = float((points[ids] @ normal).max())
        faces.append(HullFace(normal, offset, _ccw(points, ids, normal)))
    return faces


def _ccw(points: np.ndarray, ids: np.ndarray, normal: np.ndarray) -> tuple[int, ...]:
    """Order the face's vertices counter-clockwise around ``normal``."""
    p = points[ids]
    centre = p.mean(axis=0)
    u = p[0] - centre if np.linalg.norm(p[0] - centre) > 0 else np.cross(normal, [1.0, 0, 0])
    u = u / np.linalg.norm(u)
    v = np.cross(normal, u)
    angles = np.arctan2((p - centre) @ v, (p - centre) @ u)
    return tuple(int(i) for i in ids[np.argsort(angles)])


def face_edges(rings: Iterable[tuple[int, ...]]) -> np.ndarray:
    """The edges of faces given as vertex rings, as sorted (E, 2) index pairs, each once."""
    edges = set()
    for ring in rings:
        for a, b in zip(ring, ring[1:] + ring[:1], strict=True):
            edges.add((min(a, b), max(a, b)))
    return np.array(sorted(edges), dtype=int).reshape(-1, 2)
