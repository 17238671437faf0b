"""The C-obs slice: known answers, boundary vertices against brute force, and membership
against an independent exact collision check (coal, shipped with Pinocchio)."""

from itertools import combinations
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bilba_dist.belief.particles import initial_belief
from bilba_dist.cspace import boundary as boundary_module
from bilba_dist.cspace import slice as slice_module
from bilba_dist.cspace.boundary import dedupe
from bilba_dist.cspace.polytope import TOL
from bilba_dist.cspace.slice import BOUNDARY, INSIDE, OUTSIDE, CObsSlice
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.piece import Part, box_piece
from bilba_dist.geometry.pose import pose_from_xyz_rpy
from bilba_dist.task.loader import load_task

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
ENV_HALF = np.array([0.2, 0.3, 0.1])
MANIP_HALF = np.array([0.05, 0.04, 0.03])


def box_part(name: str, half: np.ndarray) -> Part:
    return Part(name, (box_piece(name, 2 * half, pin.SE3.Identity()),))


@pytest.fixture(scope="module")
def box_slice() -> CObsSlice:
    return CObsSlice.build(box_part("e", ENV_HALF), box_part("m", MANIP_HALF), np.eye(3))


def test_box_in_box_slice_is_the_box_of_summed_half_extents(box_slice):
    (polytope,) = box_slice.polytopes
    half = ENV_HALF + MANIP_HALF
    assert len(polytope.b) == 6
    for normal, offset in zip(polytope.A, polytope.b, strict=True):
        axis = int(np.argmax(np.abs(normal)))
        assert np.allclose(np.abs(normal), np.eye(3)[axis])
        assert offset == pytest.approx(half[axis])
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    assert np.allclose(np.sort(box_slice.vertices, axis=0), np.sort(corners * half, axis=0))


@pytest.mark.parametrize("axis", range(3))
@pytest.mark.parametrize("sign", [1, -1])
def test_box_facets_are_labelled_with_the_touching_faces(box_slice, axis, sign):
    (polytope,) = box_slice.polytopes
    names = "xyz"[axis]
    normal = sign * np.eye(3)[axis]
    facet = int(np.argmax(polytope.A @ normal))
    env_face = f"e/{'+' if sign > 0 else '-'}{names}"
    manip_face = f"m/{'-' if sign > 0 else '+'}{names}"
    assert polytope.labels[facet] == {ContactPair(env_face, manip_face)}


def test_box_corner_vertex_names_three_pairs(box_slice):
    corner = ENV_HALF + MANIP_HALF
    (contacts,) = box_slice.contacts(corner)
    assert contacts == {
        ContactPair("e/+x", "m/-x"),
        ContactPair("e/+y", "m/-y"),
        ContactPair("e/+z", "m/-z"),
    }


def test_point_queries(box_slice):
    half = ENV_HALF + MANIP_HALF
    points = np.array([[0, 0, 0], [half[0], 0, 0], [half[0] + 1e-6, 0, 0]])
    assert box_slice.classify(points).tolist() == [INSIDE, BOUNDARY, OUTSIDE]
    assert box_slice.contacts(points[0]) == (frozenset(),)


def test_mode_samples_lie_on_the_mode_and_inside_when_pushed(box_slice):
    mode = ContactPair("e/+z", "m/-z")
    rng = np.random.default_rng(1)
    on = box_slice.sample_mode(mode, 50, rng)
    assert len(on) == 50
    assert np.allclose(on[:, 2], ENV_HALF[2] + MANIP_HALF[2])
    assert all(mode in c for c in box_slice.contacts(on))
    pushed = box_slice.sample_mode(mode, 50, rng, depth=1e-3)
    assert (box_slice.classify(pushed) == INSIDE).all()


