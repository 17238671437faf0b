"""Scoring candidate motions on a belief, spending as few rollouts as possible.

A candidate made for one particle is first run on that particle alone; only if it reaches the
contact there is it run on the others. Candidates go in chunks, and the search stops at the
first motion that brings every particle into the contact (paper: "if any of the motions ...
achieve the current desired contact for every particle") or, with a patience, once that many
candidates in a row have not raised the best score.
"""

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from bilba_dist.belief.state import Accept, Belief
from bilba_dist.rollout import Motion, RolloutBackend, RolloutRequest, RolloutResult


@dataclass(frozen=True)
class Candidate:
    motion: Motion
    screen_on: int | None  # simulated on this particle first, the rest only if it works there


@dataclass(frozen=True)
class Scored:
    """A candidate and what it did: the posterior belief when every particle was run."""

    candidate: Candidate
    score: float
    count: int
    posterior: Belief | None  # None: it failed its own particle and the rest were skipped


@dataclass
class Evaluator:
    backend: RolloutBackend
    chunk: int = 8  # candidates per batch
    rollouts: int = 0
    on_batch: Callable[[int], None] = field(default=lambda n: None)

    def run(self, belief: Belief, pairs: Sequence[tuple[int, Motion]]) -> list[RolloutResult]:
        requests = [RolloutRequest(belief.particles[i], belief.states[i], m) for i, m in pairs]
        results = self.backend.simulate(requests) if requests else []
        self.rollouts += len(results)
        self.on_batch(len(results))
        return results

    def score(
        self,
        belief: Belief,
        candidates: Sequence[Candidate],
        accept: Accept,
        on_scored: Callable[[Scored], None] = lambda scored: None,
        patience: int = 0,
    ) -> tuple[list[Scored], Scored | None]:
        """Score the candidates (screened) in order; stop at the first chunk with one that
        gets all into ``accept``, or, with ``patience`` > 0, once that many candidates in a
        row (counted per chunk) have not raised the best score."""
        scored: list[Scored] = []
        best, idle = 0.0, 0
        for start in range(0, len(candidates), self.chunk):
            batch = candidates[start : start + self.chunk]
            chunk_scored = self._score_chunk(belief, batch, accept)
            for s in chunk_scored:
                if s.posterior is not None:
                    on_scored(s)
            scored += chunk_scored
            winners = [s for s in chunk_scored if s.count == len(belief)]
            if winners:
                return scored, max(winners, key=lambda s: s.score)
            top = max(s.score for s in chunk_scored)
            best, idle = (top, 0) if top > best else (best, idle + len(batch))
            if patience and idle >= patience:
                break
        return scored, None

    def _score_chunk(
        self, belief: Belief, batch: Sequence[Candidate], accept: Accept
    ) -> list[Scored]:
        n = len(belief)
        own = [(c.screen_on, c.motion) for c in batch if c.screen_on is not None]
        own_results = iter(self.run(belief, own))
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
        rest_results = self.run(belief, [(i, batch[k].motion) for k, i in rest])
        for (k, i), result in zip(rest, rest_results, strict=True):
            screened[k][i] = result
        out = []
        for c, results in zip(batch, screened, strict=True):
            if len(results) < n:
                out.append(Scored(c, 0.0, 0, None))
                continue
            posterior = belief.after([results[i] for i in range(n)])
            out.append(Scored(c, posterior.score(accept), posterior.count(accept), posterior))
        return out


def best_of(scored: Sequence[Scored]) -> Scored | None:
    full = [s for s in scored if s.posterior is not None]
    return max(full, key=lambda s: s.score) if full else None
