from itertools import pairwise

import networkx as nx
import numpy as np
import pytest
import yaml

from bilba_dist.belief.particles import initial_belief
from bilba_dist.cspace.slice import CObsSlice
from bilba_dist.errors import NoScheduleError
from bilba_dist.geometry.contact import FREE, ContactPair
from bilba_dist.modes.graph import (
    FAIL_CAP,
    GraphParams,
    build_mode_graph,
    uncertainty_direction,
)
from bilba_dist.modes.schedule import SliceCache, belief_graph
from bilba_dist.task.loader import load_task, with_planner
from tests.conftest import prism_task, write_task
from tests.test_task_files import run_cli

SETTINGS = ["grasp.pitch=2deg", "grasp.roll=2deg", "grasp.x=1cm", "env.y=1cm", "grasp.z=5mm"]


@pytest.mark.parametrize("setting", SETTINGS)
def test_peg_schedule_goes_through_a_chamfer_or_wall_to_the_hole_bottom(setting):
    task = load_task("peg-in-hole", [setting])
    _, schedule = belief_graph(task, initial_belief(task), task.X_WG0, SliceCache(task))
    assert schedule[0] == FREE
    assert schedule[-1] == ContactPair("floor/+z", "peg/-z")
    middle = schedule[1:-1]
    assert middle, "straight from free to the goal"
    assert any(m.env.split("/")[1] in ("chamfer", "inner") for m in middle)


def test_puzzle_goal_is_reached_only_from_inside_the_frame(puzzle):
    """Its neighbours are the slot's walls, the bar above the lower block and the rail: no
    face of the frame's outside (where the goal pair touches only edge to edge)."""
    graph, _ = belief_graph(puzzle, initial_belief(puzzle), puzzle.X_WG0, SliceCache(puzzle))
    assert set(graph.graph.predecessors(puzzle.goal)) == {
        ContactPair("bar_mx/+x", "neck/-x"),
        ContactPair("bar_px/-x", "neck/+x"),
        ContactPair("bar_py/-z", "lower/+z"),
        ContactPair("rail/+z", "lower/-z"),
    }


def test_puzzle_schedule_reaches_the_goal(puzzle):
    _, schedule = belief_graph(puzzle, initial_belief(puzzle), puzzle.X_WG0, SliceCache(puzzle))
    assert schedule[0] == FREE and schedule[-1] == puzzle.goal and len(schedule) >= 3


def test_schedule_is_deterministic(peg):
    first = belief_graph(peg, initial_belief(peg), peg.X_WG0, SliceCache(peg))[1]
    again = belief_graph(peg, initial_belief(peg), peg.X_WG0, SliceCache(peg))[1]
    assert first == again


def test_pruning_a_failed_edge_changes_the_schedule(peg):
    graph, schedule = belief_graph(peg, initial_belief(peg), peg.X_WG0, SliceCache(peg))
    seen = [schedule]
    for _ in range(5):
        graph.prune(schedule[0], schedule[1])
        assert not graph.graph.has_edge(schedule[0], schedule[1])
        try:
            schedule = graph.schedule()
        except NoScheduleError:
            break
        assert schedule not in seen
        seen.append(schedule)
    assert len(seen) >= 2


def test_restore_puts_back_every_pruned_edge(peg):
    graph, schedule = belief_graph(peg, initial_belief(peg), peg.X_WG0, SliceCache(peg))
    edges = dict(graph.graph.edges)
    for v in list(graph.graph.successors(FREE)):
        graph.prune(FREE, v)
    assert not graph.has_schedule()
    graph.restore()
    assert graph.has_schedule() and graph.schedule() == schedule
    assert dict(graph.graph.edges) == edges
    graph.restore()  # nothing pruned since: no change
    assert dict(graph.graph.edges) == edges


def test_pruning_every_edge_out_of_free_leaves_no_schedule(peg):
    graph, _ = belief_graph(peg, initial_belief(peg), peg.X_WG0, SliceCache(peg))
    for v in list(graph.graph.successors(FREE)):
        graph.prune(FREE, v)
    with pytest.raises(NoScheduleError, match="no path"):
        graph.schedule()


def test_free_connects_to_the_nearest_modes(peg):
    particles = initial_belief(peg)
    graph, _ = belief_graph(peg, particles, peg.X_WG0, SliceCache(peg))
    successors = list(graph.graph.successors(FREE))
    assert len(successors) == peg.spec.planner.n_free
    start = np.mean([p.X_OM(peg.X_WG0).translation for p in particles], axis=0)
    cslice = graph.cslice
    rng = np.random.default_rng(3)

    def distance(mode):
        points = np.concatenate([cslice.sample_mode(mode, 200, rng), cslice.mode_vertices(mode)])
        return np.linalg.norm(points - start, axis=1).min()

    chosen = max(distance(m) for m in successors)
    others = [distance(m) for m in graph.modes if m not in successors]
    assert chosen <= min(others) + 2e-3  # sampled distances: a few mm of slack


