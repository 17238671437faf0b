"""BILBA's outer loop (paper Algorithm 1): follow the contact schedule from Dijkstra, make
each contact with MakeContact, replan after each contact reached, prune an edge that failed,
and go on from the contact reached while a schedule from it is left (``keep_reached``; the
paper starts over from the initial belief, as we do when none is), up to ``n_attempts`` or
the timeout. A plan that fails verification is repaired the same way: the search goes on
from the last of its contacts that the particles it lost made too (``resume_at``), and a
search restarted on more particles goes on from the last contact of the failed plan that
they all made (``restart_at``)."""

import itertools
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from bilba_dist.belief.particles import Particle, initial_belief, make_particle, random_offsets
from bilba_dist.belief.start import start_belief
from bilba_dist.belief.state import Belief
from bilba_dist.errors import NoScheduleError
from bilba_dist.geometry.contact import FREE, ContactPair
from bilba_dist.geometry.neighbours import NearContacts
from bilba_dist.modes.graph import ModeGraph
from bilba_dist.modes.schedule import SliceCache, belief_graph
from bilba_dist.planning.best import plan_best
from bilba_dist.planning.diagnosis import blocked, explain
from bilba_dist.planning.evaluate import Evaluator
from bilba_dist.planning.gp import GPParams
from bilba_dist.planning.make_contact import (
    ContactOutcome,
    ContactSearch,
    PlanningTimeoutError,
    Step,
    StiffnessRule,
    make_contact,
    planned_motions,
    race,
)
from bilba_dist.planning.recorder import NullRecorder, Recorder
from bilba_dist.planning.result import PlannedMotion, PlanResult, Verification
from bilba_dist.planning.setpoints import SetpointParams
from bilba_dist.planning.stiffness import driver_fit, fixed_stiffness, variable_stiffness
from bilba_dist.planning.verify import (
    ADD_CHECKS,
    between,
    more_particles_hint,
    raised_points,
    verify,
    verify_particles,
    with_more_checks,
    within_budget,
)
from bilba_dist.robot.drivers import planning_arms
from bilba_dist.robot.panda import PandaModel
from bilba_dist.rollout import RolloutBackend, require_world
from bilba_dist.task.loader import Task, with_points
from bilba_dist.task.schema import particle_count

Variant = Literal["bilba-variable", "bilba-fixed", "b-est"]
PLANNERS: tuple[Variant, ...] = ("bilba-variable", "bilba-fixed", "b-est")


@dataclass
class Progress:
    """What a progress display shows; the planner calls ``update`` as it goes."""

    contact: str = ""
    best_score: float = 0.0
    rollouts: int = 0
    update: Callable[["Progress"], None] = field(default=lambda progress: None)


def plan(
    task: Task,
    backend: RolloutBackend,
    variant: Variant = "bilba-variable",
    seed: int = 0,
    timeout_s: float | None = None,
    progress: Progress | None = None,
    recorder: Recorder | None = None,
    validate_on: RolloutBackend | None = None,
) -> PlanResult:
    """Plan for ``task``'s initial belief. Never raises for "no plan": the result says why.

    With ``validate_on`` (the Panda model, when ``backend`` simulates the faster floating
    model), a plan is returned only if replaying it there brings every particle to the goal."""
    require_world(task, backend)
    progress = progress or Progress()
    if variant == "b-est":
        result = plan_best(task, backend, seed, timeout_s, recorder, lambda n: _count(progress, n))
        if result.success and validate_on is not None:
            b0 = start_belief(task, initial_belief(task))
            _validate(task, result, b0, validate_on)
        result.task = task
        return result
    clock = time.perf_counter
    started = clock()
    deadline = started + (timeout_s if timeout_s is not None else task.spec.planner.timeout_s)
    evaluator = Evaluator(backend, on_batch=lambda n: _count(progress, n))
    search = _Search(
        task, evaluator, variant, seed, started, deadline, progress, recorder, validate_on
    )
    spent = 0  # by a search restarted on more particles
    try:
        result = _search(search, more_points=raised_points(task))
    except MoreParticlesError as exc:  # the first plan lost offsets between the particles
        task, spent = with_points(task, exc.points), evaluator.rollouts
        particles = particle_count(task.spec.belief, len(task.spec.bounds))
        (recorder or NullRecorder()).restarted(exc.points, particles, exc.reason)
        # a search of its own rollout counter, to the same deadline (its verification's share
        # and effort limit count the first search's too: `_Search`)
        evaluator = Evaluator(backend, on_batch=lambda n: _count(progress, n))
        search = replace(search, task=task, evaluator=evaluator, spent=spent)
        result = _search(search, more_points=None, failed=exc.failed, prefix=exc.prefix)
    result.planning_time_s = clock() - started
    result.rollouts = spent + evaluator.rollouts
    result.task = task
    return result


