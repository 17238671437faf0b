"""From a task and a belief to a contact schedule, with C-obs slices cached by rotation."""

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from bilba_dist.belief.particles import Particle
from bilba_dist.cspace.slice import CObsSlice
from bilba_dist.errors import NoScheduleError
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.pose import rotation_key
from bilba_dist.modes.graph import GraphParams, ModeGraph, build_mode_graph
from bilba_dist.task.loader import Task


class SliceCache:
    """C-obs slices of one task's parts, keyed by the manipuland's rotation."""

    def __init__(self, task: Task) -> None:
        self.task = task
        self._slices: dict[bytes, CObsSlice] = {}

    def get(self, R_OM: np.ndarray) -> CObsSlice:
        key = rotation_key(R_OM)
        if key not in self._slices:
            self._slices[key] = CObsSlice.build(self.task.environment, self.task.manipuland, R_OM)
        return self._slices[key]

    def __len__(self) -> int:
        return len(self._slices)


def graph_params(task: Task) -> GraphParams:
    p = task.spec.planner
    return GraphParams(p.n_free, p.delta_proj, p.min_mode_vertices, p.near_edge_m, p.fail_cost)


def belief_graph(
    task: Task, particles: Sequence[Particle], X_WG: pin.SE3, cache: SliceCache
) -> tuple[ModeGraph, list[ContactPair]]:
    """The mode graph and schedule of the first particle (in order) whose slice has a path
    from free to the goal — the paper's rule; one such particle is enough."""
    poses = [p.X_OM(X_WG) for p in particles]
    positions = np.array([X.translation for X in poses])
    reasons = []
    for X_OM in poses:
        graph = build_mode_graph(cache.get(X_OM.rotation), positions, task.goal, graph_params(task))
        try:
            return graph, graph.schedule()
        except NoScheduleError as exc:
            reasons.append(str(exc))
    # A part held turned against its hole (a fixture rotated in environment_pose, the hand
    # not) leaves no goal on the slice: say how the first particle's part is turned.
    rpy = np.rad2deg(pin.rpy.matrixToRpy(poses[0].rotation)) + 0.0  # no -0.0
    turned = ", ".join(f"{v:.1f}" for v in rpy)
    raise NoScheduleError(
        f"no particle's C-obs slice gives a contact schedule: {reasons[0]}; the first "
        f"particle's part is turned rpy [{turned}] deg in the environment's frame (robot_start "
        "and grasp against environment_pose)"
    )
