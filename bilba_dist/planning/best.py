"""B-EST, the paper's baseline: a belief-space expansive tree with no contact schedule.

With the authors' settings (docs/reference-values.md): nodes are beliefs, binned on a
density grid over the belief's mean manipuland pose (10 bins per position axis over a
workspace box around the environment, 4 per quaternion component). To expand, pick a random
occupied cell, then a random node in it — sparse regions get expanded as often as dense ones
— and apply a random relative twist of the mean gripper pose (rotation ±0.02 rad,
translation ±0.04 m per axis) with the "stiff" gains for a timeout uniform in [0, 4] s. A
child is kept if its mean stays in the workspace; the search ends when every particle has
the goal contact.

Expansions go out ``batch`` at a time (nodes and controls drawn first, then all their
rollouts in one call), so Ray workers have work to share; the tree, and so the plan, depends
only on the seed.
"""

import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from bilba_dist.belief.particles import initial_belief
from bilba_dist.belief.start import start_belief
from bilba_dist.belief.state import Belief
from bilba_dist.planning.make_contact import Step, planned_motions
from bilba_dist.planning.recorder import NullRecorder, Recorder
from bilba_dist.planning.result import PlanResult
from bilba_dist.planning.stiffness import driver_fit
from bilba_dist.robot.drivers import planning_arms
from bilba_dist.robot.panda import PandaModel
from bilba_dist.rollout import Motion, RolloutBackend, RolloutRequest
from bilba_dist.task.loader import Task

STIFF = np.diag([60.0, 60.0, 60.0, 400.0, 400.0, 400.0])  # rotation first [N·m/rad, N/m]
TWIST_ROT = 0.02  # ± rad per axis
TWIST_TRANS = 0.04  # ± m per axis
MAX_TIMEOUT_S = 4.0
POSITION_BINS = 10
QUATERNION_BINS = 4
MARGIN = 0.05  # the workspace box: the environment's bounds grown by this much [m] ...
HEADROOM = 0.05  # ... and reaching this far above the start gripper height [m]


@dataclass
class Node:
    belief: Belief
    parent: int | None
    motion: Motion | None


def mean_pose(poses: list[pin.SE3]) -> pin.SE3:
    """Mean position; quaternion mean (signs aligned with the first, then normalised)."""
    quats = [pin.Quaternion(X.rotation).coeffs() for X in poses]
    quats = [q if np.dot(q, quats[0]) >= 0 else -q for q in quats]
    q = np.sum(quats, axis=0)
    rotation = pin.Quaternion(q / np.linalg.norm(q)).toRotationMatrix()
    return pin.SE3(rotation, np.mean([X.translation for X in poses], axis=0))


