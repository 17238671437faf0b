"""The contact-mode graph of a C-obs slice, weighted for a belief, searched with Dijkstra.

Vertices are modes (contact pairs) found at boundary vertices of the slice; an edge joins two
modes that occur together at a boundary vertex (and, with ``near_edge_m``, two whose regions
come that close: a short move through free space). The free mode connects to the ``n_free``
modes nearest the belief. The cost of entering mode v is ``1 − δ_proj·|u(b)·n(v)|``: u(b) is
the principal direction of the particles' position spread and n(v) the C-obs normal of v,
so contacts whose normal points along the uncertainty are slightly preferred; with
``fail_cost`` c, entering a mode costs c more for each edge into it pruned so far (up to
``FAIL_CAP`` of them): of routes as short, those that avoid contacts that failed come first.
"""

from collections import Counter
from dataclasses import dataclass
from itertools import combinations

import networkx as nx
import numpy as np
from scipy.spatial import cKDTree

from bilba_dist.cspace.slice import CObsSlice
from bilba_dist.errors import NoScheduleError
from bilba_dist.geometry.contact import FREE, ContactPair

#: Points sampled on each mode's region to find the modes nearest the belief.
NEAREST_SAMPLES = 32
#: Two schedules' costs within this are "as many hops" (each hop costs 1 − δ_proj·|u·n|).
TIE = 0.5
#: A mode's failures count towards its cost up to this many (``fail_cost`` each).
FAIL_CAP = 3


@dataclass(frozen=True)
class GraphParams:
    n_free: int = 3
    delta_proj: float = 1e-4
    min_mode_vertices: int = 4
    near_edge_m: float = 0.0
    fail_cost: float = 0.0


class ModeGraph:
    """A directed graph over modes with belief-dependent edge costs; prunable."""

    def __init__(
        self,
        cslice: CObsSlice,
        graph: nx.DiGraph,
        goal: ContactPair,
        delta_proj: float,
        fail_cost: float = 0.0,
    ) -> None:
        self.cslice = cslice
        self.graph = graph
        self.goal = goal
        self.delta_proj = delta_proj
        self.fail_cost = fail_cost
        self.failures: Counter[ContactPair] = Counter()  # edges into each mode pruned so far
        self._pruned: list[tuple[ContactPair, ContactPair, dict]] = []

    def reweight(self, positions: np.ndarray) -> None:
        """Recompute every edge cost for a belief whose particles are at ``positions``."""
        u = uncertainty_direction(positions)
        for _, v, data in self.graph.edges(data=True):
            data["cost"] = edge_cost(u, self.normal(v), self.delta_proj) + self._penalty(v)

    def _penalty(self, mode: ContactPair) -> float:
        return self.fail_cost * min(self.failures[mode], FAIL_CAP)

    @property
    def modes(self) -> list[ContactPair]:
        return sorted(n for n in self.graph.nodes if n != FREE)

    def normal(self, mode: ContactPair) -> np.ndarray:
        return np.asarray(self.graph.nodes[mode]["normal"])

    def schedule(self, start: ContactPair = FREE) -> list[ContactPair]:
        """The cheapest mode sequence from ``start`` to the goal (both included)."""
        if self.goal not in self.graph:
            raise NoScheduleError(
                f"the goal contact {self.goal} does not occur on the C-obs slice: at this "
                "rotation the part cannot touch that face without entering another piece (no "
                "clearance there — or a split mesh's convex pieces filling it?)"
            )
        try:
            return list(nx.dijkstra_path(self.graph, start, self.goal, weight="cost"))
        except (nx.NetworkXNoPath, nx.NodeNotFound):
            raise NoScheduleError(
                f"no path in the mode graph from {start} to {self.goal}"
            ) from None

    def alternatives(self, start: ContactPair, k: int) -> list[list[ContactPair]]:
        """Up to ``k`` schedules from ``start`` to the goal with as many hops as the cheapest,
        each through a different next mode: Dijkstra's own first, then by cost and name.

        With δ_proj ≪ 1 every hop costs about 1, so schedules of equal length differ only by
        the tie-break; these are the contacts a planner may race before committing."""
        best = self.schedule(start)
        to_goal = nx.single_source_dijkstra_path_length(
            self.graph.reverse(copy=False), self.goal, weight="cost"
        )
        limit = to_goal[start] + TIE
        totals = {
            m: data["cost"] + to_goal[m]
            for m, data in self.graph[start].items()
            if m in to_goal and m != best[1] and data["cost"] + to_goal[m] <= limit
        }
        others = sorted(totals, key=lambda m: (totals[m], m))[: max(0, k - 1)]
        return [best] + [
            [start, *nx.dijkstra_path(self.graph, m, self.goal, "cost")] for m in others
        ]

    def prune(self, u: ContactPair, v: ContactPair) -> None:
        """Remove the edge u → v (a transition that failed); with ``fail_cost``, the other
        edges into v cost that much more (the failures are kept across ``restore``)."""
        if self.graph.has_edge(u, v):
            self._pruned.append((u, v, self.graph.edges[u, v]))
            self.graph.remove_edge(u, v)
        before = self._penalty(v)
        self.failures[v] += 1
        for _, _, data in self.graph.in_edges(v, data=True):
            data["cost"] += self._penalty(v) - before

    def restore(self) -> None:
        """Put back every pruned edge (costs as they were when pruned; ``reweight`` after)."""
        self.graph.add_edges_from(self._pruned)
        self._pruned.clear()

    def has_schedule(self, start: ContactPair = FREE) -> bool:
        return self.goal in self.graph and nx.has_path(self.graph, start, self.goal)

    def to_dot(self) -> str:
        lines = ["digraph modes {", "  rankdir=LR;"]
        for node in [FREE, *self.modes]:
            lines.append(f'  "{node}";')
        for u, v, cost in sorted(self.graph.edges(data="cost")):
            lines.append(f'  "{u}" -> "{v}" [label="{cost:.6f}"];')
        lines.append("}")
        return "\n".join(lines) + "\n"