@dataclass(frozen=True)
class _Search:
    """One search's inputs; a restart on more particles runs a second with its task."""

    task: Task
    evaluator: Evaluator
    variant: Variant
    seed: int
    #: When the plan began: a timeout's reason, the first plan's time and verify_effort's
    #: limit count from there, a restart's search included (it goes on from the first
    #: search's contacts: timed from its own start, its first plan came so soon that the
    #: limit cut repairs short, 3 of 26 puzzle restarts)
    started: float
    deadline: float
    progress: Progress
    recorder: Recorder | None
    validate_on: RolloutBackend | None
    #: Rollouts of the search before this one (a restart): verification's share counts them,
    #: as the plan it resumes from is theirs (counted from the restart, a resumed search's
    #: first plan was checked on one offset, 3 of 11 puzzle restarts)
    spent: int = 0


class MoreParticlesError(Exception):
    """The first plan of a search on the default axis belief failed verification on offsets
    between its particles: plan again on ``points`` a bounded axis (``raised_points``),
    keeping ``failed`` (the plan, its verification) as the best unverified plan so far, and
    ``prefix`` (its steps and the contacts they made), where the new search may resume."""

    def __init__(
        self,
        points: int,
        reason: str,
        failed: tuple[list[PlannedMotion], Verification],
        prefix: "tuple[list[Step], list[Reached]]",
    ) -> None:
        super().__init__(reason)
        self.points, self.reason, self.failed, self.prefix = points, reason, failed, prefix


def _search(
    inputs: _Search,
    more_points: int | None,
    failed: tuple[list[PlannedMotion], Verification] | None = None,
    prefix: "tuple[list[Step], list[Reached]] | None" = None,
) -> PlanResult:
    """Search ``inputs.task`` to its deadline. With ``more_points``, a first plan that fails
    verification on offsets inside the bounds raises MoreParticlesError; ``failed``: a plan
    from an earlier search on fewer particles, returned if no better one is found;
    ``prefix``: that plan's steps and contacts, where the first attempt resumes
    (`restart_at`)."""
    task, clock, started, deadline = inputs.task, time.perf_counter, inputs.started, inputs.deadline
    progress = inputs.progress
    rng = np.random.default_rng(inputs.seed)
    params = task.spec.planner
    particles = initial_belief(task)
    panda = PandaModel(arms=planning_arms(task.spec.planner.driver))
    b0 = start_belief(task, planning_particles(task, particles))
    b0 = b0.with_check(check_belief(task, particles))
    result = PlanResult(False, "", [], inputs.variant, inputs.seed)
    if failed is not None:
        result.unverified, result.verification = failed, failed[1]
    search = contact_search(
        task, inputs.evaluator, inputs.variant, deadline, clock, inputs.recorder
    )
    search.on_progress = lambda contact, best: _show(progress, contact, best)
    try:
        graph, _ = belief_graph(task, particles, task.X_WG0, search.cache)
        verifying = verify_particles(task, robust_friction(task))
        _attempts(
            task, graph, b0, search, rng, result, panda, verifying, inputs, more_points, prefix
        )
    except NoScheduleError as exc:
        rounds = f" in {result.rounds} rounds" if result.rounds > 1 else ""
        result.reason = (
            f"edges pruned until no schedule was left ({len(result.pruned)} pruned{rounds}); "
            f"last: {result.reason}"
            if result.pruned
            else f"no contact schedule: {exc}"
        )
    except PlanningTimeoutError:
        result.timed_out = True
        result.reason = f"timeout after {clock() - started:.1f} s"
    if not result.success and result.unverified is not None:
        # out of effort, time or schedules after plans that failed verification: the best
        plans = result.verification.plans if result.verification else 1
        result.motions, result.verification = result.unverified
        result.verification.plans, result.success = plans, True
        if result.timed_out and search.deadline < deadline:  # verify_effort's deadline, not ours
            ended = (
                f"within {params.verify_effort:g}x the time of the first "
                f"({result.first_plan_s:.1f} s; planner.verify_effort)"
            )
        elif result.timed_out:
            ended = f"before the {result.reason}"
        else:
            ended = f"({result.reason})"
        result.reason = f"no plan passed verification {ended}: the one that held best"
        if hint := more_particles_hint(task, result.verification):
            result.reason += f"; {hint}"
    if not result.success and result.blocked:
        result.reason += f"; {explain(result.blocked)}"
    if result.success and inputs.validate_on is not None:
        _validate(task, result, b0, inputs.validate_on)
    return result


