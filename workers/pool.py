"""Rollout backends: in-process (one RolloutWorker) and a pool of Ray actors.

`RayPool` hands a batch out in small groups to whichever actor is free (rollouts differ in
length: early stop ends some at 0.5 s, others run 5 s, so fixed halves leave one actor
idle), and returns the results in request order, so a seeded plan is the same on 1 worker
or on N."""

from collections.abc import Sequence

from bilba_dist.rollout import DynamicsModel, RolloutRequest, RolloutResult
from bilba_dist.task.loader import Task
from workers.rollout_worker import RolloutWorker


class RayPool:
    """``workers`` Ray actors, each a RolloutWorker with its own PyBullet worlds."""

    def __init__(self, task: Task, workers: int, model: DynamicsModel = "panda") -> None:
        import ray

        actor = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=-1)(RolloutWorker)
        self._use([actor.remote(task.spec, model) for _ in range(workers)], owner=True)

    def _use(self, actors: list, owner: bool) -> None:
        import ray
        from ray.util import ActorPool

        self._ray, self.actors, self._owner = ray, actors, owner
        self._pool = ActorPool(actors)

    def first(self, workers: int) -> "RayPool":
        """A pool on this pool's first ``workers`` actors (already started and warm), for
        comparing pool sizes back to back on one Ray instance; closing it kills nothing."""
        pool = object.__new__(RayPool)
        pool._use(self.actors[:workers], owner=False)
        return pool

    def simulate(self, requests: Sequence[RolloutRequest]) -> list[RolloutResult]:
        if not requests:
            return []
        if len(self.actors) == 1:  # one call: groups only help to balance several actors
            ref = self.actors[0].simulate.remote(list(requests))
            return list(self._ray.get(ref))
        size = max(1, len(requests) // (4 * len(self.actors)))  # ~4 groups per actor
        groups = [list(requests[i : i + size]) for i in range(0, len(requests), size)]
        done = self._pool.map(lambda actor, group: actor.simulate.remote(group), groups)
        return [r for group in done for r in group]

    def close(self) -> None:
        for actor in self.actors if self._owner else []:
            self._ray.kill(actor)