def test_a_sliver_region_of_a_large_facet_is_sampled_all_over():
    """The puzzle's goal (neck on the far bar's inner face) is 0.5 × 1 mm of a facet of
    about 160 × 42 mm: the neck fits the opening with 0.25 mm either side in x, and it faces
    the bar only while the top block clears the bar (z ≥ 111 mm), the lower block passes
    under it (z ≤ 113 mm) and rests on the rail (z ≥ 112 mm). Drawing on the facet and
    rejecting what falls off the region found ~0.15 points in 2048."""
    task = load_task("puzzle")
    cslice = CObsSlice.build(task.environment, task.manipuland, np.eye(3))
    points = cslice.sample_mode(task.goal, 200, np.random.default_rng(3))
    assert len(points) == 200
    assert all(task.goal in c for c in cslice.contacts(points))
    x, y, z = points.T * 1000  # mm
    assert np.allclose(y, 15.5)
    assert x.min() >= -0.25 - 1e-6 and x.max() <= 0.25 + 1e-6 and np.ptp(x) > 0.45
    assert z.min() >= 112 - 1e-6 and z.max() <= 113 + 1e-6 and np.ptp(z) > 0.9
    triangles, _ = cslice.mode_triangles(task.goal)
    area = 0.5 * np.linalg.norm(
        np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1
    )
    assert area.sum() == pytest.approx(0.5e-3 * 1e-3, rel=1e-4)  # cut at −TOL: +2 nm a side


def nearly_square_rotations(n: int) -> list[np.ndarray]:
    """Seeded rotations, each a normal twist of 0.01 rad scaled by 1e-4, 1e-2 or 1."""
    rng = np.random.default_rng(0)
    return [pin.exp3(rng.normal(size=3) * 0.01 * rng.choice([1e-4, 1e-2, 1])) for _ in range(n)]


@pytest.mark.parametrize("k, pieces", [(12, ("bar_py", "lower")), (20, ("bar_px", "neck"))])
def test_mode_regions_of_nearly_square_rotations(k, pieces):
    """Turned by micro-radians, a Minkowski facet is merged from nearly coplanar ones whose
    corners lie ~1e-8 m off its plane and fold when projected; at these two rotations (of a
    sweep of 30) that once made the polygon overlay raise. Every mode of the piece pair gets
    its region, and points drawn there are on the mode."""
    task = load_task("puzzle")
    cslice = CObsSlice.build(task.environment, task.manipuland, nearly_square_rotations(k + 1)[k])
    env, manip = pieces
    modes = {
        m
        for p in cslice.polytopes
        for label in p.labels
        for m in label
        if m.env.startswith(env + "/") and m.manip.startswith(manip + "/")
    }
    rng = np.random.default_rng(0)
    sampled = 0
    for mode in sorted(modes):
        points = cslice.sample_mode(mode, 20, rng)
        assert all(mode in c for c in cslice.contacts(points)), mode
        sampled += len(points) > 0
    assert sampled >= 6  # at least the six face-to-face modes of two boxes have area


def brute_force_vertices(cslice: CObsSlice) -> np.ndarray:
    """Every point where three facet planes meet, on those facets, not covered: the
    definition of a boundary vertex, enumerated over all facet triples with no pruning."""
    owner = np.concatenate([[i] * len(p.b) for i, p in enumerate(cslice.polytopes)])
    A = np.concatenate([p.A for p in cslice.polytopes])
    b = np.concatenate([p.b for p in cslice.polytopes])
    triples = np.array(list(combinations(range(len(b)), 3)))
    normals, offsets = A[triples], b[triples]
    ok = np.abs(np.linalg.det(normals)) > 1e-9
    triples = triples[ok]
    points = np.linalg.solve(normals[ok], offsets[ok][:, :, None])[:, :, 0]
    slack = cslice.stack.slack(points)  # (N, P)
    on_own = np.all(np.take_along_axis(slack, owner[triples], axis=1) <= TOL, axis=1)
    uncovered = slack.min(axis=1) >= -TOL
    return dedupe(points[on_own & uncovered])