def workspace(task: Task) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners of the box the belief mean must stay in (world frame)."""
    vertices = np.vstack([p.vertices for p in task.environment.pieces])
    world = (task.X_WO.rotation @ vertices.T).T + task.X_WO.translation
    low, high = world.min(axis=0) - MARGIN, world.max(axis=0) + MARGIN
    high[2] = max(high[2], task.X_WG0.translation[2] + HEADROOM)
    return low, high


def plan_best(
    task: Task,
    backend: RolloutBackend,
    seed: int = 0,
    timeout_s: float | None = None,
    recorder: Recorder | None = None,
    on_rollouts: Callable[[int], None] = lambda n: None,
    batch: int = 8,
) -> PlanResult:
    clock = time.perf_counter
    started = clock()
    deadline = started + (timeout_s if timeout_s is not None else task.spec.planner.timeout_s)
    rng = np.random.default_rng(seed)
    recorder = recorder or NullRecorder()
    b0 = start_belief(task, initial_belief(task))
    low, high = workspace(task)
    nodes = [Node(b0, None, None)]
    cells: dict[tuple[int, ...], list[int]] = defaultdict(list)
    cells[_cell(b0, low, high)].append(0)
    result = PlanResult(False, "", [], "b-est", seed)
    goal = frozenset([task.goal])
    fit = driver_fit(task)
    while clock() < deadline:
        occupied = list(cells)
        chosen = []
        for _ in range(batch):
            cell = occupied[int(rng.integers(len(occupied)))]
            chosen.append(cells[cell][int(rng.integers(len(cells[cell])))])
        motions = [_control(nodes[k].belief, rng, fit) for k in chosen]
        requests = [
            RolloutRequest(nodes[k].belief.particles[i], nodes[k].belief.states[i], m)
            for k, m in zip(chosen, motions, strict=True)
            for i in range(len(nodes[k].belief))
        ]
        results = backend.simulate(requests)
        result.rollouts += len(results)
        on_rollouts(len(results))
        offset = 0
        for k, motion in zip(chosen, motions, strict=True):
            parent = nodes[k].belief
            child = parent.after(results[offset : offset + len(parent)])
            offset += len(parent)
            count = child.count(goal)
            recorder.transition(task.goal, motion, parent, child, child.score(goal), count, False)
            if not _inside(_mean_X_WM(child).translation, low, high):
                continue
            nodes.append(Node(child, k, motion))
            cells[_cell(child, low, high)].append(len(nodes) - 1)
            if count == len(child):
                _finish(result, nodes, len(nodes) - 1, task, recorder)
                result.planning_time_s = clock() - started
                return result
    result.reason = f"timeout after {clock() - started:.1f} s ({len(nodes)} tree nodes)"
    result.timed_out = True
    result.planning_time_s = clock() - started
    return result


def _mean_X_WM(belief: Belief) -> pin.SE3:
    return mean_pose([s.X_WM for s in belief.states])


def _control(
    belief: Belief, rng: np.random.Generator, fit: Callable[[np.ndarray, pin.SE3], np.ndarray]
) -> Motion:
    """A random relative twist of the mean gripper pose, stiff gains, random timeout."""
    grippers = [
        s.X_WM * p.X_GM.inverse() for p, s in zip(belief.particles, belief.states, strict=True)
    ]
    twist = np.concatenate(
        [rng.uniform(-TWIST_TRANS, TWIST_TRANS, 3), rng.uniform(-TWIST_ROT, TWIST_ROT, 3)]
    )
    G_d = mean_pose(grippers) * pin.exp6(pin.Motion(twist))
    return Motion(fit(STIFF, G_d), G_d, float(rng.uniform(0.0, MAX_TIMEOUT_S)))


def _cell(belief: Belief, low: np.ndarray, high: np.ndarray) -> tuple[int, ...]:
    X = _mean_X_WM(belief)
    scaled = (X.translation - low) / (high - low)
    position = np.clip((scaled * POSITION_BINS).astype(int), 0, POSITION_BINS - 1)
    q = pin.Quaternion(X.rotation).coeffs()
    q = q if q[3] >= 0 else -q
    quaternion = np.clip(((q + 1) / 2 * QUATERNION_BINS).astype(int), 0, QUATERNION_BINS - 1)
    return (*position.tolist(), *quaternion.tolist())


def _inside(p: np.ndarray, low: np.ndarray, high: np.ndarray) -> bool:
    return bool(np.all(p >= low) and np.all(p <= high))


def _finish(
    result: PlanResult, nodes: list[Node], leaf: int, task: Task, recorder: Recorder
) -> None:
    """The motions from the root to ``leaf`` are the plan."""

    goal = frozenset([task.goal])
    edges: list[tuple[int, int]] = []  # (parent, child), leaf first
    k = leaf
    while (parent := nodes[k].parent) is not None:
        edges.append((parent, k))
        k = parent
    steps = []
    for parent, child in reversed(edges):
        node = nodes[child]
        assert node.motion is not None
        score = node.belief.score(goal)
        steps.append(Step(node.motion, task.goal, score))
        recorder.transition(
            task.goal,
            node.motion,
            nodes[parent].belief,
            node.belief,
            score,
            node.belief.count(goal),
            True,
        )
    result.success, result.reason = True, ""
    result.motions = planned_motions(
        steps, nodes[0].belief, PandaModel(arms=planning_arms(task.spec.planner.driver))
    )
    result.final_belief = nodes[leaf].belief