#: The check particles' draw is fixed (not the planning seed): a plan's robustness should not
#: depend on which seed found it.
CHECK_SEED = 7


def robust_friction(task: Task) -> float:
    """The friction margin of robust acceptance: ``planner.check_friction``, or 0 (off) when
    the task's uncertainty has a friction axis (its particles then span the friction the
    user gave, and are planned on as they are)."""
    if task.spec.uncertainty.get("friction", 0.0) > 0:
        return 0.0
    return task.spec.planner.check_friction


def planning_particles(task: Task, particles: tuple[Particle, ...]) -> tuple[Particle, ...]:
    """The particles MakeContact plans on: with robust acceptance (margin f > 0), each at
    friction x(1 + f), where compliant motions jam (docs/planner.md, Robust acceptance)."""
    f = robust_friction(task)
    if f == 0:
        return particles
    return tuple(make_particle(task, {**p.offsets, "friction": f}) for p in particles)


def check_belief(task: Task, particles: tuple[Particle, ...]) -> Belief | None:
    """The check particles of robust acceptance (margin f): the planning particles again at
    friction x1 and x(1 - f), and ``planner.check_random`` more drawn inside the pose bounds
    at x(1 - f), x1 and x(1 + f). None when f = 0."""
    f = robust_friction(task)
    if f == 0:
        return None
    drawn = random_offsets(task.spec.bounds, task.spec.planner.check_random, seed=CHECK_SEED)
    check = [
        make_particle(task, {**offsets, "friction": scale})
        for offsets, scales in [
            *((p.offsets, (0.0, -f)) for p in particles),
            *((o, (-f, 0.0, f)) for o in drawn),
        ]
        for scale in scales
    ]
    return start_belief(task, check)


def contact_search(
    task: Task,
    evaluator: Evaluator,
    variant: Variant,
    deadline: float,
    clock: Callable[[], float] = time.perf_counter,
    recorder: Recorder | None = None,
) -> ContactSearch:
    """What MakeContact needs for ``task``, from its planner parameters."""
    params = task.spec.planner
    return ContactSearch(
        evaluator=evaluator,
        cache=SliceCache(task),
        stiffness=_stiffness_rule(task, variant),
        fit=driver_fit(task),
        setpoints=SetpointParams(
            params.setpoints_per_particle,
            params.noisy_setpoints,
            params.setpoint_noise_m,
            params.setpoint_press_m,
            patience=params.sample_patience,
        ),
        gp=GPParams(
            params.gp_test_points,
            params.gp_noise,
            params.gp_simulated,
            params.gp_rounds,
            params.gp_patience,
            params.gp_restarts,
        ),
        motion_timeout_s=params.motion_timeout_s,
        deadline=deadline,
        clock=clock,
        race_contacts=params.race_contacts,
        race_chunks=params.race_chunks,
        recorder=recorder or NullRecorder(),
        near=NearContacts.of(task.environment, task.manipuland, task.goal),
    )


