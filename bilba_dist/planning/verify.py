"""Verifying a plan before it is returned (``planner.verify_particles``, on by default).

Robust acceptance checks each motion on the planning particles' twins at other frictions,
but not at offsets between the planning particles, where a part on sub-millimetre gaps may
drop either way (docs/planner.md, Verification). So a plan found is first replayed on
particles it was not planned on: offsets spread evenly inside the bounds (a fixed,
stratified draw: one in each cell of an even partition of the bounds), each at
friction x(1 - f), x1 and x(1 + f). A plan that brings fewer than ``verify_min`` of them to
the goal at some friction is not returned: up to ``ADD_CHECKS`` of the particles it failed
become check particles, and the search goes on from the last contact of the plan that
they made too (planning/bilba.py, ``resume_at``), or starts over. The replay may spend at
most ``verify_share`` of the rollouts the search has spent so far, so an easy plan gets
fewer particles (at least one offset) and a hard one all of them."""

from dataclasses import replace

from bilba_dist.belief.particles import Particle, make_particle, stratified_offsets
from bilba_dist.belief.start import start_belief
from bilba_dist.belief.state import Belief
from bilba_dist.planning.result import PlannedMotion, Verification
from bilba_dist.rollout import RolloutBackend
from bilba_dist.task.loader import Task
from bilba_dist.task.schema import (
    MAX_PARTICLES,
    AxisBelief,
    ExtremalRandomBelief,
    axis_unit,
    particle_count,
)
from bilba_dist.task.timestep import verify_timestep

#: The verification draw: neither the check particles' (7) nor `bilba validate`'s usual
#: held-out draws (0, 1), so a held-out replay of a verified plan stays independent.
VERIFY_SEED = 3

#: How many of the particles a failed plan lost become check particles of the next search.
ADD_CHECKS = 2


def verify_particles(task: Task, friction_margin: float) -> tuple[Particle, ...]:
    """``planner.verify_particles`` offsets spread evenly inside the bounds (a stratified
    draw, belief/particles.py ``stratified_offsets``), each at friction
    x(1 - f), x1 and x(1 + f) (x1 alone when f, robust acceptance's margin, is 0); in the
    order of the offsets, so a prefix is the first offsets at every friction. Simulated at
    the fine step where the task plans at a coarser one (task/timestep.py): the ones a plan
    loses become check particles, and stay at that step."""
    f = friction_margin
    drawn = stratified_offsets(
        task.spec.bounds, task.spec.planner.verify_particles, seed=VERIFY_SEED
    )
    step = verify_timestep(task.timestep_s)
    return tuple(
        replace(
            make_particle(task, {**o, "friction": scale} if f > 0 else o),
            timestep_s=step if step != task.timestep_s else None,
        )
        for o in drawn
        for scale in ((-f, 0.0, f) if f > 0 else (0.0,))
    )


def raised_points(task: Task) -> int | None:
    """The particles a bounded axis a search starts again on when its first plan fails
    verification on offsets between its particles (``between``): two more than the axis
    belief's default, when the task leaves its points to the default and verifies its plans.
    None for a belief the task file chose (planned on as it is), the authors' preset (no
    verification) or one over MAX_PARTICLES."""
    belief, bounds = task.spec.belief, task.spec.bounds
    if not isinstance(belief, AxisBelief) or "points" in belief.model_fields_set:
        return None
    if not bounds or task.spec.planner.verify_particles == 0:
        return None
    points = belief.points + 2
    return (
        points if particle_count(AxisBelief(points=points), len(bounds)) <= MAX_PARTICLES else None
    )


def between(task: Task, lost: list[Particle]) -> bool:
    """Whether every particle of ``lost`` lies inside the bounds (offsets on the uncertain
    axes only, each within its bound; a robust-acceptance twin's friction aside): the
    offsets more particles a bounded axis would plan on."""
    bounds = task.spec.bounds
    return all(
        all(abs(v) <= bounds.get(k, 0.0) * (1 + 1e-9) for k, v in pose_offsets(task, p).items())
        for p in lost
    )


def pose_offsets(task: Task, particle: Particle) -> dict[str, float]:
    """``particle``'s offsets on the uncertain axes (0 where it has none) and on any other
    it was given, but not a robust-acceptance twin's friction (friction is then no axis)."""
    bounded = task.spec.bounds
    offsets = {k: particle.offsets.get(k, 0.0) for k in bounded}
    return offsets | {
        k: v for k, v in particle.offsets.items() if k not in bounded and k != "friction"
    }


