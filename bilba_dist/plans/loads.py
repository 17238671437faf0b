"""The load a plan puts on the robot, and the collision thresholds that let it run.

A Franka stops with a reflex (``cartesian_reflex``, ``joint_reflex``) when its estimate of
the external wrench at the EE, or of the external torque at a joint, passes the *upper*
collision threshold set with ``set_collision_behavior``; between the lower and the upper one
it only flags a contact. franka_control starts the robot at 20, 20, 18, 18, 16, 14, 12 N·m and
20, 20, 20 N, 25, 25, 25 N·m, lower and upper alike — the values users keep — and a compliant
plan that presses a part into its seat with 10–20 N sits right at them.

In contact and at rest the external wrench balances the impedance's spring, so the spring's
peak wrench over a motion, and its joint torques ``Jᵀ w``, are what the estimate will read
(impacts and the estimate's own error aside: hence the margin). `plan_loads` replays a plan
as a driver runs it, on the planning particles at the verification frictions, and keeps each
motion's peaks; `collision_thresholds` puts the upper thresholds at ``MARGIN`` times the
plan's peak where that is above the usual values, and leaves them there otherwise.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bilba_dist.belief.particles import Particle, make_particle
from bilba_dist.planning.result import PlannedMotion
from bilba_dist.plans.replay import transitions
from bilba_dist.rollout import RolloutBackend, RolloutResult
from bilba_dist.task.loader import Task

#: franka_control's initial collision thresholds (its collision_config), lower = upper
USUAL_TORQUE = (20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0)  # joints 1-7 [N·m]
USUAL_WRENCH = (20.0, 20.0, 20.0, 25.0, 25.0, 25.0)  # x, y, z [N]; about x, y, z [N·m]
MARGIN = 2.0  # upper threshold over the plan's peak, where the usual one is too low


@dataclass(frozen=True)
class Load:
    """One motion's peaks over the particles: the spring's wrench per base axis at the hand,
    translation first (N, then N·m), and its torque per joint [N·m]."""

    wrench: np.ndarray
    joint_torque: np.ndarray


def friction_twins(task: Task, particles: Sequence[Particle]) -> list[Particle]:
    """``particles`` at the task's friction and at ×(1 ∓ check_friction), as verification
    checks them (a task with friction as an uncertainty axis has its own spread already)."""
    from bilba_dist.planning.bilba import robust_friction

    f = robust_friction(task)
    if f == 0:
        return list(particles)
    return [
        make_particle(task, {**p.offsets, "friction": s}) for s in (-f, 0.0, f) for p in particles
    ]


def load_of(results: Sequence[RolloutResult]) -> Load:
    """The peaks of one motion's rollouts (zero where the model keeps none)."""
    wrench, torque = np.zeros(6), np.zeros(7)
    for r in results:
        if r.peak_wrench is not None and r.peak_joint_torque is not None:
            np.maximum(wrench, np.abs(r.peak_wrench), out=wrench)
            np.maximum(torque, np.abs(r.peak_joint_torque), out=torque)
    return Load(np.concatenate([wrench[3:], wrench[:3]]), torque)


def plan_loads(
    task: Task,
    motions: Sequence[PlannedMotion],
    particles: Sequence[Particle],
    backend: RolloutBackend,
) -> list[Load]:
    """Each motion's peak load over ``particles``, the motions run in order (Panda model)."""
    return [load_of(results) for _, results in transitions(task, motions, particles, backend)]


@dataclass(frozen=True)
class Thresholds:
    """Collision thresholds for ``set_collision_behavior``: joints 1-7 [N·m]; x, y, z [N]
    and about x, y, z [N·m]."""

    lower_torque: list[float]
    upper_torque: list[float]
    lower_wrench: list[float]
    upper_wrench: list[float]
    peak_torque: list[float]
    peak_wrench: list[float]

    @property
    def raised(self) -> bool:
        return self.upper_torque != list(USUAL_TORQUE) or self.upper_wrench != list(USUAL_WRENCH)


def collision_thresholds(loads: Sequence[Load]) -> Thresholds:
    """Upper thresholds at ``MARGIN`` × the plan's peak (whole N or N·m, rounded up) where
    that is above franka_control's usual values, else the usual values; lower at the usual."""
    torque = np.max([m.joint_torque for m in loads], axis=0) if loads else np.zeros(7)
    wrench = np.max([m.wrench for m in loads], axis=0) if loads else np.zeros(6)

    def upper(peaks: np.ndarray, usual: tuple[float, ...]) -> list[float]:
        return [max(u, float(math.ceil(MARGIN * p))) for p, u in zip(peaks, usual, strict=True)]

    return Thresholds(
        list(USUAL_TORQUE),
        upper(torque, USUAL_TORQUE),
        list(USUAL_WRENCH),
        upper(wrench, USUAL_WRENCH),
        [float(v) for v in torque],
        [float(v) for v in wrench],
    )


def threshold_note(t: Thresholds) -> str:
    """One line for the export's warnings when the plan needs more than the usual values."""
    names = ["x", "y", "z", "about x", "about y", "about z"] + [f"joint {j}" for j in range(1, 8)]
    units = ["N"] * 3 + ["N·m"] * 10
    peaks = t.peak_wrench + t.peak_torque
    usual = [*USUAL_WRENCH, *USUAL_TORQUE]
    upper = t.upper_wrench + t.upper_torque
    raised = [i for i in range(13) if upper[i] > usual[i]]
    pressed = ", ".join(f"{names[i]} {peaks[i]:.1f} {units[i]}" for i in raised)
    set_to = ", ".join(f"{names[i]} {upper[i]:g} {units[i]}" for i in raised)
    return (
        f"the plan loads the arm with up to {pressed} (the spring's peak in simulation, over "
        f"its particles and frictions): more than 1/{MARGIN:g} of franka_control's usual "
        f"collision thresholds, so the script raises those upper thresholds to {set_to}"
    )
