"""Rollout backends on Ray: a pool of actors, each a RolloutWorker with its own PyBullet worlds.

`RayPool` keeps every actor fed from one queue: the rollouts asked for first, then those the
planner says it will probably ask for next (``prefetch``: the next chunk's screening
rollouts), one at a time on an actor the batch in hand leaves idle — at the batch's tail,
and while the planner thinks between batches. A rollout depends only on its request (each
world forgets its contacts at reset), so a result computed ahead is the one a later call
would compute; results return in request order, and a seeded plan is the same in-process,
on 1 worker or on N. Prefetched rollouts the planner never asks for are dropped.
"""

import math
import pickle
from collections import deque
from collections.abc import Iterable, Sequence
from typing import Any

from bilba_dist.rollout import DynamicsModel, RolloutRequest, RolloutResult
from bilba_dist.task.loader import Task
from bilba_dist.workers.rollout_worker import RolloutWorker, world_key

#: Ray tasks in flight per actor: one running, one queued behind it, so an actor never
#: waits a round trip for its next task.
DEPTH = 2


class RayPool:
    """``workers`` Ray actors, each a RolloutWorker with its own PyBullet worlds."""

    def __init__(self, task: Task, workers: int, model: DynamicsModel = "panda") -> None:
        import ray

        actor = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=-1)(RolloutWorker)
        self._use([actor.remote(task.spec, model) for _ in range(workers)], owner=True)
        self.task = task

    def simulates(self, task: Task) -> bool:
        """Whether a rollout here is one of ``task``'s (`RolloutWorker.simulates`)."""
        return world_key(task.spec) == world_key(self.task.spec)

    def _use(self, actors: list, owner: bool) -> None:
        import ray

        self._ray, self.actors, self._owner = ray, actors, owner
        self._load = [0] * len(actors)  # tasks in flight per actor
        self._running: dict[Any, int] = {}  # task ref -> actor index, until it is seen done
        self._ahead: dict[int, tuple[RolloutRequest, Any, int]] = {}  # id(request) -> (request,
        # task ref, index in the task's group): submitted, not yet asked for
        self._guess: Any = None  # the guessed rollout's task, while it may be running
        self.guessed = 0  # prefetched rollouts submitted ...
        self.guessed_used = 0  # ... and later asked for

    def first(self, workers: int) -> "RayPool":
        """A pool on this pool's first ``workers`` actors (already started and warm), for
        comparing pool sizes back to back on one Ray instance; closing it kills nothing."""
        pool = object.__new__(RayPool)
        pool._use(self.actors[:workers], owner=False)
        pool.task = self.task
        return pool

    def simulate(
        self, requests: Sequence[RolloutRequest], prefetch: Sequence[RolloutRequest] = ()
    ) -> list[RolloutResult]:
        """Results of ``requests`` in order; ``prefetch`` may run on otherwise idle actors."""
        if not requests:
            return []
        keep = {id(r) for r in (*requests, *prefetch)}
        self._ahead = {k: v for k, v in self._ahead.items() if k in keep}
        where = {id(r): self._ahead.pop(id(r))[1:] for r in requests if id(r) in self._ahead}
        self.guessed_used += len(where)
        todo = _unique(r for r in requests if id(r) not in where)
        taken = self._ahead.keys() | where.keys() | {id(r) for r in todo}
        spare = _unique(r for r in prefetch if id(r) not in taken)
        queue = deque([(group, True) for group in self._groups(todo)])
        if len(self.actors) > 1:  # one actor is never idle at a tail: no guesses
            queue += [([request], False) for request in spare]
        while True:
            self._fill(queue, where)
            urgent_left = bool(queue) and queue[0][1]
            if not urgent_left and all(ref not in self._running for ref, _ in where.values()):
                break
            self._reap()
        refs = list({ref for ref, _ in where.values()})
        done = dict(zip(refs, map(pickle.loads, self._ray.get(refs)), strict=True))
        return [done[where[id(r)][0]][where[id(r)][1]] for r in requests]

    def _groups(self, requests: list[RolloutRequest]) -> list[list[RolloutRequest]]:
        """Groups of about ``len / (DEPTH · actors)``, so that each actor gets about DEPTH
        and none waits long at the tail; on one actor, one group."""
        if not requests:
            return []
        if len(self.actors) == 1:  # one call: groups only help to balance several actors
            return [list(requests)]
        size = math.ceil(len(requests) / (DEPTH * len(self.actors)))
        return [requests[i : i + size] for i in range(0, len(requests), size)]

    def _fill(self, queue: deque, where: dict[int, tuple[Any, int]]) -> None:
        """Submit queued groups to the least loaded actor while one has room; a guess only
        to an idle actor, one at a time (on a small machine a guess shares a core with the
        planner or with a rollout that was asked for)."""
        while queue and min(self._load) < DEPTH:
            group, urgent = queue[0]
            if not urgent and (min(self._load) > 0 or self._guess in self._running):
                break
            queue.popleft()
            index = self._load.index(min(self._load))
            # Pickled by us, one bytes object each way: Ray's serialiser takes every small
            # array of a request as a buffer of its own (~0.15 ms of the driver's a task).
            ref = self.actors[index].simulate_pickled.remote(pickle.dumps(group, protocol=5))
            self._load[index] += 1
            self._running[ref] = index
            if urgent:
                where.update((id(request), (ref, k)) for k, request in enumerate(group))
            else:
                self._guess, self.guessed = ref, self.guessed + len(group)
                self._ahead.update((id(r), (r, ref, k)) for k, r in enumerate(group))

    def _reap(self) -> None:
        """Wait for at least one task in flight to finish; forget every one that has."""
        refs = list(self._running)
        self._ray.wait(refs, num_returns=1)
        ready, _ = self._ray.wait(refs, num_returns=len(refs), timeout=0)
        for ref in ready:
            self._load[self._running.pop(ref)] -= 1

    def close(self) -> None:
        """Kill the actors (if this pool started them), once the guesses still running have
        ended: a task killed with its actor is retried, and Ray says so on the terminal."""
        if not self._owner:
            return
        if self._running:
            self._ray.wait(list(self._running), num_returns=len(self._running), timeout=10)
        for actor in self.actors:
            self._ray.kill(actor)


def _unique(requests: Iterable[RolloutRequest]) -> list[RolloutRequest]:
    """Each request object once, in order (the same object asked twice is one rollout)."""
    seen: dict[int, RolloutRequest] = {}
    for r in requests:
        seen.setdefault(id(r), r)
    return list(seen.values())
