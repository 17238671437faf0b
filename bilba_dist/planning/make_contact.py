"""MakeContact (paper Algorithm 2, with Algorithm 3's sampling and GP rounds): a short
sequence of compliant motions that brings every particle into one contact, or failure."""

from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import chain, zip_longest

import numpy as np
import pinocchio as pin

from bilba_dist.belief.state import Accept, Belief
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.neighbours import NearContacts
from bilba_dist.modes.schedule import SliceCache
from bilba_dist.planning.evaluate import Candidate, Evaluator, Scored, best_of, lagging_checks
from bilba_dist.planning.gp import GPParams, features, propose
from bilba_dist.planning.laggards import step_rank
from bilba_dist.planning.recorder import NullRecorder, Recorder
from bilba_dist.planning.result import PlannedMotion
from bilba_dist.planning.setpoints import SetpointParams, sample_setpoints
from bilba_dist.robot.panda import PandaModel
from bilba_dist.rollout import Motion

#: ``stiffness(belief, mode, rng)`` → 6×6 K for the next motion.
StiffnessRule = Callable[[Belief, ContactPair, np.random.Generator], np.ndarray]
#: ``fit(K, G_d)`` → the K a motion to setpoint ``G_d`` runs with (a driver's form of it).
StiffnessFit = Callable[[np.ndarray, pin.SE3], np.ndarray]


def unchanged(K: np.ndarray, G_d: pin.SE3) -> np.ndarray:
    return K


class PlanningTimeoutError(Exception):
    """The overall planning deadline passed (caught by the outer loop)."""


@dataclass
class ContactSearch:
    """Everything MakeContact needs; the same object serves every contact of a plan."""

    evaluator: Evaluator
    cache: SliceCache
    stiffness: StiffnessRule
    setpoints: SetpointParams
    gp: GPParams
    motion_timeout_s: float
    deadline: float
    clock: Callable[[], float]
    max_motions: int = 4
    race_contacts: int = 0  # tied schedules raced before the full search (≤ 1: off)
    race_chunks: int = 2  # chunks of sampled setpoints per contact in a race
    on_progress: Callable[[str, float], None] = field(default=lambda contact, best: None)
    recorder: Recorder = field(default_factory=NullRecorder)
    fit: StiffnessFit = unchanged  # planner.driver's form of K (planning/stiffness.py)
    #: The contacts that count as the one sought (a face of a curved surface cut into pieces:
    #: its neighbours too; geometry/neighbours.py).
    near: NearContacts = field(default_factory=NearContacts)

    def motion(self, K: np.ndarray, G_d: pin.SE3) -> Motion:
        return Motion(self.fit(K, G_d), G_d, self.motion_timeout_s)


@dataclass(frozen=True)
class Step:
    motion: Motion
    contact: ContactPair
    score: float


@dataclass(frozen=True)
class ContactOutcome:
    success: bool
    steps: list[Step]
    belief: Belief
    reason: str = ""
    reached: int = 0  # on failure: particles in the contact (or past it) when it gave up
    checked: int = 0  # on failure: check particles in it then (robust acceptance)


def make_contact(
    search: ContactSearch,
    belief: Belief,
    mode: ContactPair,
    accept: Accept,
    rng: np.random.Generator,
) -> ContactOutcome:
    """Motions towards ``mode`` until every particle is in one of the ``accept`` modes (``mode``
    and those after it in the schedule); fail when a motion no longer adds a particle."""
    steps: list[Step] = []
    for _ in range(search.max_motions):
        before = _progress(belief, accept)
        best = best_motion(search, belief, mode, accept, rng)
        if best is None or best.posterior is None or best.count < before[0]:
            return _failed(steps, mode, belief, accept)
        posterior = search.evaluator.advance_check(belief, best)
        if _progress(posterior, accept) <= before:
            return _failed(steps, mode, belief, accept)
        steps.append(_accept(search, mode, belief, best))
        belief = posterior
        if _progress(belief, accept) == _all(belief):
            return ContactOutcome(True, steps, belief)
    return ContactOutcome(
        False,
        steps,
        belief,
        f"{search.max_motions} motions did not reach {mode}",
        *_progress(belief, accept),
    )


