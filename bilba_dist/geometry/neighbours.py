"""Neighbouring faces: where a meshed curved surface is cut into pieces, the faces beside a
face.

A round hole in a meshed plate that CoACD split into convex objects has a face per piece
along its round wall (within a piece such facets are one face already, ``smooth_surfaces``).
A particle held a few millimetres off touches the piece beside the one a contact names; to
the planner that is still the contact sought (``NearContacts``): it says as much about where
the part is. The relation is local: a face's neighbours are the unnamed faces of other
pieces of the same part that touch it (two of its corners within ``TOUCH_M`` of the other
face) and whose normal turns by more than ``NAME_MATCH_ANGLE`` and at most ``SMOOTH_ANGLE``
from it. It is not carried on from neighbour to neighbour (a ring of walls is not one
contact: reaching it says nothing of where the part is); faces in one plane are not
neighbours (a flat surface cut in two is two places); and a face the task file names has
none (as in ``smooth_surfaces``: a named face is its own contact; on a hole of 32 named
wall pieces, counting the walls beside made the planner worse, docs/planner.md).
"""

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from bilba_dist.geometry.contact import FREE, ContactPair
from bilba_dist.geometry.piece import (
    NAME_MATCH_ANGLE,
    SMOOTH_ANGLE,
    UNNAMED,
    ConvexPiece,
    Face,
    Part,
)

#: Two faces touch when two corners of one lie within this of the other [m]: CoACD's pieces
#: meet along their cut planes to within a fraction of a millimetre.
TOUCH_M = 5e-4


def neighbouring_faces(part: Part) -> dict[str, frozenset[str]]:
    """Each face name of ``part`` that has neighbours (module docstring): those names."""
    facets = [
        (piece, face)
        for piece in part.pieces
        for face in piece.faces
        if UNNAMED.fullmatch(face.name.rpartition("/")[2])
    ]
    if not facets:
        return {}
    normals = np.array([face.normal for _, face in facets])
    cos = normals @ normals.T
    turned = (cos >= np.cos(SMOOTH_ANGLE)) & (cos < np.cos(NAME_MATCH_ANGLE))
    low = np.array([piece.vertices.min(axis=0) for piece, _ in facets]) - TOUCH_M
    high = np.array([piece.vertices.max(axis=0) for piece, _ in facets]) + TOUCH_M
    boxes_meet = np.all((low[:, None] <= high[None]) & (low[None] <= high[:, None]), axis=2)
    near: dict[str, set[str]] = {}
    for a, b in zip(*np.nonzero(np.triu(turned & boxes_meet, 1)), strict=True):
        (piece_a, face_a), (piece_b, face_b) = facets[a], facets[b]
        if piece_a is piece_b:  # (a face's name holds its piece's)
            continue
        if _touch(piece_a, face_a, piece_b, face_b) or _touch(piece_b, face_b, piece_a, face_a):
            near.setdefault(face_a.name, set()).add(face_b.name)
            near.setdefault(face_b.name, set()).add(face_a.name)
    return {name: frozenset(others) for name, others in near.items()}


def _touch(piece_a: ConvexPiece, face_a: Face, piece_b: ConvexPiece, face_b: Face) -> bool:
    """Whether two corners of ``face_a`` lie within ``TOUCH_M`` of the polygon ``face_b``."""
    corners = piece_a.vertices[list(face_a.vertices)]
    return int(np.count_nonzero(_distance(corners, piece_b, face_b) <= TOUCH_M)) >= 2


def _distance(points: np.ndarray, piece: ConvexPiece, face: Face) -> np.ndarray:
    """Each point's distance from the convex polygon ``face``: its height over the plane
    where it lies over the polygon, else its distance from the nearest edge."""
    ring = piece.vertices[list(face.vertices)]
    edges = np.roll(ring, -1, axis=0) - ring
    inward = np.cross(face.normal, edges)
    offset = points[:, None] - ring[None]  # (point, edge start, xyz)
    over = np.all(np.einsum("ek,pek->pe", inward, offset) >= 0, axis=1)
    along = np.einsum("ek,pek->pe", edges, offset) / np.einsum("ek,ek->e", edges, edges)
    nearest = ring[None] + np.clip(along, 0, 1)[..., None] * edges[None]
    to_edge = np.linalg.norm(points[:, None] - nearest, axis=2).min(axis=1)
    return np.where(over, np.abs(points @ face.normal - face.offset), to_edge)


def _same_surface(near: Mapping[str, frozenset[str]], face: str) -> frozenset[str]:
    """``face`` and its neighbours."""
    return frozenset([face]) | near.get(face, frozenset())


@dataclass(frozen=True)
class NearContacts:
    """The contacts the planner counts as a contact sought: the pairs of its faces'
    neighbours (either side's), except for the goal, which is the pair the task names."""

    env: Mapping[str, frozenset[str]] = field(default_factory=dict)
    manip: Mapping[str, frozenset[str]] = field(default_factory=dict)
    goal: ContactPair = FREE

    @classmethod
    def of(cls, environment: Part, manipuland: Part, goal: ContactPair) -> "NearContacts":
        return cls(neighbouring_faces(environment), neighbouring_faces(manipuland), goal)

    def around(self, mode: ContactPair) -> frozenset[ContactPair]:
        """``mode`` and the pairs of its faces' neighbours."""
        if mode in (self.goal, FREE):
            return frozenset([mode])
        return frozenset(
            ContactPair(env, manip)
            for env in _same_surface(self.env, mode.env)
            for manip in _same_surface(self.manip, mode.manip)
        )

    def accept(self, modes: Iterable[ContactPair]) -> frozenset[ContactPair]:
        """The contact sets that count as in one of ``modes``: those holding one of these."""
        return frozenset().union(*(self.around(m) for m in modes))
