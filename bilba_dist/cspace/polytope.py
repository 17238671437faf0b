"""One piece pair's C-obstacle at a fixed rotation: the Minkowski difference ``E ⊕ (−R·M)``.

Positions are of the manipuland frame in the environment frame O [m]. The manipuland with
rotation R at position p overlaps the environment piece E exactly when p lies inside.
Each facet is labelled with the contact pairs of the features that touch there: every face
of E holding E's supporting feature, times every face of M holding M's supporting feature
(a corner or edge names every face that meets there).
"""

from dataclasses import dataclass
from itertools import product

import numpy as np

from bilba_dist.geometry.contact import ContactPair, ContactSet
from bilba_dist.geometry.hull import convex_hull, face_edges, planar_faces
from bilba_dist.geometry.piece import ConvexPiece

#: Length tolerance for "on a plane" and "the same point" [m]. The smallest clearance in the
#: built-in tasks is 0.25 mm, so 1e-9 m never merges features that differ physically.
TOL = 1e-9


@dataclass(frozen=True)
class Polytope:
    """``A x <= b`` with labelled facets; vertices and edges for boundary enumeration."""

    env_piece: str
    manip_piece: str
    A: np.ndarray  # (F, 3) outward unit normals
    b: np.ndarray  # (F,)
    labels: tuple[ContactSet, ...]  # per facet
    polygons: tuple[np.ndarray, ...]  # per facet: (k, 3) corners, counter-clockwise
    vertices: np.ndarray  # (V, 3)
    edges: np.ndarray  # (E, 2) indices into vertices
    lower: np.ndarray  # axis-aligned bounds
    upper: np.ndarray


def minkowski_polytope(env: ConvexPiece, manip: ConvexPiece, R_OM: np.ndarray) -> Polytope:
    """The C-obstacle of ``manip`` (rotated by ``R_OM``) against ``env``, both in O."""
    E = env.vertices
    M = manip.vertices @ R_OM.T
    points = (E[:, None, :] - M[None, :, :]).reshape(-1, 3)
    hull = convex_hull(points, f"C-obs of {env.name}/{manip.name}")
    faces = planar_faces(points, hull)
    keep = np.array(sorted(hull.vertices))
    remap = {int(old): new for new, old in enumerate(keep)}
    A = np.array([f.normal for f in faces])
    b = np.array([f.offset for f in faces])
    labels = tuple(_facet_labels(env, manip, E, M, n) for n in A)
    edges = face_edges(tuple(remap[i] for i in f.vertices) for f in faces)
    return Polytope(
        env_piece=env.name,
        manip_piece=manip.name,
        A=A,
        b=b,
        labels=labels,
        polygons=tuple(points[list(f.vertices)] for f in faces),
        vertices=points[keep],
        edges=edges,
        lower=points[keep].min(axis=0),
        upper=points[keep].max(axis=0),
    )


def _facet_labels(
    env: ConvexPiece, manip: ConvexPiece, E: np.ndarray, M: np.ndarray, normal: np.ndarray
) -> ContactSet:
    env_support = _support(E @ normal)
    manip_support = _support(-(M @ normal))
    env_faces = _faces_holding(env, env_support)
    manip_faces = _faces_holding(manip, manip_support)
    return frozenset(ContactPair(e, m) for e, m in product(env_faces, manip_faces))


def _support(heights: np.ndarray) -> set[int]:
    return set(np.flatnonzero(heights >= heights.max() - TOL).tolist())


def _faces_holding(piece: ConvexPiece, vertex_ids: set[int]) -> list[str]:
    return [f.name for f in piece.faces if vertex_ids <= set(f.vertices)]


def slack(polytope: Polytope, points: np.ndarray) -> np.ndarray:
    """``max_f (A_f x - b_f)`` per point: < 0 inside, 0 on the boundary, > 0 outside [m]."""
    return (np.atleast_2d(points) @ polytope.A.T - polytope.b).max(axis=1)