def assert_same_points(a: np.ndarray, b: np.ndarray) -> None:
    assert len(a) == len(b)
    for p in a:
        assert np.linalg.norm(b - p, axis=1).min() < 1e-7


@pytest.mark.parametrize("task_name", ["peg", "puzzle"])
def test_boundary_vertices_match_brute_force(task_name, request):
    task = request.getfixturevalue(task_name)
    for particle in initial_belief(task)[:2]:
        cslice = CObsSlice.build(
            task.environment, task.manipuland, particle.X_OM(task.X_WG0).rotation
        )
        if task_name == "puzzle":  # 180 facets in all: brute force the pieces near the goal
            near = [p for p in cslice.polytopes if p.env_piece in ("rail", "bar_py")]
            cslice = CObsSlice.of(cslice.R_OM, near)
        assert_same_points(cslice.vertices, brute_force_vertices(cslice))


def test_peg_goal_region_has_vertices_only_where_three_polytopes_meet(peg):
    cslice = CObsSlice.build(peg.environment, peg.manipuland, np.eye(3))
    goal = [
        v for v, c in zip(cslice.vertices, cslice.vertex_contacts, strict=True) if peg.goal in c
    ]
    assert len(goal) >= 4
    for v in goal:  # the channel floor's corners: floor, and two walls
        touching = [p for p in cslice.polytopes if abs((v @ p.A.T - p.b).max()) <= TOL]
        assert len({p.env_piece for p in touching}) >= 3


def test_a_box_corner_keeps_all_three_modes(box_slice):
    """Every mode at a single box's corner has a face of the slice there."""
    assert box_slice.vertex_modes == box_slice.vertex_contacts
    assert all(len(modes) == 3 for modes in box_slice.vertex_modes)


def test_modes_that_touch_a_vertex_only_edge_to_edge_are_left_out(puzzle):
    """The puzzle's goal pair (neck/+y on bar_py/-y) occurs on the slot's four corners and,
    edge to edge, at the frame's outer corners (x = ±80.25 mm), where the neck's face meets
    only the end of the bar's: only the slot's corners lie on the goal's region."""
    cslice = CObsSlice.build(puzzle.environment, puzzle.manipuland, np.eye(3))
    touching = np.array(
        [
            v
            for v, c in zip(cslice.vertices, cslice.vertex_contacts, strict=True)
            if puzzle.goal in c
        ]
    )
    assert np.isclose(np.abs(touching[:, 0]), 0.08025).sum() >= 4
    region = cslice.mode_vertices(puzzle.goal)
    assert len(region) == 4
    assert np.allclose(np.abs(region[:, 0]), 0.00025) and np.allclose(region[:, 1], 0.0155)
    for modes, contacts in zip(cslice.vertex_modes, cslice.vertex_contacts, strict=True):
        assert modes <= contacts


def signed_distance(task, X_OM: pin.SE3) -> float:
    """Exact signed distance between the two parts (coal): < 0 when they overlap."""
    request = coal.DistanceRequest()
    best = np.inf
    for env in task.environment.pieces:
        env_shape = _coal_convex(env.vertices)
        for manip in task.manipuland.pieces:
            result = coal.DistanceResult()
            d = coal.distance(
                env_shape,
                coal.Transform3s(),
                _coal_convex(manip.vertices),
                coal.Transform3s(X_OM.rotation, X_OM.translation),
                request,
                result,
            )
            best = min(best, d)
    return float(best)


def _coal_convex(vertices: np.ndarray):
    points = coal.StdVec_Vec3s()
    for v in vertices:
        points.append(np.asarray(v, dtype=float))
    return coal.Convex.convexHull(points, False, None)


_slices: dict = {}