def test_edge_costs_prefer_normals_along_the_uncertainty():
    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    positions = np.array([p.X_OM(task.X_WG0).translation for p in initial_belief(task)])
    u = uncertainty_direction(positions)
    assert np.allclose(np.abs(u), [1, 0, 0])
    cslice = CObsSlice.build(task.environment, task.manipuland, np.eye(3))
    graph = build_mode_graph(cslice, positions, task.goal, GraphParams(delta_proj=0.1))
    for _, b, cost in graph.graph.edges(data="cost"):
        assert cost == pytest.approx(1 - 0.1 * abs(graph.normal(b)[0]))
    wall = ContactPair("wall_px/inner", "peg/+x")
    floor = task.goal
    assert graph.graph.edges[floor, wall]["cost"] == pytest.approx(0.9)
    assert graph.graph.edges[wall, floor]["cost"] == pytest.approx(1.0)


def test_no_spread_gives_no_preference():
    assert np.array_equal(uncertainty_direction(np.ones((3, 3))), np.zeros(3))


def test_modes_need_enough_vertices_but_the_goal_is_kept(peg):
    cslice = CObsSlice.build(peg.environment, peg.manipuland, np.eye(3))
    positions = np.zeros((1, 3))
    strict = build_mode_graph(cslice, positions, peg.goal, GraphParams(min_mode_vertices=1000))
    assert strict.modes == [peg.goal]


def test_dot_output_is_a_graph_with_every_edge(peg, tmp_path):
    graph, _ = belief_graph(peg, initial_belief(peg), peg.X_WG0, SliceCache(peg))
    dot = graph.to_dot()
    assert dot.startswith("digraph modes {") and dot.rstrip().endswith("}")
    assert dot.count(" -> ") == graph.graph.number_of_edges()


def test_slices_are_cached_by_rotation(peg):
    cache = SliceCache(peg)
    particles = initial_belief(peg)
    for p in particles:
        cache.get(p.X_OM(peg.X_WG0).rotation)
    cache.get(particles[0].X_OM(peg.X_WG0).rotation.copy())
    assert len(cache) == 3


def test_goal_missing_from_the_slice_is_no_schedule(peg):
    cslice = CObsSlice.build(peg.environment, peg.manipuland, np.eye(3))
    unreachable = ContactPair("floor/-z", "peg/+x")  # faces that never touch at this rotation
    graph = build_mode_graph(cslice, np.zeros((1, 3)), unreachable, GraphParams())
    with pytest.raises(NoScheduleError):
        graph.schedule()
    assert nx.is_directed(graph.graph)


def test_alternatives_are_the_shortest_schedules_through_different_next_modes():
    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    graph, schedule = belief_graph(task, initial_belief(task), task.X_WG0, SliceCache(task))
    alternatives = graph.alternatives(FREE, 3)
    assert alternatives[0] == schedule  # Dijkstra's own first
    assert len(alternatives) == 3 and len({s[1] for s in alternatives}) == 3
    for s in alternatives:
        assert s[0] == FREE and s[-1] == task.goal and len(s) == len(schedule)
        assert all(graph.graph.has_edge(a, b) for a, b in pairwise(s))
    assert graph.alternatives(FREE, 1) == [schedule]
    assert len(graph.alternatives(FREE, 10)) == 3  # free has only n_free = 3 edges
    graph.prune(FREE, schedule[1])
    assert graph.alternatives(FREE, 3)[0] == graph.schedule()
    assert schedule[1] not in [s[1] for s in graph.alternatives(FREE, 3)]


def test_alternatives_leave_out_longer_schedules(puzzle):
    """From free, the puzzle's bar tops lead to the goal in more hops than Dijkstra's."""
    graph, schedule = belief_graph(puzzle, initial_belief(puzzle), puzzle.X_WG0, SliceCache(puzzle))
    alternatives = graph.alternatives(FREE, 3)
    assert {len(s) for s in alternatives} == {len(schedule)}
    assert len(alternatives) < len(graph.graph[FREE])


def _puzzle_graph(puzzle, near: float):
    task = with_planner(puzzle, near_edge_m=near)
    graph, _ = belief_graph(task, initial_belief(task), task.X_WG0, SliceCache(task))
    return graph.graph


