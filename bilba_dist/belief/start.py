"""The state every particle starts in: the robot at the task's start pose."""

from collections.abc import Sequence

import numpy as np

from bilba_dist.belief.particles import Particle, initial_belief, make_particle
from bilba_dist.belief.state import Belief
from bilba_dist.cspace.slice import CObsSlice
from bilba_dist.errors import TaskError, UnreachableError
from bilba_dist.geometry.pose import rotation_key
from bilba_dist.robot.drivers import planning_arms
from bilba_dist.robot.gripper import finger_opening, gripper_part
from bilba_dist.robot.panda import Q_CENTRE, PandaModel
from bilba_dist.rollout import ParticleState
from bilba_dist.task.loader import Task

#: A part this far inside the environment at the start counts as penetrating [m] (resting
#: contact in PyBullet sits ~1e-5 m deep; the C-obs is exact to 1e-9 m).
START_CONTACT_TOL_M = 1e-4
#: The gripper this far inside the environment counts as penetrating [m] (1 mm: the
#: simulated hulls are rounded at their edges, the C-obs hulls here are not).
GRIPPER_TOL_M = 1e-3
#: Points drawn on the goal's C-obs region to look for a pose the gripper fits at (seeded).
GOAL_SAMPLES = 256
#: Steps [m] and how many, backing the part out of its goal to say how far short of it the
#: gripper stops it.
GOAL_BACK_STEP_M = 1e-3
GOAL_BACK_STEPS = 300
#: ... from this many of the goal poses, those where the gripper is least deep.
GOAL_BACKED = 16


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


def _gripper_slice(task: Task, R_OH: np.ndarray) -> CObsSlice:
    """C-obs of the gripper against the environment with the hand turned by ``R_OH`` in the
    environment's frame, the fingers where they close on the nominal part: a point is a hand
    position there (the gripper: the hand, fingers and flange, as the simulated arm collides
    with them; each particle's fingers differ from the nominal's by its offsets' share of the
    part's width, a millimetre or two)."""
    key = (task.hash, rotation_key(R_OH))
    if key not in _GRIPPER_SLICES:
        if len(_GRIPPER_SLICES) >= GRIPPER_SLICES_KEPT:  # a batch loads task after task
            _GRIPPER_SLICES.clear()
        opening = finger_opening(task.manipuland, make_particle(task, {}).X_GM)
        _GRIPPER_SLICES[key] = CObsSlice.build(task.environment, gripper_part(opening), R_OH)
    return _GRIPPER_SLICES[key]


_GRIPPER_SLICES: dict[tuple[str, bytes], CObsSlice] = {}
GRIPPER_SLICES_KEPT = 16


def check_gripper_start(task: Task, particles: Sequence[Particle]) -> None:
    """Raise a TaskError naming the first particle whose gripper starts inside the
    environment (the hand is where the task says for every particle; the environment moves
    with the particles' env offsets)."""
    for i, particle in enumerate(particles):
        X_OH = particle.X_WO.inverse() * task.X_WG0
        hand = _gripper_slice(task, X_OH.rotation)
        slack = hand.stack.slack(X_OH.translation)[0]
        deepest = int(np.argmin(slack))
        if slack[deepest] < -GRIPPER_TOL_M:
            pair = hand.polytopes[deepest]
            raise TaskError(
                f"{task.source}: robot_start: the gripper starts {-slack[deepest] * 1000:.3g} "
                f"mm inside the environment ({pair.manip_piece} in {pair.env_piece}, particle "
                f"{i}); start the robot clear of the parts"
            )


def check_gripper_reaches_goal(task: Task) -> None:
    """Raise a TaskError where, wherever the nominal part touches its goal, the gripper is
    inside the environment: a part held too short for the depth of its hole, whose fingers
    meet the rim before the part meets the floor. It says how far short of the goal the
    gripper stops the part (at least: the simulated hull is a little larger). Nothing is
    said when the goal is missing from the slice (the mode graph says that)."""
    nominal = make_particle(task, {})
    X_OM = nominal.X_OM(task.X_WG0)
    part = CObsSlice.build(task.environment, task.manipuland, X_OM.rotation)
    on_goal = part.sample_mode(task.goal, GOAL_SAMPLES, np.random.default_rng(0))
    if len(on_goal) == 0:
        return
    X_MH = nominal.X_GM.inverse()
    hand = _gripper_slice(task, X_OM.rotation @ X_MH.rotation)
    on_goal = on_goal + X_OM.rotation @ X_MH.translation  # the hand's positions
    depth = -hand.stack.slack(on_goal).min(axis=1)
    if depth.min() <= GRIPPER_TOL_M:
        return
    # How far short of the goal: back the hand out along the goal's C-obs normal (the way
    # the part came in) until the gripper is clear, from the goal poses where it is least deep.
    normal = part.mode_triangles(task.goal)[1].mean(axis=0)
    normal /= np.linalg.norm(normal)
    nearest = on_goal[np.argsort(depth)[:GOAL_BACKED]]
    back = np.arange(1, GOAL_BACK_STEPS + 1) * GOAL_BACK_STEP_M
    path = (nearest[:, None, :] + back[None, :, None] * normal).reshape(-1, 3)
    free = (hand.stack.slack(path) >= -GRIPPER_TOL_M).all(axis=1).reshape(len(nearest), -1)
    short = np.where(free.any(axis=1), free.argmax(axis=1), len(back))
    best = int(np.argmin(short))
    pair = hand.polytopes[int(np.argmin(hand.stack.slack(nearest[best])[0]))]
    how_far = (
        f"at least {back[short[best]] * 1000:.0f} mm"
        if short[best] < len(back)
        else f"over {back[-1] * 1000:.0f} mm"
    )
    env, manip = task.goal
    raise TaskError(
        f"{task.source}: goal: the gripper meets the environment before the part reaches "
        f"{manip} on {env} ({pair.manip_piece} on {pair.env_piece}): it stops the part "
        f"{how_far} short of it; hold the part further out of the hand (grasp) by more than "
        "that, or leave the gripper room"
    )


def check_task(task: Task, allow_start_contact: bool = False) -> None:
    """What ``bilba plan`` checks before it plans, each a TaskError of one line: the start
    within reach of the arm (``start_joints``), every particle's part and gripper clear of
    the environment there (unless ``allow_start_contact``), and the gripper clear where the
    part meets its goal."""
    start_joints(task)
    if not allow_start_contact:
        particles = initial_belief(task)
        check_start_free(task, particles)
        check_gripper_start(task, particles)
    check_gripper_reaches_goal(task)
