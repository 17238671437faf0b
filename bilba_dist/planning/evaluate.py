"""Scoring candidate motions on a belief, spending as few rollouts as possible.

A candidate made for one particle is first run on that particle alone; only if it reaches the
contact there is it run on the others. Candidates go in chunks, and the search stops at the
first motion that brings every particle into the contact (paper: "if any of the motions ...
achieve the current desired contact for every particle") or, with a patience, once that many
candidates in a row have not raised the best score.

Robust acceptance: a belief may carry check particles (``Belief.check``: the planning
particles' twins at other frictions, planning/bilba.py). A motion that brings every planning
particle into the contact is then also simulated on them (the chunk's best such motion first,
the others only if it fails), and wins only if it brings them all in too; one that does not
is kept as a candidate (ranked by how many it brought), so the search goes on; MakeContact
counts the check particles it brought as progress, and needs them all in before the contact
is made. Once every planning particle is in and only check particles lag, screening on a
planning particle tells nothing (it is in already): a candidate is then screened on a lagging
check particle instead (MakeContact samples setpoints on those particles too, taking turns
with the planning particles'), and only one that brings it in is run on the rest.
"""

from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from bilba_dist.belief.state import Accept, Belief
from bilba_dist.rollout import Motion, RolloutBackend, RolloutRequest, RolloutResult


@dataclass(frozen=True)
class Candidate:
    motion: Motion
    screen_on: int | None  # simulated on this particle first, the rest only if it works there
    #: ``screen_on`` indexes the check particles (a candidate sampled for a check particle
    #: that lags behind planning particles already in the contact)
    on_check: bool = False


@dataclass(frozen=True)
class Scored:
    """A candidate and what it did: the posterior belief when every particle was run."""

    candidate: Candidate
    score: float
    count: int
    posterior: Belief | None  # None: it failed its own particle and the rest were skipped
    checked: int = -1  # check particles it brought into the contact (-1: not simulated)

    @classmethod
    def of(cls, candidate: Candidate, posterior: Belief, accept: Accept) -> "Scored":
        """``candidate`` scored by its ``posterior`` (and its check particles, if simulated)."""
        checked = -1 if posterior.check is None else posterior.check.count(accept)
        return cls(candidate, posterior.score(accept), posterior.count(accept), posterior, checked)

    def rank(self) -> tuple[int, int, float]:
        """Particles in, then check particles in, then the score (its tie-break)."""
        return self.count, self.checked, self.score