def _validate(task: Task, result: PlanResult, b0: Belief, backend: RolloutBackend) -> None:
    from bilba_dist.plans.replay import replay

    final = replay(task, result.motions, b0.particles, backend)
    reached = sum(task.goal in c for c in final.contacts)
    if reached < len(final):
        result.success = False
        result.reason = (
            f"the plan failed validation on the Panda model: {reached}/{len(final)} "
            f"particles reach {task.goal}"
        )
    result.final_belief = final


def _attempts(
    task: Task,
    graph: ModeGraph,
    b0: Belief,
    search: ContactSearch,
    rng: np.random.Generator,
    result: PlanResult,
    panda: PandaModel,
    verifying: tuple[Particle, ...],
    inputs: _Search,
    more_points: int | None = None,
    prefix: "tuple[list[Step], list[Reached]] | None" = None,
) -> None:
    params, started = task.spec.planner, inputs.started
    attempts = range(params.n_attempts) if params.n_attempts else itertools.count()
    for attempt in attempts:
        result.attempts = attempt + 1
        belief, mode, steps = b0, FREE, []
        more_rounds = params.prune_rounds == 0 or result.rounds < params.prune_rounds
        if more_rounds and not graph.has_schedule():
            graph.restore()
            result.rounds += 1
        reached = [Reached(belief, mode, 0)]  # the contacts made so far in this attempt
        if attempt == 0 and prefix is not None:  # a restart: go on where the plan before did
            made = restart_at(search, graph, b0, *prefix)
            if made is not None:
                reached = made
                belief, mode = reached[-1].belief, reached[-1].mode
                steps = prefix[0][: reached[-1].steps]
                result.resumed = mode, len(steps)
                search.recorder.resumed(mode, len(steps))
        graph.reweight(_positions(belief))
        added: list[Particle] = []  # check particles added in this attempt (verification)
        while True:
            evaluator = search.evaluator
            before = evaluator.rollouts, evaluator.arm_touching, evaluator.arm_touches.copy()
            schedule, outcome = _next_contact(graph, belief, mode, search, rng, attempt, result)
            target = schedule[1]
            if not outcome.success:
                touched = evaluator.arm_touches - before[2]
                arm = (
                    evaluator.rollouts - before[0],
                    evaluator.arm_touching - before[1],
                    touched.most_common(1)[0][0] if touched else "",
                )
                result.blocked.append(
                    blocked(search.cache, belief, target, outcome.reached, outcome.checked, arm)
                )
                graph.prune(mode, target)
                result.pruned.append((mode, target))
                search.recorder.pruned((mode, target), outcome.reason)
                result.reason = outcome.reason
                if params.keep_reached and mode != FREE and graph.has_schedule(mode):
                    continue  # go on from the contact reached, on another schedule
                break
            steps += outcome.steps
            belief, mode = outcome.belief, furthest_common(schedule, outcome.belief, search.near)
            reached.append(Reached(belief, mode, len(steps)))
            if mode == task.goal:
                motions = planned_motions(steps, b0, panda)
                if result.first_plan_s == 0.0:  # go on for verify_effort x this at most
                    result.first_plan_s = search.clock() - started
                    limit = started + params.verify_effort * result.first_plan_s
                    search.deadline = min(search.deadline, limit)
                lost = (
                    _verify(task, motions, verifying, search, result, inputs.spent)
                    if verifying
                    else []
                )
                first = result.verification is not None and result.verification.plans == 1
                if lost and more_points is not None and first and between(task, lost):
                    assert result.unverified is not None  # _verify keeps the plan it failed
                    raise MoreParticlesError(
                        more_points, result.reason, result.unverified, (steps, reached)
                    )
                if lost:
                    b0 = with_more_checks(task, b0, lost[:ADD_CHECKS])
                    added += lost[:ADD_CHECKS]
                    resumed = (
                        resume_at(task, search, steps, reached, added)
                        if params.keep_reached
                        else None
                    )
                    if resumed is None:
                        break  # start over, checking particles this plan lost
                    # go on from the last contact that the lost particles made too
                    k, check = resumed
                    reached = reached[: k + 1]
                    belief, mode = reached[k].belief.with_check(check), reached[k].mode
                    steps = steps[: reached[k].steps]
                    graph.reweight(_positions(belief))
                    continue
                result.success, result.reason = True, ""
                result.motions = motions
                result.final_belief = belief
                return
            graph.reweight(_positions(belief))
    result.reason = (
        f"all {result.attempts} attempts failed ({len(result.pruned)} edges pruned); "
        f"last: {result.reason}"
    )


