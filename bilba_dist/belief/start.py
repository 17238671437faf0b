"""The state every particle starts in: the robot at the task's start pose."""

from collections.abc import Sequence

import numpy as np

from bilba_dist.belief.particles import Particle
from bilba_dist.belief.state import Belief
from bilba_dist.robot.panda import Q_CENTRE, PandaModel
from bilba_dist.rollout import ParticleState
from bilba_dist.task.loader import Task


def start_state(task: Task, particle: Particle, model: PandaModel | None = None) -> ParticleState:
    """The particle at rest with the gripper at ``X_WG0``: joints by IK from the task's
    ``robot_start.joints`` (or the centre posture) as the seed."""
    model = model or PandaModel()
    joints = task.spec.robot_start.joints
    seed = np.array(joints) if joints is not None else Q_CENTRE
    q = model.ik(task.X_WG0, seed)
    return ParticleState(X_WM=task.X_WG0 * particle.X_GM, q=q)


def start_belief(task: Task, particles: Sequence[Particle]) -> Belief:
    """Every particle at rest at the start pose, free of contact."""
    model = PandaModel()
    return Belief(
        tuple(particles),
        tuple(start_state(task, p, model) for p in particles),
        tuple(frozenset() for _ in particles),
    )
