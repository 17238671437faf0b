"""The C-obstacle slice ``C_obs(R)``: the union of every piece pair's Minkowski polytope.

Positions are the manipuland frame's origin in the environment frame O [m], with the
manipuland's rotation fixed at ``R_OM``. Inside: the parts overlap; on the boundary: they
touch, with the contact set given by the labels of the facets there.
"""

from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from bilba_dist.cspace.boundary import FacetStack, boundary_vertices
from bilba_dist.cspace.polytope import TOL, Polytope, minkowski_polytope
from bilba_dist.geometry.contact import ContactPair, ContactSet
from bilba_dist.geometry.piece import Part

INSIDE, BOUNDARY, OUTSIDE = -1, 0, 1

#: How far from a boundary vertex the probes of its modes' regions lie [m]: far above TOL,
#: far below the smallest clearance of the built-in tasks (0.25 mm).
PROBE_M = 1e-5
#: Probe directions in each facet's plane: 12, each 15° off the plane's axes, so that on the
#: mostly axis-aligned faces of these parts no probe runs along an edge of a region.
PROBE_ANGLES = (np.arange(12) + 0.5) * np.pi / 6


@dataclass(frozen=True)
class CObsSlice:
    """The slice at rotation ``R_OM``, with its boundary vertices and their contact sets."""

    R_OM: np.ndarray
    polytopes: tuple[Polytope, ...]
    stack: FacetStack = field(repr=False)

    @classmethod
    def build(cls, environment: Part, manipuland: Part, R_OM: np.ndarray) -> "CObsSlice":
        R_OM = np.asarray(R_OM, dtype=float)
        polytopes = [
            minkowski_polytope(e, m, R_OM) for e in environment.pieces for m in manipuland.pieces
        ]
        return cls.of(R_OM, polytopes)

    @classmethod
    def of(cls, R_OM: np.ndarray, polytopes: Iterable[Polytope]) -> "CObsSlice":
        """The union of ``polytopes`` (all at rotation ``R_OM``)."""
        polytopes = tuple(polytopes)
        return cls(R_OM, polytopes, FacetStack(list(polytopes)))

    @cached_property
    def vertices(self) -> np.ndarray:
        """(V, 3) boundary vertices of the union, sorted lexicographically."""
        return boundary_vertices(list(self.polytopes), self.stack)

    @cached_property
    def vertex_contacts(self) -> tuple[ContactSet, ...]:
        """The contact set of each boundary vertex."""
        return self.contacts(self.vertices)

    @cached_property
    def vertex_modes(self) -> tuple[ContactSet, ...]:
        """Per boundary vertex, the modes of its contact set whose region has area next to it.

        A mode can touch a vertex along a line or at a point only, where two faces meet edge
        to edge: the puzzle's goal pair (neck on the frame's inner bar face) "occurs" at the
        frame's outer corners that way, and an edge through such a vertex would be a contact
        transition no motion can make. Each mode is kept only if a probe ``PROBE_M`` from the
        vertex, in the plane of a facet through it, lies on that mode's region."""
        V = self.vertices
        if len(V) == 0:
            return ()
        vertex, f = np.nonzero(self._on_facets(V)[1])
        e1, e2 = _plane_axes(self.stack.A[f])
        directions = np.cos(PROBE_ANGLES)[None, :, None] * e1[:, None, :]
        directions += np.sin(PROBE_ANGLES)[None, :, None] * e2[:, None, :]
        probes = V[vertex][:, None, :] + PROBE_M * directions
        nearby: list[set[ContactPair]] = [set() for _ in V]
        owner = np.repeat(vertex, len(PROBE_ANGLES))
        for k, contacts in zip(owner, self.contacts(probes.reshape(-1, 3)), strict=True):
            nearby[k] |= contacts
        return tuple(frozenset(c & n) for c, n in zip(self.vertex_contacts, nearby, strict=True))

    @cached_property
    def _facet_labels(self) -> tuple[ContactSet, ...]:
        return tuple(label for p in self.polytopes for label in p.labels)

    def classify(self, points: np.ndarray) -> np.ndarray:
        """INSIDE (-1), BOUNDARY (0) or OUTSIDE (1) per point, within 1e-9 m."""
        slack = self.stack.slack(np.atleast_2d(points)).min(axis=1)
        return np.where(slack < -TOL, INSIDE, np.where(slack <= TOL, BOUNDARY, OUTSIDE))

    def contacts(self, points: np.ndarray) -> tuple[ContactSet, ...]:
        """The contact set at each point: the labels of every facet it lies on, of every
        polytope it is on the boundary of; empty for points not on the slice's boundary."""
        points = np.atleast_2d(points)
        on_union, on_facet = self._on_facets(points)
        result: list[ContactSet] = []
        for i in range(len(points)):
            if not on_union[i]:
                result.append(frozenset())
                continue
            labels: set[ContactPair] = set()
            for f in np.flatnonzero(on_facet[i]):
                labels |= self._facet_labels[f]
            result.append(frozenset(labels))
        return tuple(result)

    def in_mode(self, points: np.ndarray, mode: ContactPair) -> np.ndarray:
        """Whether each point lies on the boundary region of ``mode``."""
        labelled = np.array([mode in label for label in self._facet_labels], dtype=bool)
        on_union, on_facet = self._on_facets(np.atleast_2d(points))
        return on_union & on_facet[:, labelled].any(axis=1)

    def _on_facets(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per point, whether it is on the union's boundary or outside it (N,), and which
        facets it lies on, each on its own polytope's surface (N, F); within TOL."""
        facet = self.stack.facet_slack(points)
        per_polytope = np.maximum.reduceat(facet, self.stack.starts, axis=1)
        on_union = per_polytope.min(axis=1) >= -TOL
        on_facet = (np.abs(facet) <= TOL) & (np.abs(per_polytope[:, self.stack.owner]) <= TOL)
        return on_union, on_facet

    def mode_facets(self, mode: ContactPair) -> list[tuple[int, int]]:
        """(polytope, facet) indices of every facet labelled with ``mode``."""
        return [
            (i, f)
            for i, p in enumerate(self.polytopes)
            for f, label in enumerate(p.labels)
            if mode in label
        ]

    def sample_mode(
        self,
        mode: ContactPair,
        n: int,
        rng: np.random.Generator,
        depth: float | tuple[float, float] = 0.0,
    ) -> np.ndarray:
        """Up to ``n`` points on the boundary region of ``mode`` (area-weighted over its
        facets, rejecting points covered by another polytope); with ``depth`` > 0 each point
        is then pushed that far inside, against its facet's normal [m] (a pair: a depth
        uniform in that range, per point)."""
        facets = self.mode_facets(mode)
        if not facets:
            return np.zeros((0, 3))
        triangles, normals = _fan(self.polytopes, facets)
        areas = 0.5 * np.linalg.norm(
            np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1
        )
        found: list[np.ndarray] = []
        for _ in range(8):
            pick = rng.choice(len(triangles), size=4 * n, p=areas / areas.sum())
            points = _in_triangles(triangles[pick], rng)
            on = self.in_mode(points, mode)
            d = rng.uniform(*depth, size=(int(on.sum()), 1)) if isinstance(depth, tuple) else depth
            found.append(points[on] - d * normals[pick][on])
            if sum(len(f) for f in found) >= n:
                break
        return np.concatenate(found)[:n]

    def mode_vertices(self, mode: ContactPair) -> np.ndarray:
        """The boundary vertices at the edge of ``mode``'s region (see ``vertex_modes``)."""
        mask = np.array([mode in c for c in self.vertex_modes], dtype=bool)
        return self.vertices[mask] if len(mask) else np.zeros((0, 3))


def _plane_axes(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane of each unit normal: e1 = n × (the axis least
    along n), e2 = n × e1."""
    axis = np.eye(3)[np.argmin(np.abs(normals), axis=1)]
    e1 = np.cross(normals, axis)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(normals, e1)


def _fan(
    polytopes: Iterable[Polytope], facets: list[tuple[int, int]]
) -> tuple[np.ndarray, np.ndarray]:
    polytopes = list(polytopes)
    triangles, normals = [], []
    for i, f in facets:
        ring = polytopes[i].polygons[f]
        for k in range(1, len(ring) - 1):
            triangles.append([ring[0], ring[k], ring[k + 1]])
            normals.append(polytopes[i].A[f])
    return np.array(triangles), np.array(normals)


def _in_triangles(triangles: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    u, v = rng.uniform(size=(2, len(triangles)))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    return a + u[:, None] * (b - a) + v[:, None] * (c - a)
