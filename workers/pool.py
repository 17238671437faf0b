"""Rollout backends: in-process (one RolloutWorker) and a pool of Ray actors.

`RayPool` splits a batch into contiguous slices, one per actor, and concatenates the
results in request order, so a seeded plan is the same on 1 worker or on N."""

from collections.abc import Sequence

from bilba_dist.rollout import DynamicsModel, RolloutRequest, RolloutResult
from bilba_dist.task.loader import Task
from workers.rollout_worker import RolloutWorker


class RayPool:
    """``workers`` Ray actors, each a RolloutWorker with its own PyBullet worlds."""

    def __init__(self, task: Task, workers: int, model: DynamicsModel = "panda") -> None:
        import ray

        self._ray = ray
        actor = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=-1)(RolloutWorker)
        self.actors = [actor.remote(task.spec, model) for _ in range(workers)]

    def simulate(self, requests: Sequence[RolloutRequest]) -> list[RolloutResult]:
        if not requests:
            return []
        n = len(self.actors)
        size = -(-len(requests) // n)
        parts = [list(requests[i : i + size]) for i in range(0, len(requests), size)]
        futures = [
            a.simulate.remote(part)  # type: ignore[attr-defined]
            for a, part in zip(self.actors, parts, strict=False)
        ]
        return [r for part in self._ray.get(futures) for r in part]

    def close(self) -> None:
        for actor in self.actors:
            self._ray.kill(actor)  # type: ignore[arg-type]
