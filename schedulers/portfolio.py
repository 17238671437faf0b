"""Portfolio planning: N independently seeded searches of one problem side by side on Ray,
the first plan found wins and the others are cancelled.

Planning time varies several-fold between seeds of one problem (the peg's grasp.x ±2 cm,
bilba-fixed: 6.3, 18.8 and 28.2 s), so the first of N searches comes in well before a
typical one. Each search is a Ray task on one CPU with its rollouts in-process (the batch's
`execute_job`), so a cluster's CPUs each run a search. A search is a pure function of its
seed: the winner's plan is the plan `bilba plan --seed S` makes alone; which seed wins
depends on timing, and the result records it.
"""

from dataclasses import dataclass
from typing import Any

from bilba_dist.planning.bilba import Variant
from bilba_dist.rollout import DynamicsModel
from bilba_dist.schedulers.batch import JOB_RETRIES, execute_job
from bilba_dist.schedulers.jobs import Job
from bilba_dist.task.loader import Task


@dataclass
class PortfolioResult:
    winner: int | None  # the seed whose plan came in first; None when no search found one
    output: dict[str, Any]  # that search's execute_job output (or the last one's, no plan)
    finished: dict[int, str]  # seed -> status of every search that ended before the winner
    cancelled: list[int]


def _stop(ray: Any, refs: list, grace_s: float = 5.0) -> None:
    """Cancel the searches still running. A plain cancel interrupts a search between two
    Python steps and leaves its worker process alive, so the next searches of the session
    start warm (a forced cancel kills the process: the next search on that CPU then pays
    the imports and the world's set-up again, ~1.7 s a search on a 2-core laptop). A search
    that has not stopped after ``grace_s`` is killed."""
    for ref in refs:
        ray.cancel(ref)
    _, stuck = ray.wait(refs, num_returns=len(refs), timeout=grace_s)
    for ref in stuck:
        ray.cancel(ref, force=True)


def run_portfolio(
    task: Task,
    variant: Variant,
    seeds: list[int],
    timeout_s: float | None,
    model: DynamicsModel = "panda",
    actors: int = 0,
) -> PortfolioResult:
    """Run one search per seed in the current Ray session; return the first plan found.
    With ``actors``, each search plans in a task of no CPU of its own and runs its rollouts
    on that many actors of one CPU each (N searches then take N × ``actors`` CPUs)."""
    import ray

    remote = ray.remote(num_cpus=0 if actors else 1, max_retries=JOB_RETRIES)(execute_job)
    timeout = timeout_s if timeout_s is not None else task.spec.planner.timeout_s
    pending = {
        remote.remote(
            Job(f"portfolio-s{seed}", task.name, "", (), variant, seed, timeout, model),
            task.spec,
            task.source,
            actors,
        ): seed
        for seed in seeds
    }
    finished: dict[int, str] = {}
    output: dict[str, Any] = {}
    while pending:
        (ref,), _ = ray.wait(list(pending), num_returns=1)
        seed = pending.pop(ref)
        output = ray.get(ref)
        if output["status"] == "success":
            _stop(ray, list(pending))
            return PortfolioResult(seed, output, finished, sorted(pending.values()))
        finished[seed] = output["status"]
    return PortfolioResult(None, output, finished, [])
