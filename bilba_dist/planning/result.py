"""What a planner returns: always a result that says whether it worked and why not."""

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from bilba_dist.belief.state import Belief
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.planning.diagnosis import Blocked

if TYPE_CHECKING:
    from bilba_dist.task.loader import Task


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
class Verification:
    """What the returned plan did on its verification particles."""

    particles: int = 0  # verification particles it was replayed on
    #: Fraction in the goal by friction scale ("0.5", "1", "1.5"), or "all" when the
    #: uncertainty has a friction axis (its particles draw their own)
    held: dict[str, float] = field(default_factory=dict)
    passed: bool = True
    plans: int = 0  # plans verified in the search, this one included
    #: The uncertain-axis offsets of the particles it lost, each once (friction twins merged)
    lost: list[dict[str, float]] = field(default_factory=list)

    def text(self) -> str:
        """E.g. "1 offset × 3 frictions (3 particles), in the goal 1.00 at 0.5 μ, …": how
        many offsets a plan was replayed on (a quick plan's few, `verify_share`) is what a
        reader weighs, not the particles."""
        held = ", ".join(
            f"{v:.2f}" + ("" if k == "all" else f" at {k} μ") for k, v in self.held.items()
        )
        frictions = 0 if "all" in self.held else len(self.held)
        if frictions == 0:
            on = f"{self.particles} particles"
        else:
            offsets = self.particles // frictions
            on = f"{offsets} offset{'' if offsets == 1 else 's'}"
            if frictions > 1:
                on += f" × {frictions} frictions ({self.particles} particles)"
        return f"{on}, in the goal {held}"

    def holds_better_than(self, other: "Verification") -> bool:
        """Whether this plan held better than ``other`` on its verification: a higher worst
        fraction (over the frictions), ties broken by the mean one, so of two plans that
        each lose one offset at 0.5 μ the one that also loses it at 1 μ is not kept."""
        mine, theirs = list(self.held.values()), list(other.held.values())
        return (min(mine), sum(mine) / len(mine)) > (min(theirs), sum(theirs) / len(theirs))


@dataclass
class PlanResult:
    success: bool
    reason: str  # "" on success (but a plan that failed verification); else why not
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
    #: The returned plan's verification (None: off, or no plan); when the search ran out of
    #: time with no plan that passed, the plan that held best, ``passed`` false.
    verification: Verification | None = None
    #: Seconds to the first plan found by the search that returned it (before its
    #: verification; 0: none yet), from the start of planning (a restart's search included).
    first_plan_s: float = 0.0
    #: The best plan that failed verification so far, for a search that runs out of time.
    unverified: tuple[list[PlannedMotion], Verification] | None = None
    #: Whether the search ended at its deadline (the timeout, or verify_effort's).
    timed_out: bool = False
    #: The task planned on: the one given, or it on more particles a bounded axis when the
    #: first plan failed verification between them (planning/bilba.py ``plan``); None from
    #: a planner that does not say.
    task: "Task | None" = None
    #: After such a restart: the contact of the first plan, and its motions that made it,
    #: that the new particles made too, where the restarted search went on (None: from the
    #: start).
    resumed: tuple[ContactPair, int] | None = None

    def outcome(self) -> dict[str, Any]:
        """Success, why not, time, rollouts and whether the plan passed verification (None:
        no plan, or verification off): the log's /outcome and a batch record."""
        check = self.verification
        return {
            "success": self.success,
            "reason": self.reason,
            "planning_time_s": self.planning_time_s,
            "rollouts": self.rollouts,
            "verified": check.passed if check is not None and self.success else None,
        }


def verification_json(verification: Verification) -> dict[str, Any]:
    """A verification as the log's /verify and the plan file's ``verification``: the held
    fractions keyed by friction scale ("0.5") or "all"."""
    return {
        "particles": verification.particles,
        "held": dict(verification.held),
        "passed": verification.passed,
        "plan": verification.plans,
    }
