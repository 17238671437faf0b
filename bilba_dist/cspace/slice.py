"""The C-obstacle slice ``C_obs(R)``: the union of every piece pair's Minkowski polytope.

Positions are the manipuland frame's origin in the environment frame O [m], with the
manipuland's rotation fixed at ``R_OM``. Inside: the parts overlap; on the boundary: they
touch, with the contact set given by the labels of the facets there.
"""

from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import shapely

from bilba_dist.cspace.boundary import (
    BOX_MARGIN,
    CHUNK_POINTS,
    FacetStack,
    boundary_vertices,
)
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
    #: Per mode, its region as triangles with their facet normals (see ``mode_triangles``).
    _regions: dict[ContactPair, tuple[np.ndarray, np.ndarray]] = field(
        default_factory=dict, repr=False, compare=False
    )
    #: Per (polytope, facet), its region (``_facet_region``): a facet with several labels
    #: is the region of each of their modes
    _facet_regions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = field(
        default_factory=dict, repr=False, compare=False
    )
    #: Per set of facets, the union of their labels (``_labels_of``)
    _label_sets: dict[tuple[int, ...], ContactSet] = field(
        default_factory=dict, repr=False, compare=False
    )

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
        _, vertex, f = self._facet_hits(V)
        e1, e2 = plane_axes(self.stack.A[f])
        directions = np.cos(PROBE_ANGLES)[None, :, None] * e1[:, None, :]
        directions += np.sin(PROBE_ANGLES)[None, :, None] * e2[:, None, :]
        probes = V[vertex][:, None, :] + PROBE_M * directions
        nearby: list[set[ContactPair]] = [set() for _ in V]
        owner = np.repeat(vertex, len(PROBE_ANGLES))
        # A probe is PROBE_M from its vertex, so only the polytopes that vertex is within
        # PROBE_M of (facet normals are unit) can hold it or have it on a facet
        near = self.stack.slack(V) <= PROBE_M + BOX_MARGIN
        for k, contacts in zip(
            owner, self._contacts(probes.reshape(-1, 3), near[owner]), strict=True
        ):
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
        return self._contacts(np.atleast_2d(points))

    def _contacts(
        self, points: np.ndarray, near: np.ndarray | None = None
    ) -> tuple[ContactSet, ...]:
        """``contacts``, measuring each point only against the polytopes ``near`` (N, P)
        allows, when given (`_facet_hits`)."""
        result: list[ContactSet] = []
        for start in range(0, len(points), CHUNK_POINTS):  # bounded memory
            chunk_near = None if near is None else near[start : start + CHUNK_POINTS]
            on_union, rows, facets = self._facet_hits(
                points[start : start + CHUNK_POINTS], chunk_near
            )
            chunk: list[ContactSet] = [frozenset()] * len(on_union)
            keep = on_union[rows]
            rows, facets = rows[keep], facets[keep]
            if len(rows):  # the facets of each point, grouped: point rows[a] has facets[a:b]
                ends = [*(np.flatnonzero(np.diff(rows)) + 1).tolist(), len(rows)]
                starts, listed = [0, *ends[:-1]], facets.tolist()
                for row, a, b in zip(rows[starts].tolist(), starts, ends, strict=True):
                    chunk[row] = self._labels_of(tuple(listed[a:b]))
            result += chunk
        return tuple(result)

    def _labels_of(self, facets: tuple[int, ...]) -> ContactSet:
        """The union of ``facets``' labels, once per set of facets (the boundary's points
        lie on a few hundred such sets: a vertex's probes share their facets)."""
        labels = self._label_sets.get(facets)
        if labels is None:
            labels = frozenset().union(*(self._facet_labels[f] for f in facets))
            self._label_sets[facets] = labels
        return labels

    def in_mode(self, points: np.ndarray, mode: ContactPair) -> np.ndarray:
        """Whether each point lies on the boundary region of ``mode``."""
        labelled = np.array([mode in label for label in self._facet_labels], dtype=bool)
        on_union, rows, facets = self._facet_hits(np.atleast_2d(points))
        on_mode = np.zeros(len(on_union), dtype=bool)
        on_mode[rows[labelled[facets]]] = True
        return on_union & on_mode

    def _facet_hits(
        self, points: np.ndarray, near: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per point, whether it is on the union's boundary or outside it (N,), and the
        facets it lies on, each on its own polytope's surface, within TOL, as (point, facet)
        index pairs sorted by point and then facet (a point lies on a few of thousands).
        Only the points in a polytope's box are measured against its facets
        (`FacetStack.in_box`: a part split into tens of pieces has thousands of facets, and
        each point is near a few pieces). ``near`` (N, P), when given, rules out more: a
        point is measured against polytope k only where ``near[:, k]``, which must hold
        wherever the point may be inside it or on its surface."""
        inside = np.zeros(len(points), dtype=bool)  # strictly inside some polytope
        rows, facets = [np.zeros(0, dtype=np.intp)], [np.zeros(0, dtype=np.intp)]
        for k, (p, start) in enumerate(zip(self.polytopes, self.stack.starts, strict=True)):
            measured = np.arange(len(points)) if near is None else np.flatnonzero(near[:, k])
            measured = measured[self.stack.in_box(points[measured], k)]
            if len(measured) == 0:
                continue
            facet = points[measured] @ p.A.T - p.b
            per_polytope = facet.max(axis=1)
            inside[measured] |= per_polytope < -TOL
            r, f = np.nonzero((np.abs(facet) <= TOL) & (np.abs(per_polytope) <= TOL)[:, None])
            rows.append(measured[r])
            facets.append(start + f)
        row, facet = np.concatenate(rows), np.concatenate(facets)
        order = np.lexsort((facet, row))
        return ~inside, row[order], facet[order]

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
        """Up to ``n`` points uniform on the boundary region of ``mode`` (``mode_triangles``,
        area-weighted); with ``depth`` > 0 each point is then pushed that far inside, against
        its facet's normal [m] (a pair: a depth uniform in that range, per point)."""
        triangles, normals = self.mode_triangles(mode)
        if len(triangles) == 0:
            return np.zeros((0, 3))
        areas = 0.5 * np.linalg.norm(
            np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1
        )
        pick = rng.choice(len(triangles), size=n, p=areas / areas.sum())
        points = _in_triangles(triangles[pick], rng)
        on = self.in_mode(points, mode)  # all but rounding at the region's edges
        d = rng.uniform(*depth, size=(int(on.sum()), 1)) if isinstance(depth, tuple) else depth
        return points[on] - d * normals[pick][on]

    def mode_triangles(self, mode: ContactPair) -> tuple[np.ndarray, np.ndarray]:
        """``mode``'s boundary region as (T, 3, 3) triangles and their facet normals (T, 3):
        each facet labelled with it, less the interiors of the other polytopes, cut in the
        facet's plane (Shapely) and triangulated. A region can be a sliver of its facet —
        the puzzle's goal is 0.5 × 1 mm of a 160 × 42 mm facet — so points are drawn in the
        region itself, not in the facet and then rejected."""
        if mode not in self._regions:
            found = [self._facet_region(i, f) for i, f in self.mode_facets(mode)]
            triangles = [t for t, _ in found if len(t)]
            normals = [m for t, m in found if len(t)]
            self._regions[mode] = (
                (np.concatenate(triangles), np.concatenate(normals))
                if triangles
                else (np.zeros((0, 3, 3)), np.zeros((0, 3)))
            )
        return self._regions[mode]

    def _facet_region(self, i: int, f: int) -> tuple[np.ndarray, np.ndarray]:
        if (i, f) not in self._facet_regions:
            self._facet_regions[i, f] = _facet_region(self.polytopes, i, f, self.stack)
        return self._facet_regions[i, f]

    def mode_vertices(self, mode: ContactPair) -> np.ndarray:
        """The boundary vertices at the edge of ``mode``'s region (see ``vertex_modes``)."""
        mask = np.array([mode in c for c in self.vertex_modes], dtype=bool)
        return self.vertices[mask] if len(mask) else np.zeros((0, 3))


def plane_axes(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane of each unit normal: e1 = n × (the axis least
    along n), e2 = n × e1."""
    axis = np.eye(3)[np.argmin(np.abs(normals), axis=1)]
    e1 = np.cross(normals, axis)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(normals, e1)


#: How far beyond a plane of another polytope (past its interior shrunk by TOL) every corner
#: of a facet must lie for that polytope to be passed over without `_clip` [m]: far above
#: the rounding of the two ways of measuring it, so the polytopes `_clip` would have found
#: apart are all that is passed over.
CLEAR_M = 1e-12


def _facet_region(
    polytopes: tuple[Polytope, ...], i: int, f: int, stack: FacetStack
) -> tuple[np.ndarray, np.ndarray]:
    """Facet ``f`` of polytope ``i`` less every other polytope's interior (slack below
    −TOL, as ``classify`` has it), as triangles in 3-D and their normals. ``stack``: the
    polytopes' facets and boxes, to pass over at once those whose box misses the facet's or
    that have a plane the whole facet lies beyond (most of tens of pieces)."""
    polytope = polytopes[i]
    ring, normal = polytope.polygons[f], polytope.A[f]
    e1, e2 = plane_axes(normal[None, :])
    axes = np.vstack([e1, e2])  # (2, 3): plane coordinates w ↦ origin + w @ axes
    # On the facet's plane itself: the hull's corners of a facet merged from nearly coplanar
    # ones lie up to ~1e-8 m off it, and points drawn there would not count as on it.
    origin = ring[0] - (normal @ ring[0] - polytope.b[f]) * normal
    # ... and projected, such a ring can fold by a nanometre: its convex hull is the facet.
    hull = shapely.convex_hull(shapely.MultiPoint((ring - origin) @ axes.T))
    if not isinstance(hull, shapely.Polygon):
        return np.zeros((0, 3, 3)), np.zeros((0, 3))
    face = np.asarray(hull.exterior.coords)[:-1]
    lower, upper = ring.min(axis=0) - TOL, ring.max(axis=0) + TOL
    meets = ~((stack.lower > upper).any(axis=1) | (stack.upper < lower).any(axis=1))
    meets[i] = False
    rows = np.flatnonzero(meets[stack.owner])
    corners = origin + face @ axes
    beyond = (corners @ stack.A[rows].T - stack.b[rows] > -TOL + CLEAR_M).all(axis=0)
    meets[stack.owner[rows[beyond]]] = False
    cuts = []
    for j in np.flatnonzero(meets).tolist():
        other = polytopes[j]
        inside = _clip(face, other.A @ axes.T, other.b - other.A @ origin - TOL)
        cut = shapely.convex_hull(shapely.MultiPoint(inside))  # convex, up to rounding
        if isinstance(cut, shapely.Polygon):
            cuts.append(cut)
    # Snap-rounded to a TOL grid: exact floating-point overlay of these nearly coincident
    # polygons (slivers, corners a nanometre apart) can raise GEOS topology errors.
    region = shapely.set_precision(hull, TOL)
    if cuts:
        covered = shapely.union_all(shapely.set_precision(cuts, TOL), grid_size=TOL)
        region = shapely.difference(region, covered, grid_size=TOL)
    parts = shapely.get_parts(shapely.constrained_delaunay_triangles(region))
    # Slivers (a region that meets a facet only along a line, left as triangles a rounding
    # error wide) are not area to sample: under a PROBE_M square, as ``vertex_modes`` has it.
    parts = parts[shapely.area(parts) >= PROBE_M**2]
    flat = np.array([np.asarray(t.exterior.coords)[:3] for t in parts]).reshape(-1, 3, 2)
    return origin + flat @ axes, np.repeat(normal[None, :], len(flat), axis=0)


def _clip(polygon: np.ndarray, M: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The convex 2-D ``polygon`` cut to the half-planes ``M w ≤ r`` (Sutherland–Hodgman).
    Only the half-planes that cut the polygon as given are tried (a cut polygon lies inside
    it): a facet against one of tens of C-obstacles meets a few of its ~100 planes."""
    outside = polygon @ M.T > r  # (corners, planes)
    if outside.all(axis=0).any():
        return np.zeros((0, 2))
    for h in np.flatnonzero(outside.any(axis=0)):
        s = (polygon @ M[h] - r[h]).tolist()  # Python floats: the same IEEE steps, less overhead
        if max(s) <= 0:
            continue
        if min(s) > 0:
            return np.zeros((0, 2))
        corners, kept = polygon.tolist(), []
        for k, ((x, y), sk) in enumerate(zip(corners, s, strict=True)):
            nxt = (k + 1) % len(corners)
            if sk <= 0:
                kept.append((x, y))
            if (sk <= 0) != (s[nxt] <= 0):
                t = sk / (sk - s[nxt])
                kept.append((x + t * (corners[nxt][0] - x), y + t * (corners[nxt][1] - y)))
        polygon = np.array(kept)
    return polygon


def _in_triangles(triangles: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    u, v = rng.uniform(size=(2, len(triangles)))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    return a + u[:, None] * (b - a) + v[:, None] * (c - a)