def within_budget(
    particles: tuple[Particle, ...], per_offset: int, motions: int, budget: float
) -> tuple[Particle, ...]:
    """The first offsets (``per_offset`` particles each) whose replay of ``motions``
    motions fits in ``budget`` rollouts; at least one offset."""
    offsets = max(1, int(budget // max(1, per_offset * motions)))
    return particles[: offsets * per_offset]


def verify(
    task: Task,
    motions: list[PlannedMotion],
    particles: tuple[Particle, ...],
    backend: RolloutBackend,
) -> tuple[Verification, list[Particle]]:
    """Replay ``motions`` on ``particles``: the fraction in the goal at each friction scale
    ("0.5", "1", "1.5"; "all" when the uncertainty has a friction axis, whose draw gives
    each particle its own), and the particles that are not."""
    from bilba_dist.plans.replay import replay

    by_friction = task.spec.uncertainty.get("friction", 0.0) <= 0
    final = replay(task, motions, particles, backend)
    ok = [task.goal in c for c in final.contacts]
    groups: dict[float, list[bool]] = {}
    for p, good in zip(particles, ok, strict=True):
        groups.setdefault(round(p.friction_scale, 6) if by_friction else 0.0, []).append(good)
    held = {
        f"{scale:g}" if by_friction else "all": sum(v) / len(v)
        for scale, v in sorted(groups.items())
    }
    passed = min(held.values()) >= task.spec.planner.verify_min
    failed = [p for p, good in zip(particles, ok, strict=True) if not good]
    lost: list[dict[str, float]] = []
    for p in failed:
        offsets = pose_offsets(task, p)
        if offsets not in lost:
            lost.append(offsets)
    return Verification(len(particles), held, passed, lost=lost), failed


def more_particles_hint(task: Task, verification: Verification) -> str:
    """For a plan that failed verification: the offsets it lost, which lie between (or
    beyond the spread of) the particles it was planned on, and how to plan on more of them
    (the task's belief generator's own knob) and see where it fails (``bilba validate
    --map``). Empty when nothing was lost."""
    if not verification.lost:
        return ""
    keys = list(dict.fromkeys(k for o in verification.lost for k in o))
    if len(keys) == 1:  # grasp.pitch -0.94, -0.60, +1.10 deg
        shown = [_number(keys[0], v) for v in sorted(o[keys[0]] for o in verification.lost)]
        lost = f"{keys[0]} {', '.join(shown[:4])}{' …' if len(shown) > 4 else ''} {_unit(keys[0])}"
    else:  # (grasp.x +3.1 mm, env.y -0.4 mm); …
        shown = [
            "(" + ", ".join(f"{k} {_number(k, v)} {_unit(k)}" for k, v in o.items()) + ")"
            for o in verification.lost
        ]
        lost = "; ".join(shown[:3]) + (" …" if len(shown) > 3 else "")
    belief = task.spec.belief
    if isinstance(belief, AxisBelief):
        knob = f"belief: {{points: {min(belief.points + 2, 51)}}} puts particles between them"
    elif isinstance(belief, ExtremalRandomBelief):
        knob = f"belief: {{random: {belief.random + 4}}} draws more of them"
    else:
        knob = "add offsets like these to belief.particles"
    mapped = " ".join(
        f"--map {k}={_number(k, v, sign='')}{_unit(k)}"
        for k, v in list(task.spec.bounds.items())[:2]
    )
    where = f"; `bilba validate PLAN {mapped}` shows where it fails" if mapped else ""
    return (
        f"it lost offsets it was not planned on ({lost}): try planning on more particles "
        f"({knob}){where}"
    )


def _unit(axis: str) -> str:
    return axis_unit(axis)[0]


def _number(axis: str, value: float, sign: str = "+") -> str:
    """An offset on ``axis`` in its unit (`axis_unit`), to 0.1 mm, 0.01° or 1 %."""
    unit, scale = axis_unit(axis)
    digits = {"%": 0, "mm": 1, "deg": 2}[unit]
    return f"{value * scale:{sign}.{digits}f}"


def with_more_checks(task: Task, b0: Belief, extra: list[Particle]) -> Belief:
    """``b0`` with ``extra`` particles added to its check particles, at their start."""
    check = b0.check.particles if b0.check is not None else ()
    return b0.with_check(start_belief(task, [*check, *extra]))