def _progress(belief: Belief, accept: Accept) -> tuple[int, int]:
    """Particles in ``accept``, then check particles in it."""
    return belief.count(accept), belief.check.count(accept) if belief.check is not None else 0


def _all(belief: Belief) -> tuple[int, int]:
    return len(belief), len(belief.check) if belief.check is not None else 0


def _failed(steps: list[Step], mode: ContactPair, belief: Belief, accept: Accept) -> ContactOutcome:
    count, checked = _progress(belief, accept)
    reason = f"no motion brought more particles into {mode} ({count}/{len(belief)})"
    if count == len(belief) and belief.check is not None:
        reason = (
            f"no motion brought more check particles into {mode} ({checked}/{len(belief.check)} "
            f"at other frictions; planner.check_friction)"
        )
    return ContactOutcome(False, steps, belief, reason, count, checked)


def race(
    search: ContactSearch,
    belief: Belief,
    schedules: list[list[ContactPair]],
    rng: np.random.Generator,
    on_start: Callable[[int], None] = lambda j: None,
) -> tuple[int, ContactOutcome | None]:
    """Race the next contacts of ``schedules``: a chunk of sampled setpoints for each in
    turn, ``race_chunks`` rounds, no GP; the first motion that brings every particle into
    its schedule's next contact (or a later one) wins: (its schedule, its outcome). When
    none did, (the schedule whose best motion brought most particles in, None): the one
    the full search should take on (ties: the earliest, Dijkstra's first).

    Each contact's setpoints are drawn when it first runs (``on_start(j)``), so when the
    first schedule wins its first chunk, the draws and the motion are those MakeContact
    would have made without a race."""
    chunk, drawn = search.evaluator.chunk, list[list[Candidate]]()

    def chunk_of(at: tuple[int, int] | None) -> list[Candidate]:
        """Round r's chunk of schedule j's setpoints (``at`` = (r, j)); none where they are
        not drawn yet."""
        if at is None or at[1] >= len(drawn):
            return []
        round_, j = at
        return drawn[j][round_ * chunk : (round_ + 1) * chunk]

    furthest: dict[int, tuple[int, int]] = {}  # schedule -> (particles, check particles) in
    turns = [(r, j) for r in range(search.race_chunks) for j in range(len(schedules))]
    for at, upcoming in zip(turns, [*turns[1:], None], strict=True):
        j = at[1]
        mode, accept = schedules[j][1], search.near.accept(schedules[j][1:])
        if j == len(drawn):
            on_start(j)
            drawn.append(sampled_candidates(search, belief, mode, accept, rng)[1])
        _check(search)
        scored, winner = search.evaluator.score(
            belief,
            chunk_of(at),
            accept,
            _recording(search, mode, belief),
            then=chunk_of(upcoming),
        )
        best = winner or best_of(scored)
        _report(search, mode, best)
        if best is not None:
            furthest[j] = max(furthest.get(j, (0, 0)), best.rank()[:2])
        if winner is not None and winner.posterior is not None:
            step = _accept(search, mode, belief, winner)
            return j, ContactOutcome(True, [step], winner.posterior)
    return max(range(len(schedules)), key=lambda j: (furthest.get(j, (0, 0)), -j)), None


def _accept(search: ContactSearch, mode: ContactPair, belief: Belief, best: Scored) -> Step:
    """Record ``best`` as the motion taken from ``belief`` towards ``mode``."""
    assert best.posterior is not None
    search.recorder.transition(
        mode, best.candidate.motion, belief, best.posterior, best.score, best.count, True
    )
    return Step(best.candidate.motion, mode, best.score)