@dataclass(frozen=True)
class Reached:
    """A contact made in the current attempt: the belief there, the mode, and how many of
    the attempt's steps led there."""

    belief: Belief
    mode: ContactPair
    steps: int


def _replayed(
    search: ContactSearch, belief: Belief, steps: list[Step], reached: list[Reached]
) -> Iterator[tuple[int, Belief, bool]]:
    """``steps`` replayed on ``belief``: at each contact ``k`` of ``reached`` before the
    goal, its belief there and whether every particle of it is in that contact or one after."""
    done = 0
    for k in range(1, len(reached) - 1):
        for step in steps[done : reached[k].steps]:
            belief = belief.after(search.evaluator.simulate(belief.under(step.motion)))
        done = reached[k].steps
        accept = search.near.accept(r.mode for r in reached[k:])
        yield k, belief, belief.count(accept) == len(belief)


def restart_at(
    search: ContactSearch,
    graph: ModeGraph,
    b0: Belief,
    steps: list[Step],
    reached: list[Reached],
) -> list[Reached] | None:
    """Where a search restarted on more particles goes on: the plan of the search before
    (``steps``, making the contacts ``reached``) replayed from ``b0`` on the new particles and
    their check particles, up to the last of its contacts they all made (with a schedule on
    from there): those contacts need no new search. The contacts they made, from the start
    (``Reached``, on the new particles); None when they made none."""
    n, check = len(b0), b0.check
    whole = b0 if check is None else b0 + check
    made, last = [Reached(b0, FREE, 0)], 0
    for k, replayed, all_in in _replayed(search, whole, steps, reached):
        if not all_in:
            continue
        belief = replayed[:n] if check is None else replayed[:n].with_check(replayed[n:])
        made.append(Reached(belief, reached[k].mode, reached[k].steps))
        if graph.has_schedule(reached[k].mode):
            last = len(made) - 1
    return made[: last + 1] if last > 0 else None


def resume_at(
    task: Task,
    search: ContactSearch,
    steps: list[Step],
    reached: list[Reached],
    lost: list[Particle],
) -> tuple[int, Belief] | None:
    """Where a plan that lost ``lost`` in verification can be repaired rather than searched
    again from the start: the last contact it made (before the goal) that the lost
    particles made too, or one after it, replaying its motions on them; and the check
    particles there, with the lost ones (last, replacing any there already: those added
    earlier in the attempt). None when there is no such contact."""
    found: tuple[int, Belief] | None = None  # the last contact they made, their belief there
    for k, extra, all_in in _replayed(search, start_belief(task, lost), steps, reached):
        if all_in:
            found = k, extra
    if found is None:
        return None
    k, extra = found
    check = reached[k].belief.check
    if check is None:
        return k, extra
    return k, check.without(lost) + extra


def _verify(
    task: Task,
    motions: list[PlannedMotion],
    particles: tuple[Particle, ...],
    search: ContactSearch,
    result: PlanResult,
    spent: int = 0,
) -> list[Particle]:
    """Verify a plan (planning/verify.py) on as many of the particles as ``verify_share``
    of the plan's rollouts allows (the search's, and ``spent`` by one before it); the
    particles it lost when it failed, else none."""
    params = task.spec.planner
    per_offset = 3 if robust_friction(task) > 0 else 1  # verify_particles: one a friction
    budget = params.verify_share * (spent + search.evaluator.rollouts)
    chosen = within_budget(particles, per_offset, len(motions), budget)
    verification, failed = verify(task, motions, chosen, search.evaluator)
    plans = result.verification.plans + 1 if result.verification else 1
    verification.plans = plans
    result.verification = verification
    search.recorder.verified(verification)
    if verification.passed:
        return []
    best = result.unverified
    if best is None or verification.holds_better_than(best[1]):
        result.unverified = (motions, verification)
    result.reason = f"a plan failed verification on {verification.text()} (planner.verify_min)"
    return failed


