"""The state every particle starts in: the robot at the task's start pose."""

from collections.abc import Sequence

import numpy as np

from bilba_dist.belief.particles import Particle
from bilba_dist.belief.state import Belief
from bilba_dist.errors import TaskError, UnreachableError
from bilba_dist.robot.drivers import planning_arms
from bilba_dist.robot.panda import Q_CENTRE, PandaModel
from bilba_dist.rollout import ParticleState
from bilba_dist.task.loader import Task

#: A part this far inside the environment at the start counts as penetrating [m] (resting
#: contact in PyBullet sits ~1e-5 m deep; the C-obs is exact to 1e-9 m).
START_CONTACT_TOL_M = 1e-4


#: Joint postures, drawn uniformly within the limits (seeded), that the start IK tries
#: after the task's own seed: damped least squares from the centre posture stalls on some
#: reachable hands (pointing sideways, turned near the wrist's limit).
START_SEEDS = 16


def start_joints(task: Task) -> np.ndarray:
    """The joints that put the hand at ``X_WG0``, within the joint limits of the arm the
    task's driver drives: IK from the task's ``robot_start.joints`` (or the centre posture),
    else from each of START_SEEDS seeded postures in turn."""
    joints = task.spec.robot_start.joints
    first = np.array(joints) if joints is not None else Q_CENTRE
    arms = planning_arms(task.spec.planner.driver)
    key = task.X_WG0.homogeneous.tobytes() + first.tobytes() + repr(arms).encode()
    if key not in _START_JOINTS:  # once per process: every particle starts there
        _START_JOINTS[key] = _start_joints(task, arms, first)
    return _START_JOINTS[key].copy()


_START_JOINTS: dict[bytes, np.ndarray] = {}


def _start_joints(task: Task, arms: tuple[str, ...], first: np.ndarray) -> np.ndarray:
    model = PandaModel(arms=arms)
    rng = np.random.default_rng(0)
    seeds = [first, *(rng.uniform(model.lower, model.upper) for _ in range(START_SEEDS))]
    nearest, at_limit = float("inf"), None
    for seed in seeds:
        try:
            q = model.ik(task.X_WG0, seed)
        except UnreachableError as exc:
            nearest = min(nearest, exc.residual)
            continue
        hit = model.limit_reached(q, q)
        if hit is None:
            return q
        at_limit = at_limit if at_limit is not None else hit[0]
    xyz = ", ".join(f"{v:.4g}" for v in task.X_WG0.translation)
    if at_limit is not None:  # a real arm would stop with a reflex before the first motion
        raise TaskError(
            f"{task.source}: robot_start: the hand at [{xyz}] m turned as given is reached "
            f"only with joint {at_limit} at its limit (from {len(seeds)} starting postures), "
            "where a Franka stops with a reflex; move or turn the start"
        )
    driver = task.spec.planner.driver
    arm = " and ".join(f"{a}'s" for a in arms)
    arm += f" (planner.driver {driver})" if driver != "none" else ""
    raise TaskError(
        f"{task.source}: robot_start: no IK solution within the {arm} joint limits puts the "
        f"hand at [{xyz}] m turned as given (from {len(seeds)} starting postures; the nearest "
        f"{nearest:.2g} off, m and rad): out of reach, or past a joint limit — a hand turned "
        "about its own axis can be past the wrist's; move or turn the start, or give "
        "robot_start.joints near it"
    )


def start_state(task: Task, particle: Particle) -> ParticleState:
    """The particle at rest with the gripper at ``X_WG0`` (joints: `start_joints`)."""
    return ParticleState(X_WM=task.X_WG0 * particle.X_GM, q=start_joints(task))


def start_belief(task: Task, particles: Sequence[Particle]) -> Belief:
    """Every particle at rest at the start pose, free of contact."""
    return Belief(
        tuple(particles),
        tuple(start_state(task, p) for p in particles),
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
