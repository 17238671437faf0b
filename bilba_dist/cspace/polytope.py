"""One piece pair's C-obstacle at a fixed rotation: the Minkowski difference ``E ⊕ (−R·M)``.

Positions are of the manipuland frame in the environment frame O [m]. The manipuland with
rotation R at position p overlaps the environment piece E exactly when p lies inside.
Each facet is labelled with the contact pairs of the features that touch there: every face
of E holding E's supporting feature, times every face of M holding M's supporting feature
(a corner or edge names every face that meets there).
"""

from dataclasses import dataclass
from functools import lru_cache
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
    remap = np.full(len(points), -1)
    remap[keep] = np.arange(len(keep))
    A = np.array([f.normal for f in faces])
    b = np.array([f.offset for f in faces])
    edges = face_edges(remap[list(f.vertices)].tolist() for f in faces)
    return Polytope(
        env_piece=env.name,
        manip_piece=manip.name,
        A=A,
        b=b,
        labels=_facet_labels(env, manip, E, M, A),
        polygons=tuple(points[list(f.vertices)] for f in faces),
        vertices=points[keep],
        edges=edges,
        lower=points[keep].min(axis=0),
        upper=points[keep].max(axis=0),
    )


def _facet_labels(
    env: ConvexPiece, manip: ConvexPiece, E: np.ndarray, M: np.ndarray, A: np.ndarray
) -> tuple[ContactSet, ...]:
    """Per facet normal (rows of ``A``): every face of E holding E's supporting feature
    times every face of M holding M's."""
    env_faces = _faces_holding(env, E @ A.T)
    manip_faces = _faces_holding(manip, -(M @ A.T))
    return tuple(map(_label, env_faces, manip_faces))


def _faces_holding(piece: ConvexPiece, heights: np.ndarray) -> list[tuple[str, ...]]:
    """Per column of ``heights`` (vertex × direction), the piece's faces that hold its
    supporting feature: every vertex within TOL of the highest."""
    support = heights >= heights.max(axis=0) - TOL
    faces = piece.face_vertex_sets
    return [_holding(faces, key) for key in map(bytes, np.packbits(support, axis=0).T)]


# A slice has ~30 facets per piece pair and a plan builds hundreds of slices, but the
# features that support them, and so the labels, come from a short list: cached.
@lru_cache(maxsize=16384)
def _holding(faces: tuple[tuple[str, frozenset[int]], ...], support: bytes) -> tuple[str, ...]:
    """The faces holding every vertex whose bit is set in ``support`` (np.packbits)."""
    ids = set(np.flatnonzero(np.unpackbits(np.frombuffer(support, dtype=np.uint8))).tolist())
    return tuple(name for name, holds in faces if ids <= holds)


@lru_cache(maxsize=16384)
def _label(env_faces: tuple[str, ...], manip_faces: tuple[str, ...]) -> ContactSet:
    return frozenset(ContactPair(e, m) for e, m in product(env_faces, manip_faces))


def slack(polytope: Polytope, points: np.ndarray) -> np.ndarray:
    """``max_f (A_f x - b_f)`` per point: < 0 inside, 0 on the boundary, > 0 outside [m]."""
    return (np.atleast_2d(points) @ polytope.A.T - polytope.b).max(axis=1)
