"""`bilba execute`: a plan run in simulation as a driver would run it, motion by motion.

With a driver each motion's stiffness is the one `bilba export` gives that driver (fitted to
its form and limits, `plans.export.driver_motions`), the setpoint ramps along the hand's
straight line (every exported script ramps the EE pose), and a driver that cannot bound the
spring wrench runs without the planner's clip. Without one, the plan runs as planned.
"""

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from bilba_dist.belief.particles import Particle, initial_belief, make_particle
from bilba_dist.belief.state import Belief
from bilba_dist.errors import BilbaError
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.neighbours import NearContacts
from bilba_dist.planning.result import PlannedMotion
from bilba_dist.plans.file import PlanFile
from bilba_dist.plans.loads import Load, load_of
from bilba_dist.plans.replay import transitions
from bilba_dist.robot.drivers import DEFAULT_EE_OFFSET_M
from bilba_dist.rollout import RolloutBackend
from bilba_dist.task.loader import Task, parse_axis_items


def parse_particle(text: str) -> dict[str, float]:
    """``"grasp.x=3mm env.y=-1mm"`` (or comma-separated) → signed offsets in SI units."""
    items = text.replace(",", " ").split()
    if not items:
        raise BilbaError("--particle: give at least one AXIS=VALUE, e.g. grasp.x=3mm")
    return parse_axis_items(items, "--particle", "grasp.x=3mm")


def particles_for(task: Task, extra: Sequence[dict[str, float]]) -> tuple[Particle, ...]:
    """The plan's planning particles, then one per ``--particle``."""
    return initial_belief(task) + tuple(make_particle(task, o) for o in extra)


@dataclass(frozen=True)
class Step:
    """One motion's outcome: which particles are in the contact it was meant to reach."""

    intended: ContactPair
    reached: list[bool]
    contacts: list[str]  # "is in CONTACTS" (or "stopped: WHY") per particle
    load: Load  # the spring's peaks over the particles (plans/loads.py)
    arm_touches: dict[str, list[int]]  # environment piece -> particles whose arm touches it


def describe(particle: Particle) -> str:
    offsets = ", ".join(f"{k}={v:+.4g}" for k, v in particle.offsets.items() if v)
    return offsets or "nominal"


def steps_of(
    task: Task,
    motions: Sequence[PlannedMotion],
    particles: Sequence[Particle],
    backend: RolloutBackend,
) -> Iterator[tuple[Step, Belief]]:
    near = NearContacts.of(task.environment, task.manipuland, task.goal)
    for planned, (belief, results) in zip(
        motions, transitions(task, motions, particles, backend), strict=False
    ):
        reached = [bool(c & near.around(planned.contact)) for c in belief.contacts]
        shown = [
            f"stopped: {s.stopped}, where a Franka halts with a reflex"
            if s.stopped
            else "is in " + (", ".join(sorted(map(str, c))) or "free")
            for s, c in zip(belief.states, belief.contacts, strict=True)
        ]
        touches: dict[str, list[int]] = {}
        for i, state in enumerate(belief.states):
            for piece in state.arm_touches:
                touches.setdefault(piece, []).append(i)
        yield Step(planned.contact, reached, shown, load_of(results), touches), belief


def final_misses(task: Task, belief: Belief) -> list[int]:
    """Indices of the particles not in the goal contact at the end."""
    return [i for i, c in enumerate(belief.contacts) if task.goal not in c]


def ee_offset_of(plan: PlanFile, given: tuple[float, ...] | None) -> np.ndarray:
    """``--ee-offset`` (one number: along the hand's z; or x y z) or the plan's own."""
    if given is not None:
        values = list(given)
        return np.array([0.0, 0.0, values[0]] if len(values) == 1 else values, dtype=float)
    robot = plan.document.get("robot") or {}
    return np.array(robot.get("ee_offset_m", [0.0, 0.0, DEFAULT_EE_OFFSET_M]), dtype=float)
