"""Vertices of the boundary of a union of convex polytopes, with their contact sets.

Three kinds, each kept only if no polytope holds it strictly inside:
1. a vertex of one polytope;
2. an edge of one polytope crossing a facet of another;
3. a point where facets of three different polytopes meet (rare, but the floor of a channel
   between walls has only these: without them a peg's goal region has no vertex).
Polytope pairs and triples whose bounding boxes do not overlap are skipped, and so are the
facets of a triple whose own box misses the box the three share: a point on a facet and
inside all three lies in both (a meshed part split into tens of convex pieces makes tens of
thousands of triples, each of up to 10⁵ facet combinations).
"""

from collections.abc import Iterator
from itertools import combinations, permutations

import numpy as np
from scipy.spatial import cKDTree

from bilba_dist.cspace.polytope import TOL, Polytope

#: Planes whose normals' triple product is below this are treated as parallel.
SINGULAR = 1e-9
#: How far outside a facet's or polytope's box a point on it (within TOL) may be found —
#: rounding where three planes meet at a shallow angle, TOL's reach past a sharp corner [m]:
#: generous, since it only decides which facets or polytopes a point is measured against.
BOX_MARGIN = 1e-6
#: Points measured against every facet at once: (N, F) arrays of a part split into tens of
#: convex pieces (thousands of facets) for a million probes would take tens of GB.
CHUNK_POINTS = 4096
#: Triples of polytopes whose facet planes are solved together (`_facet_triples`): bounded
#: memory, as a triple can give thousands of facet combinations.
TRIPLES_AT_ONCE = 512


def boundary_vertices(polytopes: list[Polytope], stack: "FacetStack") -> np.ndarray:
    """All boundary vertices of the union, deduplicated, as a (V, 3) array."""
    overlap = _overlaps(polytopes)
    candidates = [p.vertices for p in polytopes]
    for i, j in permutations(range(len(polytopes)), 2):
        if overlap[i, j]:
            candidates.append(_edge_facet(polytopes[i], polytopes[j]))
    boxes = [_facet_boxes(p) for p in polytopes]
    triples = [
        (i, j, k)
        for i, j, k in combinations(range(len(polytopes)), 3)
        if overlap[i, j] and overlap[j, k] and overlap[i, k]
    ]
    for start in range(0, len(triples), TRIPLES_AT_ONCE):
        candidates.append(
            _facet_triples(polytopes, boxes, triples[start : start + TRIPLES_AT_ONCE])
        )
    points = np.concatenate([c for c in candidates if len(c)]) if candidates else np.zeros((0, 3))
    return dedupe(points[~stack.strictly_inside(points)])


def _overlaps(polytopes: list[Polytope]) -> np.ndarray:
    lower = np.array([p.lower for p in polytopes]) - TOL
    upper = np.array([p.upper for p in polytopes]) + TOL
    return np.all(
        (lower[:, None, :] <= upper[None, :, :]) & (lower[None, :, :] <= upper[:, None, :]), axis=2
    )


def _inside_closed(p: Polytope, points: np.ndarray) -> np.ndarray:
    return (points @ p.A.T - p.b).max(axis=1) <= TOL


def _edge_facet(a: Polytope, b: Polytope) -> np.ndarray:
    """Points where an edge of ``a`` crosses a facet of ``b`` (strictly between its ends)."""
    p0 = a.vertices[a.edges[:, 0]]
    d = a.vertices[a.edges[:, 1]] - p0
    denom = d @ b.A.T  # (E, F)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (b.b[None, :] - p0 @ b.A.T) / denom
    length = np.linalg.norm(d, axis=1)[:, None]
    ok = (np.abs(denom) > SINGULAR * length) & (t * length > TOL) & ((1 - t) * length > TOL)
    e, f = np.nonzero(ok)
    points = p0[e] + t[e, f][:, None] * d[e]
    return points[_inside_closed(b, points)]


def _facet_boxes(p: Polytope) -> tuple[np.ndarray, np.ndarray]:
    """The axis-aligned bounds of each facet polygon of ``p``, (F, 3) each."""
    return (
        np.array([polygon.min(axis=0) for polygon in p.polygons]),
        np.array([polygon.max(axis=0) for polygon in p.polygons]),
    )


def _facet_triples(
    polytopes: list[Polytope],
    boxes: list[tuple[np.ndarray, np.ndarray]],
    triples: list[tuple[int, int, int]],
) -> np.ndarray:
    """Points where one facet plane of each polytope of a triple meet, inside all three,
    for each of ``triples`` (indices into ``polytopes``). Such a point lies on all three
    facets, so only facets whose boxes (``boxes``: `_facet_boxes` of each polytope) meet the
    box the three polytopes share and each other's are tried: first the pairs of ``a`` and
    ``b``, then the facets of ``c`` that meet both. The facets are chosen triple by triple;
    the planes are solved and the points tested against their polytopes for all the
    triples at once (a plate split into 100 pieces has 10⁵ triples)."""
    picked: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    owners: list[tuple[int, int, int]] = []
    for triple in triples:
        found = _triple_facets([polytopes[t] for t in triple], [boxes[t] for t in triple])
        if found is not None and len(found[0]):
            picked.append(found)
            owners.append(triple)
    if not picked:
        return np.zeros((0, 3))
    counts = [len(f[0]) for f in picked]
    owner = np.repeat(np.array(owners, dtype=np.intp).reshape(-1, 3), counts, axis=0)
    facet = np.concatenate([np.stack(f, axis=1) for f in picked])  # (R, 3) facet per slot
    normals = np.empty((len(facet), 3, 3))
    offsets = np.empty((len(facet), 3))
    for slot, p, rows in _by_polytope(owner):
        normals[rows, slot] = polytopes[p].A[facet[rows, slot]]
        offsets[rows, slot] = polytopes[p].b[facet[rows, slot]]
    ok = np.abs(np.linalg.det(normals)) > SINGULAR
    points = np.linalg.solve(normals[ok], offsets[ok][:, :, None])[:, :, 0]
    inside = np.ones(len(points), dtype=bool)
    for _, p, rows in _by_polytope(owner[ok]):
        inside[rows] &= _inside_closed(polytopes[p], points[rows])
    return points[inside]