def _next_contact(
    graph: ModeGraph,
    belief: Belief,
    mode: ContactPair,
    search: ContactSearch,
    rng: np.random.Generator,
    attempt: int,
    result: PlanResult,
) -> tuple[list[ContactPair], ContactOutcome]:
    """MakeContact for the next contact of Dijkstra's schedule from ``mode``. With
    ``race_contacts`` = k > 1, first race the next contacts of up to k schedules as short
    as Dijkstra's (its tie-break picks among them, and under a spread along a chamfer's
    normal it picks one the belief cannot make at once) and follow the winner; else, or
    when none wins, the full search on the contact the race got furthest with (most
    particles in; ties: Dijkstra's)."""
    k = search.race_contacts
    schedules = graph.alternatives(mode, k) if k > 1 else [graph.schedule(mode)]
    made = next((s for s in schedules if already_made(belief, s, search.near)), None)
    if made is not None:
        _follow(search, attempt, result, made)
        return made, ContactOutcome(True, [], belief)
    j = 0
    if len(schedules) > 1:
        j, outcome = race(
            search, belief, schedules, rng, lambda j: _follow(search, attempt, result, schedules[j])
        )
        if outcome is not None:
            return schedules[j], outcome
    schedule = schedules[j]
    _follow(search, attempt, result, schedule)
    accept = search.near.accept(schedule[1:])
    return schedule, make_contact(search, belief, schedule[1], accept, rng)


def _follow(
    search: ContactSearch, attempt: int, result: PlanResult, schedule: list[ContactPair]
) -> None:
    result.schedules.append(schedule)
    search.recorder.schedule(attempt, schedule)


#: No face has neighbours: each mode counts as itself only.
NO_NEIGHBOURS = NearContacts()


def already_made(
    belief: Belief, schedule: list[ContactPair], near: NearContacts = NO_NEIGHBOURS
) -> bool:
    """Whether every particle, check particles included, is in ``schedule``'s next contact
    or past it already. A schedule from the contact reached need not be the one that
    reached it (Dijkstra after a contact, or after a pruned edge with ``keep_reached``), so
    the belief may be further along it than its first mode; searching for a motion into a
    contact every particle is in can only fail (no motion adds a particle) and pruned a
    good edge (puzzle env.y ±1 cm fixed, seed 1)."""
    return furthest_common(schedule, belief, near) != schedule[0]


def furthest_common(
    schedule: list[ContactPair], belief: Belief, near: NearContacts = NO_NEIGHBOURS
) -> ContactPair:
    """The furthest schedule mode that every particle has reached or passed, check particles
    included: a contact is made when they are all in it or past it, so a motion that carried
    the planning particles on to the goal but left a check particle at the contact sought
    has made that contact, not the goal (the plan then goes on from there). A particle is
    in a mode when it is in one of ``near.around`` it (a neighbouring face's contact)."""
    check = belief.check.contacts if belief.check is not None else ()
    around = [near.around(m) for m in schedule]
    reached = [
        max((k for k, m in enumerate(around) if contacts & m), default=0)
        for contacts in (*belief.contacts, *check)
    ]
    return schedule[min(reached)]


def _positions(belief: Belief) -> np.ndarray:
    return np.array([belief.X_OM(i).translation for i in range(len(belief))])


def _stiffness_rule(task: Task, variant: Variant) -> StiffnessRule:
    if variant == "bilba-fixed":
        return lambda belief, mode, rng: fixed_stiffness()

    def variable(belief: Belief, mode: ContactPair, rng: np.random.Generator) -> np.ndarray:
        i = int(rng.integers(len(belief)))
        return variable_stiffness(task, mode, belief.X_OM(i))

    return variable


def _count(progress: Progress, n: int) -> None:
    progress.rollouts += n
    progress.update(progress)


def _show(progress: Progress, contact: str, best: float) -> None:
    progress.contact, progress.best_score = contact, best
    progress.update(progress)
