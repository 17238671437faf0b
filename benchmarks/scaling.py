"""How planning scales on Ray: one plan on 1 and 2 rollout actors against in-process rollouts,
and a batch grid on 1 and 2 CPUs.

    .venv/bin/python benchmarks/scaling.py [--seeds 5] [--jobs-seeds 3]

One plan: peg-in-hole at grasp.pitch=2deg, the same seeds in-process, on a RayPool of 1 and
of 2 actors (one local Ray instance with 2 CPUs; planner time, actor start-up excluded);
ratios are per seed, then the median. Batch: that setting × both planners × N seeds through
`run_batch` with 1 and then 2 CPUs (time from the first submission to the last record).
Targets (issue 5): 2 actors ≥ 1.8× one; Ray on one actor ≤ 10 % slower than in-process.
Prints a table and one JSON line.
"""

import argparse
import json
import os
import platform
import statistics
import tempfile
from pathlib import Path

from bilba_dist.planning.bilba import plan
from bilba_dist.task.loader import load_task
from schedulers.batch import run_batch
from schedulers.jobs import load_jobs
from schedulers.session import ray_session
from workers.pool import RayPool
from workers.rollout_worker import RolloutWorker


def one_plan(seeds: int) -> dict[str, list[float]]:
    task = load_task("peg-in-hole", ["grasp.pitch=2deg"])
    times: dict[str, list[float]] = {"in-process": [], "1 actor": [], "2 actors": []}
    local = RolloutWorker(task, "panda")
    plan(task, local, seed=99)  # warm: worlds built, imports done
    for seed in range(seeds):
        times["in-process"].append(plan(task, local, seed=seed).planning_time_s)
    with ray_session(2, None):
        # One pool at a time: the instance has 2 CPUs and each actor holds one.
        for name, actors in (("1 actor", 1), ("2 actors", 2)):
            pool = RayPool(task, actors)
            plan(task, pool, seed=99)
            for seed in range(seeds):
                times[name].append(plan(task, pool, seed=seed).planning_time_s)
            pool.close()
    return times


def batch(job_seeds: int) -> dict[int, float]:
    elapsed = {}
    with tempfile.TemporaryDirectory() as folder:
        jobs = Path(folder) / "jobs.yaml"
        jobs.write_text(
            "name: scaling\ntasks: [peg-in-hole]\nuncertainty: {pitch: [grasp.pitch=2deg]}\n"
            f"planners: [bilba-variable, bilba-fixed]\nseeds: {job_seeds}\n"
        )
        grid = load_jobs(jobs)
        for cpus in (1, 2):
            elapsed[cpus] = run_batch(grid, Path(folder) / f"out{cpus}", workers=cpus).elapsed_s
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--jobs-seeds", type=int, default=3)
    args = parser.parse_args()
    times = one_plan(args.seeds)
    speedup = statistics.median(
        a / b for a, b in zip(times["1 actor"], times["2 actors"], strict=True)
    )
    overhead = statistics.median(
        a / b - 1 for a, b in zip(times["1 actor"], times["in-process"], strict=True)
    )
    elapsed = batch(args.jobs_seeds)
    print(
        f"machine: {platform.node()} {platform.machine()}, {os.cpu_count()} cores; "
        f"peg-in-hole grasp.pitch=2deg, {args.seeds} seeds"
    )
    print(f"{'rollouts':<12}{'median plan s':>14}")
    for name, values in times.items():
        print(f"{name:<12}{statistics.median(values):>14.2f}")
    print(f"2 actors vs 1 (median of per-seed ratios): {speedup:.2f}x  (target >= 1.8)")
    print(f"Ray on 1 actor vs in-process: {100 * overhead:+.1f} %  (target <= 10 %)")
    jobs = 2 * args.jobs_seeds
    print(
        f"batch of {jobs} jobs: 1 CPU {elapsed[1]:.1f} s, 2 CPUs {elapsed[2]:.1f} s, "
        f"{elapsed[1] / elapsed[2]:.2f}x"
    )
    print(
        json.dumps(
            {
                "plan_two_actor_speedup": speedup,
                "plan_ray_overhead": overhead,
                "batch_two_cpu_speedup": elapsed[1] / elapsed[2],
                "plan_median_s": {k: statistics.median(v) for k, v in times.items()},
            },
            sort_keys=True,
        )
    )


if __name__ == "__main__":
    main()