def build_mode_graph(
    cslice: CObsSlice, positions: np.ndarray, goal: ContactPair, params: GraphParams
) -> ModeGraph:
    """The mode graph of ``cslice`` weighted for particles at ``positions`` (N, 3) in O."""
    counts = Counter(mode for contacts in cslice.vertex_modes for mode in contacts)
    modes = sorted(m for m, c in counts.items() if c >= params.min_mode_vertices or m == goal)
    normals = {m: mode_normal(cslice, m) for m in modes}
    u = uncertainty_direction(positions)
    graph = nx.DiGraph()
    graph.add_node(FREE, normal=np.zeros(3))
    for m in modes:
        graph.add_node(m, normal=normals[m])
    kept = set(modes)
    pairs = {
        tuple(sorted(pair))
        for contacts in cslice.vertex_modes
        for pair in combinations(sorted(contacts & kept), 2)
    }
    if params.near_edge_m > 0:
        pairs |= near_pairs(cslice, modes, params.near_edge_m)
    for a, b in sorted(pairs):
        graph.add_edge(a, b, cost=edge_cost(u, normals[b], params.delta_proj))
        graph.add_edge(b, a, cost=edge_cost(u, normals[a], params.delta_proj))
    for m in nearest_modes(cslice, modes, positions.mean(axis=0), params.n_free):
        graph.add_edge(FREE, m, cost=edge_cost(u, normals[m], params.delta_proj))
    return ModeGraph(cslice, graph, goal, params.delta_proj, params.fail_cost)


def near_pairs(
    cslice: CObsSlice, modes: list[ContactPair], distance: float
) -> set[tuple[ContactPair, ContactPair]]:
    """Pairs of ``modes`` whose regions (boundary vertices and ``NEAREST_SAMPLES`` points
    sampled on each, seeded) come within ``distance`` of each other."""
    rng = np.random.default_rng(0)
    points, owner = [], []
    for k, m in enumerate(modes):
        region = region_points(cslice, m, rng)
        points.append(region)
        owner += [k] * len(region)
    close = cKDTree(np.concatenate(points)).query_pairs(distance, output_type="ndarray")
    who = np.asarray(owner)[close]
    return {(modes[min(a, b)], modes[max(a, b)]) for a, b in who.tolist() if a != b}


def edge_cost(u: np.ndarray, normal: np.ndarray, delta_proj: float) -> float:
    return float(1.0 - delta_proj * abs(float(u @ normal)))


def uncertainty_direction(positions: np.ndarray) -> np.ndarray:
    """Unit principal direction of the centred positions' spread; zero when there is none."""
    centred = np.atleast_2d(positions) - np.atleast_2d(positions).mean(axis=0)
    if len(centred) < 2 or np.allclose(centred, 0.0, atol=1e-12):
        return np.zeros(3)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    u = vt[0]
    return u if u[np.argmax(np.abs(u))] > 0 else -u  # fix the sign: deterministic output


def mode_normal(cslice: CObsSlice, mode: ContactPair) -> np.ndarray:
    """Area-weighted mean outward normal of the C-obs facets labelled with ``mode``."""
    total = np.zeros(3)
    for i, f in cslice.mode_facets(mode):
        ring = cslice.polytopes[i].polygons[f]
        area = 0.5 * np.linalg.norm(np.cross(ring[1:-1] - ring[0], ring[2:] - ring[0]).sum(axis=0))
        total += max(area, 1e-12) * cslice.polytopes[i].A[f]
    norm = np.linalg.norm(total)
    return total / norm if norm > 0 else total


def nearest_modes(
    cslice: CObsSlice, modes: list[ContactPair], point: np.ndarray, k: int
) -> list[ContactPair]:
    """The ``k`` modes whose boundary region comes nearest ``point``; ties by name."""
    rng = np.random.default_rng(0)
    distance = {}
    for m in modes:
        distance[m] = float(np.linalg.norm(region_points(cslice, m, rng) - point, axis=1).min())
    return sorted(modes, key=lambda m: (round(distance[m], 9), m))[:k]


def region_points(cslice: CObsSlice, mode: ContactPair, rng: np.random.Generator) -> np.ndarray:
    """Where ``mode``'s region is, as points: ``NEAREST_SAMPLES`` sampled on it, then its
    boundary vertices."""
    return np.concatenate(
        [cslice.sample_mode(mode, NEAREST_SAMPLES, rng), cslice.mode_vertices(mode)]
    )
