"""Replaying a plan: run its motions, in order, on every particle of a belief."""

from collections.abc import Sequence

from bilba_dist.belief.particles import Particle
from bilba_dist.belief.start import start_belief
from bilba_dist.belief.state import Belief
from bilba_dist.planning.result import PlannedMotion
from bilba_dist.rollout import Motion, RolloutBackend, RolloutRequest
from bilba_dist.task.loader import Task


def replay(
    task: Task,
    motions: Sequence[PlannedMotion],
    particles: Sequence[Particle],
    backend: RolloutBackend,
) -> Belief:
    """The belief after the plan, from every particle's start state (one batch per motion)."""
    belief = start_belief(task, particles)
    for planned in motions:
        motion = Motion(planned.K, planned.G_d, planned.timeout_s)
        requests = [
            RolloutRequest(p, s, motion)
            for p, s in zip(belief.particles, belief.states, strict=True)
        ]
        belief = belief.after(backend.simulate(requests))
    return belief


def success_fraction(belief: Belief, task: Task) -> float:
    return sum(task.goal in c for c in belief.contacts) / len(belief)
