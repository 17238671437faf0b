"""How planning scales on Ray: one plan on 1, 2, ... rollout actors against in-process
rollouts, and a batch grid on 1, 2, ... CPUs.

    .venv/bin/python benchmarks/scaling.py [--seeds 5] [--settings peg-pitch peg-x ...]
        [--jobs-seeds 3] [--actors 1 2] [--batch-cpus 1 2]

One plan per setting (bilba-variable): each seed in-process and on each pool size of
``--actors`` (one local Ray instance with as many CPUs as the largest pool; a smaller pool
is the first actors of the largest), back to back, so that each ratio compares the same
moment of a shared machine; planner time, actor start-up excluded. A seeded plan is the same
on every backend, so each per-seed ratio compares the same rollouts; the median of those is
quoted. peg-pitch plans are small (~70 rollouts in ~10 batches of a few each); peg-x plans
(~120-600 rollouts) give the headline figures; puzzle-x plans (thousands of rollouts, a
minute or more a seed on 2 actors; only when asked, choose seeds that plan) are the load
scaling is for. Batch: peg-pitch × both planners × N seeds through `run_batch` with each of
``--batch-cpus`` CPUs in turn (time from the first submission to the last record). Targets
(issue 5): 2 actors ≥ 1.8× one; Ray on one actor ≤ 10 % slower than in-process. Besides,
where the time went: the serial share and the most it allows 2, 4, 8 and 16 actors (Amdahl;
batches of a few rollouts make many actors gain less still), and how much faster each pool
ran the batches alone (what one plan would gain with no serial work). Past two actors, run
it on a machine with the cores (`--actors 1 2 4 8 16 --batch-cpus 1 2 4 8 16`). Prints a
table and one JSON line.
"""

import argparse
import json
import os
import platform
import statistics
import tempfile
from pathlib import Path

import ray
from cpu_split import GROUPS, TimedBackend, batch_speedup, cpu_seconds, serial_bound, spent
from planning import SETTINGS, at_least_one  # benchmarks/planning.py

from bilba_dist.planning.bilba import plan
from bilba_dist.schedulers.batch import run_batch
from bilba_dist.schedulers.jobs import load_jobs
from bilba_dist.schedulers.session import ray_session
from bilba_dist.task.loader import load_task
from bilba_dist.workers.pool import RayPool
from bilba_dist.workers.rollout_worker import RolloutWorker


def label(actors: int) -> str:
    return f"{actors} actor" + ("s" if actors > 1 else "")


def one_plan(
    name: str, bound: str, seeds: int, sizes: list[int]
) -> tuple[dict[str, list[float]], dict]:
    """Per seed, the plan in-process and on each pool size, back to back: the VM's load
    drifts over minutes, and interleaving gives each ratio the same moment. Also, per
    backend over all seeds: the wall time with no rollout batch in flight (serial) and, on
    Ray, the CPU seconds of the driver, the actors and Ray's own processes."""
    task = load_task(name, [bound])
    times: dict[str, list[float]] = {"in-process": [], **{label(n): [] for n in sizes}}
    split = {k: {"wall": 0.0, "serial": 0.0, **dict.fromkeys(GROUPS, 0.0)} for k in times}
    local = RolloutWorker(task, "panda")
    with ray_session(max(sizes), None):
        largest = RayPool(task, max(sizes))  # the smaller pools are its first actors
        pids = set(ray.get([actor.pid.remote() for actor in largest.actors]))
        backends: dict = {"in-process": local}
        for n in sizes:
            backends[label(n)] = largest if n == max(sizes) else largest.first(n)
        for backend in (local, largest):  # warm: worlds built, imports done (a smaller
            plan(task, backend, seed=99, timeout_s=10)  # pool is the largest's first actors)
        largest.guessed = largest.guessed_used = 0
        for seed in range(seeds):
            for name, backend in backends.items():
                timed, before = TimedBackend(backend), cpu_seconds(pids)
                wall = plan(task, timed, seed=seed).planning_time_s
                times[name].append(wall)
                for group, cpu in spent(before, cpu_seconds(pids)).items():
                    split[name][group] += cpu
                split[name]["wall"] += wall
                split[name]["serial"] += wall - timed.inside_s
        split["guessed"] = {"submitted": largest.guessed, "used": largest.guessed_used}
        largest.close()
    local.close()
    return times, split


def batch(job_seeds: int, cpu_counts: list[int]) -> dict[int, float]:
    elapsed = {}
    with tempfile.TemporaryDirectory() as folder:
        jobs = Path(folder) / "jobs.yaml"
        jobs.write_text(
            "name: scaling\ntasks: [peg-in-hole]\nuncertainty: {pitch: [grasp.pitch=2deg]}\n"
            f"planners: [bilba-variable, bilba-fixed]\nseeds: {job_seeds}\n"
        )
        grid = load_jobs(jobs)
        for cpus in cpu_counts:
            elapsed[cpus] = run_batch(grid, Path(folder) / f"out{cpus}", workers=cpus).elapsed_s
    return elapsed