def _by_polytope(owner: np.ndarray) -> Iterator[tuple[int, int, np.ndarray]]:
    """For each slot of ``owner`` (R, 3) and each polytope in it: (slot, polytope, the rows
    it owns there)."""
    for slot in range(3):
        for p in np.unique(owner[:, slot]).tolist():
            yield slot, p, np.flatnonzero(owner[:, slot] == p)


def _triple_facets(
    triple: list[Polytope], boxes: list[tuple[np.ndarray, np.ndarray]]
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The facet index triples of ``triple`` whose boxes meet each other and the box the
    three polytopes share (`_facet_triples`), in the order of a full grid; None when a
    polytope has no facet in that box."""
    lower = np.max([p.lower for p in triple], axis=0) - BOX_MARGIN
    upper = np.min([p.upper for p in triple], axis=0) + BOX_MARGIN
    near = []  # per polytope: its facets in the shared box, with their boxes
    for low, high in boxes:
        keep = np.flatnonzero(np.all((low <= upper) & (lower <= high), axis=1))
        if len(keep) == 0:
            return None
        near.append((keep, low[keep] - BOX_MARGIN, high[keep] + BOX_MARGIN))
    (fa, lo_a, hi_a), (fb, lo_b, hi_b), (fc, lo_c, hi_c) = near
    pa, pb = np.nonzero(_boxes_meet(lo_a, hi_a, lo_b, hi_b))
    pair, pc = np.nonzero(
        _boxes_meet(np.maximum(lo_a[pa], lo_b[pb]), np.minimum(hi_a[pa], hi_b[pb]), lo_c, hi_c)
    )
    return fa[pa[pair]], fb[pb[pair]], fc[pc]


def _boxes_meet(lo1: np.ndarray, hi1: np.ndarray, lo2: np.ndarray, hi2: np.ndarray) -> np.ndarray:
    """(N, M): whether box n of the first set meets box m of the second."""
    return np.all((lo1[:, None] <= hi2[None]) & (lo2[None] <= hi1[:, None]), axis=2)


def dedupe(points: np.ndarray, radius: float = 10 * TOL) -> np.ndarray:
    """One representative (the lexicographically first) per cluster of nearby points."""
    if len(points) == 0:
        return points.reshape(0, 3)
    order = np.lexsort(points.T[::-1])
    points = points[order]
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    keep = np.ones(len(points), dtype=bool)
    if len(pairs):
        keep[pairs.max(axis=1)] = False
    return points[keep]


class FacetStack:
    """All polytopes' facets in one matrix, for vectorised slack over many points."""

    def __init__(self, polytopes: list[Polytope]) -> None:
        self.A = np.concatenate([p.A for p in polytopes])
        self.b = np.concatenate([p.b for p in polytopes])
        counts = [len(p.b) for p in polytopes]
        self.starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
        self.counts = counts
        self.owner = np.repeat(np.arange(len(polytopes)), counts)  # each facet's polytope
        self.lower = np.array([p.lower for p in polytopes]).reshape(-1, 3)  # their boxes
        self.upper = np.array([p.upper for p in polytopes]).reshape(-1, 3)

    def facet_slack(self, points: np.ndarray) -> np.ndarray:
        """(N, F) signed distance of each point to each facet plane [m]."""
        return np.atleast_2d(points) @ self.A.T - self.b

    def in_box(self, points: np.ndarray, k: int) -> np.ndarray:
        """(N,) whether each point lies in polytope k's box, BOX_MARGIN around it: a point
        outside it is outside the polytope and on none of its facets."""
        return (
            (points >= self.lower[k] - BOX_MARGIN) & (points <= self.upper[k] + BOX_MARGIN)
        ).all(axis=1)

    def strictly_inside(self, points: np.ndarray) -> np.ndarray:
        """(N,) whether each point lies strictly inside (slack below −TOL) some polytope:
        each measured only against the polytopes whose box holds it (a point outside a box
        is outside its polytope), so many points against tens of pieces stay cheap."""
        points = np.atleast_2d(points)
        inside = np.zeros(len(points), dtype=bool)
        for k, start in enumerate(self.starts.tolist()):
            measured = np.flatnonzero(self.in_box(points, k) & ~inside)
            if len(measured) == 0:
                continue
            end = start + self.counts[k]
            slack = (points[measured] @ self.A[start:end].T - self.b[start:end]).max(axis=1)
            inside[measured[slack < -TOL]] = True
        return inside

    def slack(self, points: np.ndarray) -> np.ndarray:
        """(N, P) per-polytope slack: < 0 strictly inside, ~0 on the boundary. Computed
        CHUNK_POINTS at a time: the (N, F) facet slack of tens of thousands of points
        against a part split into tens of pieces would take gigabytes."""
        points = np.atleast_2d(points)
        if len(points) == 0:
            return np.zeros((0, len(self.starts)))
        return np.concatenate(
            [
                np.maximum.reduceat(self.facet_slack(chunk), self.starts, axis=1)
                for chunk in np.split(points, range(CHUNK_POINTS, len(points), CHUNK_POINTS))
            ]
        )