@pytest.mark.parametrize("task_name", ["peg", "puzzle"])
@settings(max_examples=150, deadline=None, derandomize=True)
@given(
    rpy=st.lists(st.floats(-0.1, 0.1), min_size=3, max_size=3),
    unit=st.lists(st.floats(0, 1), min_size=3, max_size=3),
)
def test_slice_membership_agrees_with_exact_collision(task_name, rpy, unit, request):
    task = request.getfixturevalue(task_name)
    R = pose_from_xyz_rpy([0, 0, 0], rpy).rotation
    cslice = CObsSlice.build(task.environment, task.manipuland, R)
    lower = np.min([p.lower for p in cslice.polytopes], axis=0) - 0.01
    upper = np.max([p.upper for p in cslice.polytopes], axis=0) + 0.01
    position = lower + np.array(unit) * (upper - lower)
    distance = signed_distance(task, pin.SE3(R, position))
    (state,) = cslice.classify(position)
    if abs(distance) < 1e-6:
        return  # within coal's tolerance of touching: either answer is right
    assert state == (INSIDE if distance < 0 else OUTSIDE), f"coal distance {distance}"


@pytest.mark.parametrize("task_name", ["hex-peg", "puzzle"])
def test_pruning_facets_by_their_boxes_loses_no_vertex(task_name, monkeypatch):
    """A triple of C-obstacles only tries the facets whose boxes meet the box all three
    share (a ring of overlapping walls — hex-peg, or a part split into convex pieces — has
    thousands of triples): the same vertices as trying every facet."""
    import bilba_dist.cspace.boundary as boundary

    task = load_task(task_name)
    rotations = [p.X_OM(task.X_WG0).rotation for p in initial_belief(task)[:2]]
    pruned = [CObsSlice.build(task.environment, task.manipuland, R).vertices for R in rotations]

    def unbounded(p):
        return np.full((len(p.b), 3), -np.inf), np.full((len(p.b), 3), np.inf)

    monkeypatch.setattr(boundary, "_facet_boxes", unbounded)
    for R, vertices in zip(rotations, pruned, strict=True):
        every = CObsSlice.build(task.environment, task.manipuland, R).vertices
        np.testing.assert_array_equal(vertices, every)


@settings(max_examples=200)
@given(
    corners=st.integers(3, 12),
    planes=st.lists(
        st.tuples(st.floats(0, 2 * np.pi), st.floats(-1.2, 1.2)), min_size=1, max_size=12
    ),
)
def test_clip_is_the_polygon_cut_by_every_half_plane(corners, planes):
    """`_clip` (which skips the planes that do not cut the polygon as given) against
    Shapely's intersection with each half-plane, as a large square beyond the line."""
    import shapely

    from bilba_dist.cspace.slice import _clip

    angles = np.linspace(0, 2 * np.pi, corners, endpoint=False) + 0.1
    polygon = np.c_[np.cos(angles), np.sin(angles)]
    M = np.array([[np.cos(a), np.sin(a)] for a, _ in planes])
    r = np.array([c for _, c in planes])
    expected = shapely.Polygon(polygon)
    for m, c in zip(M, r, strict=True):
        t = np.array([-m[1], m[0]])
        half = shapely.Polygon(
            [c * m + 10 * t, c * m - 10 * t, c * m - 10 * t - 10 * m, c * m + 10 * t - 10 * m]
        )
        expected = expected.intersection(half)
    clipped = _clip(polygon, M, r)
    got = shapely.convex_hull(shapely.MultiPoint(clipped)) if len(clipped) else shapely.Polygon()
    assert abs(got.area - expected.area) < 1e-9
    if expected.area > 1e-6:
        assert got.symmetric_difference(expected).area < 1e-9


