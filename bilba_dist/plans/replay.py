"""Replaying a plan: run its motions, in order, on every particle of a belief."""

from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bilba_dist.belief.particles import Particle, initial_belief, make_particle, random_offsets
from bilba_dist.belief.start import start_belief
from bilba_dist.belief.state import Belief
from bilba_dist.planning.result import PlannedMotion
from bilba_dist.rollout import Motion, RolloutBackend, RolloutResult, require_world
from bilba_dist.task.loader import Task
from bilba_dist.task.schema import axis_unit


def transitions(
    task: Task,
    motions: Sequence[PlannedMotion],
    particles: Sequence[Particle],
    backend: RolloutBackend,
) -> Iterator[tuple[Belief, list[RolloutResult]]]:
    """The belief after each motion in turn, with its rollouts, from every particle's start
    state (one batch per motion)."""
    require_world(task, backend)
    belief = start_belief(task, particles)
    for planned in motions:
        motion = Motion(planned.K, planned.G_d, planned.timeout_s)
        results = backend.simulate(belief.under(motion))
        belief = belief.after(results)
        yield belief, results


def run_motions(
    task: Task,
    motions: Sequence[PlannedMotion],
    particles: Sequence[Particle],
    backend: RolloutBackend,
) -> Iterator[Belief]:
    """The belief after each motion in turn, from every particle's start state."""
    return (belief for belief, _ in transitions(task, motions, particles, backend))


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
    extra = tuple(make_particle(task, o) for o in random_offsets(task.spec.bounds, held_out, seed))
    final = replay(task, motions, planning + extra, backend)
    n = len(planning)
    return Validation(
        planning=success_fraction(final[:n], task),
        n_planning=n,
        held_out=success_fraction(final[n:], task) if held_out else None,
        n_held_out=held_out,
    )


@dataclass(frozen=True)
class SuccessMap:
    """Success of a plan over a grid of one or two axes (offsets from nominal)."""

    axes: list[str]
    values: list[list[float]]  # the grid points of each axis [m|rad|1]
    success: np.ndarray  # 1/0 per grid point, shape (len(values[0]), len(values[1]))

    def csv(self) -> str:
        rows = [",".join([*self.axes, "success"])]
        for index in np.ndindex(self.success.shape):
            point = [f"{self.values[k][i]:.6g}" for k, i in enumerate(index)]
            rows.append(",".join([*point, str(int(self.success[index]))]))
        return "\n".join(rows) + "\n"

    def png(self, path: Path, title: str) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        def shown(axis: str, v: list[float]) -> tuple[list[float], str]:
            unit, scale = axis_unit(axis)
            label = f"{axis} offset [%]" if unit == "%" else f"{axis} [{unit}]"
            return [scale * x for x in v], label

        fig, ax = plt.subplots(figsize=(5.5, 4.5), dpi=120)
        x, x_label = shown(self.axes[0], self.values[0])
        grid = self.success if len(self.axes) == 2 else self.success[:, None]
        y, y_label = shown(self.axes[1], self.values[1]) if len(self.axes) == 2 else ([0.0], "")
        mesh = ax.pcolormesh(x, y, grid.T, cmap="RdYlGn", vmin=0, vmax=1, shading="nearest")
        ax.set_xlabel(x_label)
        ax.set_ylabel(y_label)
        if len(self.axes) == 1:
            ax.set_yticks([])
        ax.set_title(f"{title}\n{self.success.mean():.3f} of {self.success.size} reach the goal")
        fig.colorbar(mesh, ax=ax, ticks=[0, 1], label="reaches the goal")
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)


def success_map(
    task: Task,
    motions: Sequence[PlannedMotion],
    backend: RolloutBackend,
    bounds: dict[str, float],
    points: int,
) -> SuccessMap:
    """Replay ``motions`` on a grid of ``points`` per axis over ±bound of each of the one or
    two ``bounds`` axes (the others nominal), in one batch per motion."""
    axes = list(bounds)
    values = [np.linspace(-bounds[a], bounds[a], points).tolist() for a in axes]
    shape = tuple(len(v) for v in values)
    offsets = [
        {a: values[k][i] for k, (a, i) in enumerate(zip(axes, index, strict=True))}
        for index in np.ndindex(shape)
    ]
    particles = [make_particle(task, o) for o in offsets]
    final = replay(task, motions, particles, backend)
    reached = np.array([task.goal in c for c in final.contacts], dtype=float).reshape(shape)
    return SuccessMap(axes, values, reached)
