"""The state every particle starts in: the robot at the task's start pose."""

from collections.abc import Sequence

import numpy as np

from bilba_dist.belief.particles import Particle
from bilba_dist.belief.state import Belief
from bilba_dist.errors import TaskError
from bilba_dist.robot.panda import Q_CENTRE, PandaModel
from bilba_dist.rollout import ParticleState
from bilba_dist.task.loader import Task

#: A part this far inside the environment at the start counts as penetrating [m] (resting
#: contact in PyBullet sits ~1e-5 m deep; the C-obs is exact to 1e-9 m).
START_CONTACT_TOL_M = 1e-4


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


def check_start_free(task: Task, particles: Sequence[Particle]) -> None:
    """Raise a TaskError naming the first particle whose part already penetrates the
    environment at the start pose, and how deep (from the C-obs slice at its rotation:
    the depth inside the deepest piece pair is the shortest move that frees it)."""
    from bilba_dist.cspace.slice import CObsSlice

    for i, particle in enumerate(particles):
        X_OM = particle.X_OM(task.X_WG0)
        cobs = CObsSlice.build(task.environment, task.manipuland, X_OM.rotation)
        slack = cobs.stack.slack(X_OM.translation)[0]
        deepest = int(np.argmin(slack))
        if slack[deepest] < -START_CONTACT_TOL_M:
            pair = cobs.polytopes[deepest]
            offsets = ", ".join(f"{k}={v:+.4g}" for k, v in particle.offsets.items()) or "nominal"
            raise TaskError(
                f"particle {i} ({offsets}): the part starts {-slack[deepest] * 1000:.3g} mm "
                f"inside the environment (pieces {pair.manip_piece} in {pair.env_piece}); "
                "start the robot clear of the parts, or pass --allow-start-contact"
            )
