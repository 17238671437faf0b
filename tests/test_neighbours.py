"""Neighbouring faces across pieces (a curved surface cut into pieces) and the contacts the
planner counts as a contact sought because of them."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from bilba_dist.geometry.contact import FREE, ContactPair
from bilba_dist.geometry.neighbours import TOUCH_M, NearContacts, neighbouring_faces
from bilba_dist.geometry.piece import UNNAMED, ConvexPiece, Part, convex_piece
from bilba_dist.planning.bilba import already_made, furthest_common
from bilba_dist.task.loader import load_task
from tests.conftest import prism_task
from tests.test_planner import belief_with

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_a_meshed_round_hole_has_neighbours_across_its_pieces():
    """The round-peg example's plate, split by CoACD into 16 convex objects: the wall
    facets of pieces side by side are neighbours, each relation both ways."""
    task = load_task(str(EXAMPLES / "round-peg" / "round-peg.yaml"))
    near = neighbouring_faces(task.environment)
    assert near["plate_12/f1"] == {"plate_13/f1", "plate_7/f4"}
    assert all(face in near[other] for face, others in near.items() for other in others)
    assert neighbouring_faces(task.manipuland) == {}  # one piece: its side is one face already


def test_named_faces_have_no_neighbours(tmp_path):
    """A hole of 32 wall pieces, 11.25° apart, whose faces the task file names (inner,
    chamfer, top): each is a contact of its own. Measured (generated 32-gon, 8 seeds of 9
    at 120 s): counting neighbours' contacts there planned 0 where names alone planned 5."""
    task = prism_task(tmp_path, 32, 0.002)
    near = neighbouring_faces(task.environment)
    assert near and all(UNNAMED.fullmatch(face.rpartition("/")[2]) for face in near)
    assert "wall0/inner" not in near and "wall0/chamfer" not in near


@pytest.mark.parametrize("sides", [4, 6, 8, 12])
def test_polygon_holes_and_the_builtins_have_no_neighbours(tmp_path, sides):
    """Walls 90° to 30° apart are faces of their own, as in the built-in tasks: their
    planning is unchanged by construction."""
    task = prism_task(tmp_path, sides, 0.002)
    assert neighbouring_faces(task.environment) == {}
    for name in ("peg-in-hole", "puzzle", "hex-peg"):
        builtin = load_task(name)
        assert neighbouring_faces(builtin.environment) == {}
        assert neighbouring_faces(builtin.manipuland) == {}


def _turn(turn_deg: float, tilt_deg: float = 0) -> np.ndarray:
    """``turn_deg`` about the z axis, then ``tilt_deg`` about the y axis."""
    return pin.utils.rotate("y", np.deg2rad(tilt_deg)) @ pin.utils.rotate("z", np.deg2rad(turn_deg))


def _slab(name: str, x0: float, turn_deg: float, gap_m: float, tilt_deg: float = 0) -> ConvexPiece:
    """A 20 mm slab from ``x0`` along x, turned by ``_turn`` about the origin and moved
    ``gap_m`` along x: its faces unnamed (f0 ...)."""
    corners = [[x, y, z] for x in (x0, x0 + 0.02) for y in (0, -0.01) for z in (0, 0.01)]
    place = pin.SE3(_turn(turn_deg, tilt_deg), np.array([gap_m, 0, 0]))
    return convex_piece(name, corners, place)


def _face_along(piece: ConvexPiece, direction: np.ndarray) -> str:
    return max(piece.faces, key=lambda f: f.normal @ direction).name


@pytest.mark.parametrize(("tilt", "neighbours"), [(0, True), (10, False)])
def test_faces_meeting_at_one_corner_are_not_neighbours(tilt, neighbours):
    """The second slab turned 10° about the z axis through the shared edge, then tilted
    ``tilt`` about the y axis through that edge's lower corner: tilted, the top faces still
    touch at that corner, but the edge's upper corners part by 1.7 mm, so the faces no longer
    meet along a seam and are two places."""
    first, second = _slab("a", -0.02, 0, 0), _slab("b", 0, 10, 0, tilt)
    a = _face_along(first, np.array([0, 1, 0]))
    b = _face_along(second, _turn(10, tilt) @ [0, 1, 0])
    assert (b in neighbouring_faces(Part("p", (first, second))).get(a, ())) is neighbours


