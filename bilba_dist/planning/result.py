"""What a planner returns: always a result that says whether it worked and why not."""

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from bilba_dist.belief.state import Belief
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.planning.diagnosis import Blocked


@dataclass(frozen=True)
class PlannedMotion:
    """One motion of a plan: stiffness ``K`` (6×6, rotation first, world axes), gripper
    setpoint ``G_d`` (``X_WG``), joint setpoint ``q_d`` (IK of G_d), the contact it is meant to
    reach and the belief score it reached in simulation."""

    K: np.ndarray
    G_d: pin.SE3
    q_d: np.ndarray
    timeout_s: float
    contact: ContactPair
    score: float


@dataclass
class PlanResult:
    success: bool
    reason: str  # "" on success; else why: no schedule, edges pruned, timeout, ...
    motions: list[PlannedMotion]
    planner: str
    seed: int
    planning_time_s: float = 0.0
    rollouts: int = 0
    attempts: int = 0
    rounds: int = 1  # of pruning (planner.prune_rounds)
    schedules: list[list[ContactPair]] = field(default_factory=list)
    pruned: list[tuple[ContactPair, ContactPair]] = field(default_factory=list)
    final_belief: Belief | None = None
    #: Each failed attempt at a contact, for the reason given when no plan is found.
    blocked: list[Blocked] = field(default_factory=list)

    def outcome(self) -> dict[str, Any]:
        """Success, why not, time and rollouts: the log's /outcome and a batch record."""
        return {
            "success": self.success,
            "reason": self.reason,
            "planning_time_s": self.planning_time_s,
            "rollouts": self.rollouts,
        }