def test_near_edges_join_the_bar_top_to_the_slot_beside_it(puzzle):
    """On a bar's top, the part is 0.5 mm from the slot's far wall but shares no C-obs
    vertex with it: only near edges give the graph that step (the drop into the opening)."""
    top = ContactPair("bar_mx/+z", "foot_mx/-z")
    far_wall = ContactPair("bar_px/-x", "foot_px/+x")
    assert not _puzzle_graph(puzzle, 0.0).has_edge(top, far_wall)
    near = _puzzle_graph(puzzle, 0.6e-3)
    assert near.has_edge(top, far_wall) and near.has_edge(far_wall, top)
    assert not _puzzle_graph(puzzle, 0.4e-3).has_edge(top, far_wall)


def test_near_edges_only_add_to_the_vertex_graph(puzzle):
    plain, near = _puzzle_graph(puzzle, 0.0), _puzzle_graph(puzzle, 1e-3)
    assert set(plain.nodes) == set(near.nodes)
    assert set(plain.edges) < set(near.edges)
    assert set(_puzzle_graph(puzzle, 0.6e-3).edges) <= set(near.edges)


def _octagon(tmp_path, fail_cost: float):
    """A task of our own: an octagonal peg, 6 mm clearance, grasp.x ±1 cm."""
    return prism_task(tmp_path, 8, 0.006, {"fail_cost": fail_cost}, {"grasp.x": "1cm"})


@pytest.mark.parametrize("fail_cost", [0.0, 0.1])
def test_a_contact_that_failed_costs_more_up_to_its_cap(tmp_path, fail_cost):
    task = _octagon(tmp_path, fail_cost)
    graph, schedule = belief_graph(task, initial_belief(task), task.X_WG0, SliceCache(task))
    target = schedule[1]
    before = {u: graph.graph.edges[u, target]["cost"] for u in graph.graph.predecessors(target)}
    failed = next(u for u in before if u != FREE)
    graph.prune(failed, target)
    for u in graph.graph.predecessors(target):
        assert graph.graph.edges[u, target]["cost"] == pytest.approx(before[u] + fail_cost)
    for _ in range(FAIL_CAP + 1):  # more failures than count
        graph.prune(failed, target)
    assert graph.failures[target] == FAIL_CAP + 2 and len(before) > 2
    capped = {u: before[u] + fail_cost * FAIL_CAP for u in before}
    for u in graph.graph.predecessors(target):
        assert graph.graph.edges[u, target]["cost"] == pytest.approx(capped[u])
    positions = np.array([p.X_OM(task.X_WG0).translation for p in initial_belief(task)])
    graph.restore()
    graph.reweight(positions)  # the failures outlive the edges' return
    assert graph.graph.has_edge(failed, target)
    for u in before:
        assert graph.graph.edges[u, target]["cost"] == pytest.approx(capped[u])


def test_after_a_failure_an_equally_short_schedule_avoids_the_contact(tmp_path):
    """The failed contact is entered from elsewhere: with ``fail_cost`` the schedule from
    free goes another way of as many hops; without, it keeps the contact."""
    schedules = {}
    for fail_cost in (0.0, 0.1):
        task = _octagon(tmp_path, fail_cost)
        graph, schedule = belief_graph(task, initial_belief(task), task.X_WG0, SliceCache(task))
        assert len(graph.alternatives(FREE, 3)) > 1
        other = next(u for u in graph.graph.predecessors(schedule[1]) if u != FREE)
        graph.prune(other, schedule[1])
        schedules[fail_cost] = schedule, graph.schedule()
    (first, again), (first_c, avoided) = schedules[0.0], schedules[0.1]
    assert first == first_c and again == first
    assert avoided[1] != first[1] and len(avoided) == len(first)


@pytest.mark.parametrize("fail_cost", [-0.1, 11, ".nan"])
def test_a_fail_cost_out_of_range_is_one_line(tmp_path, peg_yaml, fail_cost):
    text = yaml.safe_dump({**peg_yaml, "planner": {"fail_cost": 0.5}})
    path = write_task(tmp_path, text.replace("fail_cost: 0.5", f"fail_cost: {fail_cost}"))
    result = run_cli("plan", str(path), "--workers", "0", "--no-log")
    assert result.exit_code == 2 and "fail_cost" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_part_that_cannot_reach_its_goal_face_is_one_line_saying_why(tmp_path):
    """A square peg 2 mm wider than its hole (as a hole's convex pieces that fill its
    clearance would make it): `bilba graph` says the goal cannot be touched, exit 2."""
    from tests.conftest import prism_file
    from tests.test_task_files import run_cli

    result = run_cli("graph", str(prism_file(tmp_path, 4, -0.002)))
    assert result.exit_code == 2, result.output
    (line,) = result.stderr.splitlines()
    assert "the goal contact (floor/top, peg/bottom) does not occur" in line
    assert "cannot touch that face without entering another piece" in line