@pytest.mark.parametrize(
    ("turn", "gap", "neighbours"),
    [(10, 0, True), (10, 0.4 * TOUCH_M, True), (10, 3 * TOUCH_M, False), (30, 0, False),
     (0, 0, False)],
)  # fmt: skip
def test_faces_are_neighbours_when_they_touch_and_turn_a_little(turn, gap, neighbours):
    """Two slabs side by side, the second turned: their top (+y) faces are neighbours only
    when they touch (within TOUCH_M) and turn by more than a degree and at most 25°."""
    first, second = _slab("a", -0.02, 0, 0), _slab("b", 0, turn, gap)
    a = _face_along(first, np.array([0, 1, 0]))
    b = _face_along(second, _turn(turn) @ [0, 1, 0])
    near = neighbouring_faces(Part("p", (first, second)))
    assert (b in near.get(a, ())) is neighbours
    assert (a in near.get(b, ())) is neighbours


def test_a_neighbours_contact_counts_as_the_contact_sought_but_not_as_the_goal():
    wall8, wall9, floor = (ContactPair(f"wall{k}/inner", "peg/f0") for k in (8, 9, 10))
    goal = ContactPair("floor/top", "peg/bottom")
    near = NearContacts({"wall8/inner": frozenset({"wall9/inner"}),
                         "wall9/inner": frozenset({"wall8/inner"}),
                         "floor/top": frozenset({"ring/top"})}, {}, goal)  # fmt: skip
    assert near.around(wall8) == {wall8, wall9}
    assert near.around(goal) == {goal} and near.around(FREE) == {FREE}
    assert near.accept([wall8, goal]) == {wall8, wall9, goal}
    schedule = [FREE, wall8, goal]
    split = belief_with([{wall8}, {wall9}, {wall8}])
    assert furthest_common(schedule, split, near) == wall8
    assert furthest_common(schedule, split) == FREE  # without neighbours: not made
    assert already_made(split, schedule, near) and not already_made(split, schedule)
    off_goal = belief_with([{goal}, {ContactPair("ring/top", "peg/bottom")}])
    assert furthest_common(schedule, off_goal, near) == FREE
    assert floor not in near.around(wall8)


def test_the_planner_takes_a_neighbours_contact_as_made(peg):
    """The outer loop reads the search's neighbours: particles on a neighbour of the next
    contact's face have made it (no motion, no rollout)."""
    from dataclasses import replace

    from bilba_dist.belief.particles import initial_belief
    from bilba_dist.modes.schedule import belief_graph
    from bilba_dist.planning.bilba import _next_contact, contact_search
    from bilba_dist.planning.evaluate import Evaluator
    from bilba_dist.planning.result import PlanResult
    from bilba_dist.workers.rollout_worker import RolloutWorker

    worker = RolloutWorker(peg)
    evaluator = Evaluator(worker)
    search = contact_search(peg, evaluator, "bilba-fixed", deadline=float("inf"))
    assert search.near.env == {} and search.near.goal == peg.goal  # the peg has none
    graph, _ = belief_graph(peg, initial_belief(peg), peg.X_WG0, search.cache)
    schedule = graph.schedule()
    target = schedule[1]
    beside = ContactPair("beside/f0", target.manip)
    belief = belief_with([{beside}, {beside}, {beside}])
    assert not already_made(belief, schedule)  # on its own, "beside" is another contact
    near = NearContacts({target.env: frozenset({"beside/f0"})}, {}, peg.goal)
    search = replace(search, near=near)
    rng = np.random.default_rng(0)
    result = PlanResult(False, "", [], "bilba-fixed", 0)
    followed, outcome = _next_contact(graph, belief, FREE, search, rng, 0, result)
    assert outcome.success and outcome.steps == [] and evaluator.rollouts == 0
    assert followed == schedule
    worker.close()


def test_the_distance_from_a_face_is_exact_over_it_and_beyond_its_corners():
    """Against a dense sampling of a box's top face: points over it, off an edge, off a
    corner and below the plane (seeded)."""
    from bilba_dist.geometry.neighbours import _distance
    from bilba_dist.geometry.piece import box_piece

    box = box_piece("b", [0.02, 0.01, 0.01], pin.SE3.Identity())
    top = box.face("b/+z")
    rng = np.random.default_rng(3)
    points = rng.uniform([-0.02, -0.01, -0.01], [0.02, 0.01, 0.02], size=(200, 3))
    grid = np.stack(np.meshgrid(np.linspace(-0.01, 0.01, 401), np.linspace(-0.005, 0.005, 201)))
    samples = np.column_stack([grid[0].ravel(), grid[1].ravel(), np.full(grid[0].size, 0.005)])
    brute = np.array([np.linalg.norm(samples - p, axis=1).min() for p in points])
    assert np.allclose(_distance(points, box, top), brute, atol=4e-5)