def sampled_candidates(
    search: ContactSearch,
    belief: Belief,
    mode: ContactPair,
    accept: Accept,
    rng: np.random.Generator,
) -> tuple[np.ndarray, list[Candidate]]:
    """The stiffness for ``mode`` and setpoints sampled on it for each particle, taken a
    particle at a time; each candidate is screened on the particle it was made for.

    The particles take turns even when some are already in the contact: scoring the
    laggards' setpoints first cut the peg's ±2 cm searches by a third but made plans that
    just reach the extreme particles and miss those between (benchmarks/HISTORY.md). When
    every planning particle is in and only check particles lag (robust acceptance), those
    take turns too, sampled from their own states (after the planning particles' draws)."""
    K = search.stiffness(belief, mode, rng)
    sources = [(belief, i, False) for i in range(len(belief))]
    if belief.check is not None:
        sources += [(belief.check, i, True) for i in lagging_checks(belief, accept)]
    per_particle = [
        [
            Candidate(search.motion(K, G_d), i, on_check)
            for G_d in sample_setpoints(
                source.particles[i],
                source.states[i].X_WM,
                mode,
                search.cache,
                search.setpoints,
                rng,
            )
        ]
        for source, i, on_check in sources
    ]
    return K, [c for c in chain.from_iterable(zip_longest(*per_particle)) if c is not None]


def _recording(
    search: ContactSearch, mode: ContactPair, belief: Belief
) -> Callable[[Scored], None]:
    def record(s: Scored) -> None:
        assert s.posterior is not None
        search.recorder.transition(
            mode, s.candidate.motion, belief, s.posterior, s.score, s.count, False
        )

    return record


def best_motion(
    search: ContactSearch,
    belief: Belief,
    mode: ContactPair,
    accept: Accept,
    rng: np.random.Generator,
) -> Scored | None:
    """Sampled setpoints first (screened per particle); then GP rounds if none works for all."""
    K, candidates = sampled_candidates(search, belief, mode, accept, rng)
    _check(search)

    record = _recording(search, mode, belief)
    scored, winner = search.evaluator.score(
        belief, candidates, accept, record, search.setpoints.patience
    )
    rank = step_rank(search.cache.task, belief.count(accept), mode, accept)
    best = winner or best_of(scored, rank)
    _report(search, mode, best)
    idle = 0  # GP rounds in a row without a better motion
    for _ in range(search.gp.rounds if winner is None and scored else 0):
        _check(search)
        train = features([s.candidate.motion.G_d for s in scored])
        proposals, predicted = propose(train, np.array([s.score for s in scored]), search.gp, rng)
        # Screen GP proposals on a particle not yet in the contact: the one they must move.
        lagging = next((i for i, c in enumerate(belief.contacts) if not c & accept), 0)
        batch = [Candidate(search.motion(K, G_d), lagging) for G_d in proposals]
        more, winner = search.evaluator.score(belief, batch, accept, record)
        simulated = max((s.score for s in more), default=0.0)
        search.recorder.gp_round(mode, len(train), float(predicted[0]), simulated)
        scored += more
        previous = best
        best = winner or best_of(scored, rank)
        _report(search, mode, best)
        if winner is not None:
            break
        idle = idle + 1 if best is None or best is previous else 0
        if idle >= search.gp.patience:
            break
    return best


def _check(search: ContactSearch) -> None:
    if search.clock() > search.deadline:
        raise PlanningTimeoutError


def _report(search: ContactSearch, mode: ContactPair, best: Scored | None) -> None:
    search.on_progress(str(mode), best.score if best is not None else 0.0)


def planned_motions(steps: list[Step], b0: Belief, panda: PandaModel) -> list[PlannedMotion]:
    """Attach the joint setpoint (IK from the nominal particle's start) to each motion."""
    q = b0.states[0].q
    planned = []
    for step in steps:
        q = panda.ik(step.motion.G_d, q)
        planned.append(
            PlannedMotion(
                step.motion.K, step.motion.G_d, q, step.motion.timeout_s, step.contact, step.score
            )
        )
    return planned
