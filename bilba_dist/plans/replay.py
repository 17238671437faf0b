"""Replaying a plan: run its motions, in order, on every particle of a belief."""

from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from bilba_dist.belief.particles import Particle, initial_belief, make_particle, random_offsets
from bilba_dist.belief.start import start_belief
from bilba_dist.belief.state import Belief
from bilba_dist.planning.result import PlannedMotion
from bilba_dist.rollout import Motion, RolloutBackend, RolloutRequest
from bilba_dist.task.loader import Task


def run_motions(
    task: Task,
    motions: Sequence[PlannedMotion],
    particles: Sequence[Particle],
    backend: RolloutBackend,
) -> Iterator[Belief]:
    """The belief after each motion in turn, from every particle's start state (one batch
    per motion)."""
    belief = start_belief(task, particles)
    for planned in motions:
        motion = Motion(planned.K, planned.G_d, planned.timeout_s)
        requests = [
            RolloutRequest(p, s, motion)
            for p, s in zip(belief.particles, belief.states, strict=True)
        ]
        belief = belief.after(backend.simulate(requests))
        yield belief


def replay(
    task: Task,
    motions: Sequence[PlannedMotion],
    particles: Sequence[Particle],
    backend: RolloutBackend,
) -> Belief:
    """The belief after the plan, from every particle's start state."""
    beliefs = deque(run_motions(task, motions, particles, backend), maxlen=1)
    return beliefs[0] if beliefs else start_belief(task, particles)


def success_fraction(belief: Belief, task: Task) -> float:
    return sum(task.goal in c for c in belief.contacts) / len(belief)


@dataclass(frozen=True)
class Validation:
    """Fractions of particles that end in the goal contact after a plan."""

    planning: float  # of the planning belief
    n_planning: int
    held_out: float | None  # of the held-out particles (None when there were none)
    n_held_out: int


def validate_plan(
    task: Task,
    motions: Sequence[PlannedMotion],
    backend: RolloutBackend,
    held_out: int = 0,
    seed: int = 0,
) -> Validation:
    """Replay ``motions`` on the task's planning belief and on ``held_out`` more particles
    drawn uniformly inside its uncertainty ellipsoid (seeded), in one batch per motion."""
    planning = initial_belief(task)
    bounds = {k: v for k, v in task.spec.uncertainty.items() if v > 0}
    extra = tuple(make_particle(task, o) for o in random_offsets(bounds, held_out, seed))
    final = replay(task, motions, planning + extra, backend)
    n = len(planning)
    return Validation(
        planning=success_fraction(final[:n], task),
        n_planning=n,
        held_out=success_fraction(final[n:], task) if held_out else None,
        n_held_out=held_out,
    )