@dataclass
class Evaluator:
    backend: RolloutBackend
    chunk: int = 8  # candidates per batch
    rollouts: int = 0
    on_batch: Callable[[int], None] = field(default=lambda n: None)
    #: Rollouts that ended with the arm or hand touching the environment, per piece touched
    #: (the planner's diagnosis: fingers on a rim block a contact).
    arm_touches: Counter[str] = field(default_factory=Counter)
    arm_touching: int = 0
    # Screening requests of the current belief by candidate: one object per candidate, so a
    # request prefetched from one call is the one a later call asks for.
    _screens: dict[int, tuple[Candidate, RolloutRequest]] = field(default_factory=dict)
    _screens_of: Belief | None = None

    def simulate(
        self, requests: Sequence[RolloutRequest], prefetch: Sequence[RolloutRequest] = ()
    ) -> list[RolloutResult]:
        """Run ``requests`` (counted); ``prefetch`` is what will probably come next."""
        results = self.backend.simulate(requests, prefetch) if requests else []
        self.rollouts += len(results)
        for result in results:
            if result.state.arm_touches:
                self.arm_touching += 1
                self.arm_touches.update(result.state.arm_touches)
        self.on_batch(len(results))
        return results

    def score(
        self,
        belief: Belief,
        candidates: Sequence[Candidate],
        accept: Accept,
        on_scored: Callable[[Scored], None] = lambda scored: None,
        patience: int = 0,
        then: Sequence[Candidate] = (),
    ) -> tuple[list[Scored], Scored | None]:
        """Score the candidates (screened) in order; stop at the first chunk with one that
        gets all into ``accept``, or, with ``patience`` > 0, once that many candidates in a
        row (counted per chunk) have not raised the best score. ``then``: the candidates the
        caller will probably score next (on the same belief), whose screening a backend
        may start while this call's last chunk runs."""
        scored: list[Scored] = []
        best, idle = 0.0, 0
        batches = [candidates[s : s + self.chunk] for s in range(0, len(candidates), self.chunk)]
        lagging = lagging_checks(belief, accept)
        if lagging:
            return self._score_for_checks(belief, batches, lagging, accept, on_scored, patience)
        upcoming_batches = [*batches[1:], then[: self.chunk]][: len(batches)]
        for batch, upcoming in zip(batches, upcoming_batches, strict=True):
            # ``then`` may be another contact's chunk (a race), sampled on its lagging check
            # particles: those are screened on check particles, not prefetched here
            own = self._screen(belief, batch)
            ahead = self._screen(belief, [c for c in upcoming if not c.on_check])
            chunk_scored = self._score_chunk(belief, batch, own, ahead, accept)
            for s in chunk_scored:
                if s.posterior is not None:
                    on_scored(s)
            scored += chunk_scored
            winners = [s for s in chunk_scored if s.count == len(belief)]
            if winners and belief.check is not None:
                winners = self._check_in_turn(belief, winners, accept)
                scored = [*scored[: -len(chunk_scored)], *self._merge(chunk_scored, winners)]
                winners = [s for s in winners if s.checked == len(belief.check)]
            if winners:
                return scored, max(winners, key=Scored.rank)
            top = max(s.score for s in chunk_scored)
            best, idle = (top, 0) if top > best else (best, idle + len(batch))
            if patience and idle >= patience:
                break
        return scored, None

    def _score_for_checks(
        self,
        belief: Belief,
        batches: Sequence[Sequence[Candidate]],
        lagging: list[int],
        accept: Accept,
        on_scored: Callable[[Scored], None],
        patience: int,
    ) -> tuple[list[Scored], Scored | None]:
        """``score`` when every planning particle is in ``accept`` and only check particles
        (``lagging``) are not: each candidate is screened on one lagging check particle (its
        own, or the lagging ones in turn), and run on the planning particles and the other
        check particles only if it brings that one in. Patience counts candidates that bring
        no more check particles in than the best so far."""
        assert belief.check is not None
        check, n = belief.check, len(belief)
        scored: list[Scored] = []
        best, idle = -1, 0
        for batch in batches:
            on = [
                c.screen_on if c.on_check and c.screen_on in lagging else lagging[j % len(lagging)]
                for j, c in enumerate(batch)
            ]
            screens = self.simulate(
                _requests(check, [(i, c.motion) for i, c in zip(on, batch, strict=True)])
            )
            promising = [j for j, r in enumerate(screens) if r.contacts & accept]
            others = {j: [i for i in range(len(check)) if i != on[j]] for j in promising}
            planning_pairs = [(i, batch[j].motion) for j in promising for i in range(n)]
            check_pairs = [(i, batch[j].motion) for j in promising for i in others[j]]
            results = self.simulate(
                [*_requests(belief, planning_pairs), *_requests(check, check_pairs)]
            )
            planning, checks = results[: len(planning_pairs)], iter(results[len(planning_pairs) :])
            chunk_scored = [Scored(c, 0.0, 0, None) for c in batch]
            for k, j in enumerate(promising):
                by_index = {on[j]: screens[j]} | {i: next(checks) for i in others[j]}
                after = check.after([by_index[i] for i in range(len(check))])
                posterior = belief.after(planning[k * n : (k + 1) * n]).with_check(after)
                chunk_scored[j] = Scored.of(batch[j], posterior, accept)
                on_scored(chunk_scored[j])
            scored += chunk_scored
            winners = [s for s in chunk_scored if s.count == n and s.checked == len(check)]
            if winners:
                return scored, max(winners, key=Scored.rank)
            top = max((s.checked for s in chunk_scored if s.count == n), default=-1)
            best, idle = (top, 0) if top > best else (best, idle + len(batch))
            if patience and idle >= patience:
                break
        return scored, None

    def _check_in_turn(self, belief: Belief, winners: list[Scored], accept: Accept) -> list[Scored]:
        """``winners`` checked best first: the best alone, the rest only if it fails (most
        chunks of an easy contact are all winners, and the best passes)."""
        assert belief.check is not None
        ordered = sorted(winners, key=Scored.rank, reverse=True)
        first = self._checked(belief, ordered[:1], accept)
        if first[0].checked == len(belief.check):
            return [*first, *ordered[1:]]
        return [*first, *self._checked(belief, ordered[1:], accept)]

    def _checked(self, belief: Belief, winners: list[Scored], accept: Accept) -> list[Scored]:
        """``winners`` with their check particles simulated, in one batch."""
        check = belief.check
        assert check is not None
        requests = [
            RolloutRequest(p, st, s.candidate.motion)
            for s in winners
            for p, st in zip(check.particles, check.states, strict=True)
        ]
        results = self.simulate(requests)
        n, out = len(check), []
        for k, s in enumerate(winners):
            assert s.posterior is not None
            posterior = s.posterior.with_check(check.after(results[k * n : (k + 1) * n]))
            out.append(Scored.of(s.candidate, posterior, accept))
        return out

    @staticmethod
    def _merge(chunk: list[Scored], checked: list[Scored]) -> list[Scored]:
        by_candidate = {id(s.candidate): s for s in checked}
        return [by_candidate.get(id(s.candidate), s) for s in chunk]

    def advance_check(self, belief: Belief, best: Scored) -> Belief:
        """``best``'s posterior with the check particles moved by its motion too (simulated
        now when they were not yet)."""
        assert best.posterior is not None
        if belief.check is None or best.posterior.check is not None:
            return best.posterior
        check = belief.check
        motion = best.candidate.motion
        results = self.simulate(_requests(check, [(i, motion) for i in range(len(check))]))
        return best.posterior.with_check(check.after(results))

    def _screen(self, belief: Belief, batch: Sequence[Candidate]) -> list[RolloutRequest]:
        """The screening requests of ``batch`` (each candidate on its own particle)."""
        if self._screens_of is not belief:
            self._screens, self._screens_of = {}, belief
        for c in batch:
            if c.screen_on is not None and id(c) not in self._screens:
                self._screens[id(c)] = (c, _requests(belief, [(c.screen_on, c.motion)])[0])
        return [self._screens[id(c)][1] for c in batch if c.screen_on is not None]

    def _score_chunk(
        self,
        belief: Belief,
        batch: Sequence[Candidate],
        own: Sequence[RolloutRequest],
        ahead: Sequence[RolloutRequest],
        accept: Accept,
    ) -> list[Scored]:
        """``own``: the batch's screening requests; ``ahead``: the next batch's (prefetch)."""
        n = len(belief)
        own_results = iter(self.simulate(own, ahead))
        screened: list[dict[int, RolloutResult]] = []
        for c in batch:
            first = {c.screen_on: next(own_results)} if c.screen_on is not None else {}
            screened.append(first)
        rest = [
            (k, i)
            for k, (c, first) in enumerate(zip(batch, screened, strict=True))
            if all(r.contacts & accept for r in first.values())
            for i in range(n)
            if i not in first
        ]
        rest_results = self.simulate(
            _requests(belief, [(i, batch[k].motion) for k, i in rest]), ahead
        )
        for (k, i), result in zip(rest, rest_results, strict=True):
            screened[k][i] = result
        out = []
        for c, results in zip(batch, screened, strict=True):
            if len(results) < n:
                out.append(Scored(c, 0.0, 0, None))
                continue
            out.append(Scored.of(c, belief.after([results[i] for i in range(n)]), accept))
        return out


def lagging_checks(belief: Belief, accept: Accept) -> list[int]:
    """The check particles not in ``accept`` when every planning particle is (else none)."""
    if belief.check is None or belief.count(accept) < len(belief):
        return []
    return [i for i, c in enumerate(belief.check.contacts) if not c & accept]


def _requests(belief: Belief, pairs: Sequence[tuple[int, Motion]]) -> list[RolloutRequest]:
    return [RolloutRequest(belief.particles[i], belief.states[i], m) for i, m in pairs]


def best_of(scored: Sequence[Scored], key: Callable[[Scored], Any] = Scored.rank) -> Scored | None:
    """The best of the candidates simulated on every particle, by ``key``."""
    full = [s for s in scored if s.posterior is not None]
    return max(full, key=key) if full else None