def test_contact_sets_match_every_facet_measured(puzzle):
    """``contacts`` measures each point against the facets of the pieces whose box holds it
    and unions labels once per set of facets; measured here against every facet of every
    polytope (the definition): the puzzle's vertices, points sampled on its modes, probes
    around the vertices and points off the boundary (inside and outside)."""
    cslice = CObsSlice.build(puzzle.environment, puzzle.manipuland, np.eye(3))
    rng = np.random.default_rng(5)
    modes = sorted({m for c in cslice.vertex_contacts for m in c})[:12]
    on = [cslice.sample_mode(m, 20, rng) for m in modes]
    probes = cslice.vertices + rng.normal(scale=1e-5, size=cslice.vertices.shape)
    off = rng.uniform(-0.1, 0.1, size=(200, 3)) + cslice.vertices.mean(axis=0)
    points = np.concatenate([cslice.vertices, *on, probes, off])

    def expected(x: np.ndarray) -> frozenset[ContactPair]:
        slacks = [p.A @ x - p.b for p in cslice.polytopes]
        if any(s.max() < -TOL for s in slacks):  # inside a polytope: not on the boundary
            return frozenset()
        labels: set[ContactPair] = set()
        for p, s in zip(cslice.polytopes, slacks, strict=True):
            if abs(s.max()) <= TOL:
                for f in np.flatnonzero(np.abs(s) <= TOL):
                    labels |= p.labels[f]
        return frozenset(labels)

    found = cslice.contacts(points)
    assert found == tuple(expected(x) for x in points)
    assert sum(bool(c) for c in found) > len(cslice.vertices)  # the samples are on it too


def test_facet_regions_pass_over_only_polytopes_that_cut_nothing(monkeypatch):
    """`_facet_region` passes over, without clipping, every polytope with a plane the whole
    facet lies beyond (by CLEAR_M): its regions are those of clipping against every polytope
    whose box meets the facet, to the bit — on the round-peg example's plate (16 meshed
    pieces), where most pieces are passed over."""
    task = load_task(EXAMPLES / "round-peg" / "round-peg.yaml")
    cslice = CObsSlice.build(task.environment, task.manipuland, np.eye(3))
    facets = [(i, f) for i, p in enumerate(cslice.polytopes) for f in range(len(p.b))][::3]
    fast = [slice_module._facet_region(cslice.polytopes, i, f, cslice.stack) for i, f in facets]
    monkeypatch.setattr(slice_module, "CLEAR_M", np.inf)  # nothing passed over
    every = [slice_module._facet_region(cslice.polytopes, i, f, cslice.stack) for i, f in facets]
    assert sum(len(t) > 0 for t, _ in fast) > 10
    for (t1, n1), (t2, n2) in zip(fast, every, strict=True):
        assert np.array_equal(t1, t2) and np.array_equal(n1, n2)


def test_facet_triples_solved_together_are_those_solved_one_by_one(monkeypatch):
    """`boundary_vertices` solves the facet planes of many polytope triples at once; one
    triple at a time (each batch's rows then belong to one triple) gives the same vertices,
    to the bit — on the round-peg example's 17 polytopes (680 triples)."""
    task = load_task(EXAMPLES / "round-peg" / "round-peg.yaml")
    together = CObsSlice.build(task.environment, task.manipuland, np.eye(3)).vertices
    monkeypatch.setattr(boundary_module, "TRIPLES_AT_ONCE", 1)
    alone = CObsSlice.build(task.environment, task.manipuland, np.eye(3)).vertices
    assert len(together) > 1000 and np.array_equal(together, alone)


def test_strictly_inside_is_the_least_slack_below_minus_tol():
    """`FacetStack.strictly_inside` measures a point only against the polytopes whose box
    holds it; the definition measures it against every facet: the same answer for points
    inside, outside and on the round-peg plate's 17 polytopes (its boundary vertices)."""
    task = load_task(EXAMPLES / "round-peg" / "round-peg.yaml")
    cslice = CObsSlice.build(task.environment, task.manipuland, np.eye(3))
    rng = np.random.default_rng(11)
    spread = rng.uniform(-0.1, 0.1, size=(3000, 3)) + cslice.vertices.mean(axis=0)
    points = np.concatenate([spread, cslice.vertices])
    found = cslice.stack.strictly_inside(points)
    assert np.array_equal(found, cslice.stack.slack(points).min(axis=1) < -TOL)
    assert 0 < found.sum() < len(spread)  # some of each