def print_split(splits: dict[str, dict], rows: dict[str, dict], sizes: list[int]) -> None:
    """Where the time went, summed over the seeds: wall, serial (no batch in flight), CPU by
    process group, and the share of the pool's cores that was used."""
    print(
        f"{'setting':<10}{'backend':<11}{'wall s':>8}{'serial s':>9}{'driver CPU':>11}"
        f"{'actors CPU':>11}{'Ray CPU':>8}{'cores busy':>11}"
    )
    for setting, split in splits.items():
        for n in sizes:
            s = split[label(n)]
            busy = sum(s[g] for g in GROUPS) / (max(n, 2) * s["wall"])
            print(
                f"{setting:<10}{label(n):<11}{s['wall']:>8.2f}{s['serial']:>9.2f}"
                f"{s['driver']:>11.2f}{s['actors']:>11.2f}{s['ray']:>8.2f}{100 * busy:>10.0f}%"
            )
        r, guessed = rows[setting], split["guessed"]
        for n in sizes[1:]:
            more = r["pools"][str(n)]
            print(
                f"  {setting}: {label(n)} ran the plans {more['total_ratio']:.2f}x faster than "
                f"1 (total times); while batches were in flight, {more['in_batch_speedup']:.2f}x"
                f" (with no serial work at all, one plan would run that much faster)"
            )
        bounds = ", ".join(f"{n}: {b:.1f}x" for n, b in r["amdahl_bounds"].items())
        print(
            f"  {setting}: {100 * r['serial_share_1_actor']:.1f} % of the 1-actor wall time had "
            f"no rollout in flight, so N actors give at most ({bounds}); "
            f"{guessed['submitted']} rollouts guessed ahead on idle actors of the largest "
            f"pool, {guessed['used']} of them used"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=at_least_one, default=5)
    parser.add_argument(
        "--settings", nargs="+", default=["peg-pitch", "peg-x"], choices=list(SETTINGS)
    )
    parser.add_argument("--jobs-seeds", type=at_least_one, default=3)
    parser.add_argument("--actors", type=at_least_one, nargs="+", default=[1, 2])
    parser.add_argument("--batch-cpus", type=at_least_one, nargs="+", default=[1, 2])
    args = parser.parse_args()
    sizes = sorted(set(args.actors) | {1})  # 1 actor is every ratio's baseline
    cpu_counts = sorted(set(args.batch_cpus) | {1})
    rows, splits = {}, {}
    for setting in args.settings:
        times, splits[setting] = one_plan(*SETTINGS[setting], args.seeds, sizes)
        one, alone = times["1 actor"], times["in-process"]
        first = splits[setting]["1 actor"]
        pools = {}
        for n in sizes[1:]:
            more, many = times[label(n)], splits[setting][label(n)]
            pools[str(n)] = {
                "speedup": statistics.median(a / b for a, b in zip(one, more, strict=True)),
                "total_ratio": first["wall"] / many["wall"],
                "in_batch_speedup": batch_speedup(first, many),
                "median_s": statistics.median(more),
            }
        rows[setting] = {
            "ray_overhead": statistics.median(a / b - 1 for a, b in zip(one, alone, strict=True)),
            "serial_share_1_actor": first["serial"] / first["wall"],
            "amdahl_bounds": {
                n: serial_bound(first["serial"], first["wall"], n) for n in (2, 4, 8, 16)
            },
            "pools": pools,
            "in-process_median_s": statistics.median(alone),
            "1_actor_median_s": statistics.median(one),
        }
    elapsed = batch(args.jobs_seeds, cpu_counts)
    print(
        f"machine: {platform.node()} {platform.machine()}, {os.cpu_count()} cores; "
        f"bilba-variable, {args.seeds} seeds"
    )
    print(
        f"{'setting':<10}{'in-process s':>13}{'1 actor s':>10}"
        + "".join(f"{f'{n} actors s':>13}{'vs 1':>7}" for n in sizes[1:])
        + f"{'Ray vs in-process':>19}"
    )
    for setting, r in rows.items():
        print(
            f"{setting:<10}{r['in-process_median_s']:>13.2f}{r['1_actor_median_s']:>10.2f}"
            + "".join(
                f"{r['pools'][str(n)]['median_s']:>13.2f}{r['pools'][str(n)]['speedup']:>6.2f}x"
                for n in sizes[1:]
            )
            + f"{100 * r['ray_overhead']:>+18.1f}%"
        )
    print("targets: 2 actors >= 1.8x one; Ray on 1 actor <= +10 % (medians of per-seed ratios)")
    print_split(splits, rows, sizes)
    jobs = 2 * args.jobs_seeds
    print(
        f"batch of {jobs} jobs: "
        + ", ".join(
            f"{n} CPU{'s' if n > 1 else ''} {elapsed[n]:.1f} s ({elapsed[1] / elapsed[n]:.2f}x)"
            for n in cpu_counts
        )
    )
    headline = rows.get("peg-x", next(iter(rows.values())))
    print(
        json.dumps(
            {
                "plan_speedup": {n: v["speedup"] for n, v in headline["pools"].items()},
                "plan_ray_overhead": headline["ray_overhead"],
                "batch_speedup": {str(n): elapsed[1] / elapsed[n] for n in cpu_counts},
                "cpus": os.cpu_count(),
                "settings": rows,
            },
            sort_keys=True,
        )
    )


if __name__ == "__main__":
    main()
