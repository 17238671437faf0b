"""How planning scales on Ray: one plan on 1 and 2 rollout actors against in-process rollouts,
and a batch grid on 1 and 2 CPUs.

    .venv/bin/python benchmarks/scaling.py [--seeds 5] [--settings peg-pitch peg-x ...]
        [--jobs-seeds 3]

One plan per setting (bilba-variable): each seed in-process, on 1 actor and on 2 (one local
Ray instance with 2 CPUs; the 1-actor pool is the first actor of the 2-actor one), back to
back, so that each ratio compares the same moment of a shared machine; planner time, actor
start-up excluded. A seeded
plan is the same on every backend, so each per-seed ratio compares the same rollouts; the
median of those is quoted. peg-pitch plans are small (~70 rollouts in ~10 batches of a few
each); peg-x plans (~120-600 rollouts) give the headline figures; puzzle-x plans (thousands
of rollouts, a minute or more a seed on 2 actors; only when asked, choose seeds that plan)
are the load scaling is for. Batch: peg-pitch × both planners × N seeds through `run_batch`
with 1 and then 2 CPUs (time from the first submission to the last record). Targets (issue
5): 2 actors ≥ 1.8× one; Ray on one actor ≤ 10 % slower than in-process. Besides, where the
time went: the serial share and the most it allows 2, 4, 8 and 16 actors (Amdahl; batches
of a few rollouts make many actors gain less still), and how much faster 2 actors ran the
batches alone (what one plan would gain with no serial work). Prints a table and one JSON
line.
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
from planning import SETTINGS  # benchmarks/planning.py: name -> (task, uncertainty)

from bilba_dist.planning.bilba import plan
from bilba_dist.schedulers.batch import run_batch
from bilba_dist.schedulers.jobs import load_jobs
from bilba_dist.schedulers.session import ray_session
from bilba_dist.task.loader import load_task
from bilba_dist.workers.pool import RayPool
from bilba_dist.workers.rollout_worker import RolloutWorker


def one_plan(name: str, bound: str, seeds: int) -> tuple[dict[str, list[float]], dict]:
    """Per seed, the plan in-process, on 1 actor and on 2, back to back: the VM's load drifts
    over minutes, and interleaving gives each ratio the same moment. Also, per backend over
    all seeds: the wall time with no rollout batch in flight (serial) and, on Ray, the CPU
    seconds of the driver, the actors and Ray's own processes."""
    task = load_task(name, [bound])
    times: dict[str, list[float]] = {"in-process": [], "1 actor": [], "2 actors": []}
    split = {k: {"wall": 0.0, "serial": 0.0, **dict.fromkeys(GROUPS, 0.0)} for k in times}
    local = RolloutWorker(task, "panda")
    with ray_session(2, None):
        two = RayPool(task, 2)  # one instance with 2 CPUs: the 1-actor pool is its first
        pids = set(ray.get([actor.pid.remote() for actor in two.actors]))
        backends = {"in-process": local, "1 actor": two.first(1), "2 actors": two}
        for backend in backends.values():
            plan(task, backend, seed=99, timeout_s=10)  # warm: worlds built, imports done
        two.guessed = two.guessed_used = 0
        for seed in range(seeds):
            for name, backend in backends.items():
                timed, before = TimedBackend(backend), cpu_seconds(pids)
                wall = plan(task, timed, seed=seed).planning_time_s
                times[name].append(wall)
                for group, cpu in spent(before, cpu_seconds(pids)).items():
                    split[name][group] += cpu
                split[name]["wall"] += wall
                split[name]["serial"] += wall - timed.inside_s
        split["guessed"] = {"submitted": two.guessed, "used": two.guessed_used}
        two.close()
    local.close()
    return times, split


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


def print_split(splits: dict[str, dict], rows: dict[str, dict]) -> None:
    """Where the time went, summed over the seeds: wall, serial (no batch in flight), CPU by
    process group, and the share of the 2 cores' capacity that was used."""
    print(
        f"{'setting':<10}{'backend':<10}{'wall s':>8}{'serial s':>9}{'driver CPU':>11}"
        f"{'actors CPU':>11}{'Ray CPU':>8}{'cores busy':>11}"
    )
    for setting, split in splits.items():
        for name in ("1 actor", "2 actors"):
            s = split[name]
            busy = sum(s[g] for g in GROUPS) / (2 * s["wall"])
            print(
                f"{setting:<10}{name:<10}{s['wall']:>8.2f}{s['serial']:>9.2f}"
                f"{s['driver']:>11.2f}{s['actors']:>11.2f}{s['ray']:>8.2f}{100 * busy:>10.0f}%"
            )
        r, guessed = rows[setting], split["guessed"]
        print(
            f"  {setting}: 2 actors ran the plans {r['two_actor_total_ratio']:.2f}x faster than "
            f"1 (total times); {guessed['submitted']} rollouts guessed ahead on idle actors, "
            f"{guessed['used']} of them used"
        )
        print(
            f"  {setting}: {100 * r['serial_share_1_actor']:.1f} % of the 1-actor wall time had "
            f"no rollout in flight, so 2 actors give at most {r['two_actor_bound']:.2f}x"
            f" (4, 8, 16 actors: {', '.join(f'{b:.1f}x' for b in r['more_actor_bounds'])})"
        )
        print(
            f"  {setting}: while batches were in flight, 2 actors were "
            f"{r['in_batch_speedup']:.2f}x faster than 1: with no serial work at all, one plan "
            f"would run that much faster"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument(
        "--settings", nargs="+", default=["peg-pitch", "peg-x"], choices=list(SETTINGS)
    )
    parser.add_argument("--jobs-seeds", type=int, default=3)
    args = parser.parse_args()
    rows, splits = {}, {}
    for setting in args.settings:
        times, splits[setting] = one_plan(*SETTINGS[setting], args.seeds)
        pairs = zip(times["1 actor"], times["2 actors"], times["in-process"], strict=True)
        ratios = [(one / two, one / local - 1) for one, two, local in pairs]
        one, two = splits[setting]["1 actor"], splits[setting]["2 actors"]
        rows[setting] = {
            "two_actor_speedup": statistics.median(r[0] for r in ratios),
            "ray_overhead": statistics.median(r[1] for r in ratios),
            "serial_share_1_actor": one["serial"] / one["wall"],
            "two_actor_bound": serial_bound(one["serial"], one["wall"]),
            "more_actor_bounds": [serial_bound(one["serial"], one["wall"], n) for n in (4, 8, 16)],
            "in_batch_speedup": batch_speedup(one, two),
            "two_actor_total_ratio": one["wall"] / two["wall"],
            **{f"{k.replace(' ', '_')}_median_s": statistics.median(v) for k, v in times.items()},
        }
    elapsed = batch(args.jobs_seeds)
    print(
        f"machine: {platform.node()} {platform.machine()}, {os.cpu_count()} cores; "
        f"bilba-variable, {args.seeds} seeds"
    )
    print(
        f"{'setting':<10}{'in-process s':>13}{'1 actor s':>10}{'2 actors s':>11}"
        f"{'2 vs 1':>8}{'Ray vs in-process':>19}"
    )
    for setting, r in rows.items():
        print(
            f"{setting:<10}{r['in-process_median_s']:>13.2f}{r['1_actor_median_s']:>10.2f}"
            f"{r['2_actors_median_s']:>11.2f}{r['two_actor_speedup']:>7.2f}x"
            f"{100 * r['ray_overhead']:>+18.1f}%"
        )
    print("targets: 2 actors >= 1.8x one; Ray on 1 actor <= +10 % (medians of per-seed ratios)")
    print_split(splits, rows)
    headline = rows.get("peg-x", next(iter(rows.values())))
    jobs = 2 * args.jobs_seeds
    print(
        f"batch of {jobs} jobs: 1 CPU {elapsed[1]:.1f} s, 2 CPUs {elapsed[2]:.1f} s, "
        f"{elapsed[1] / elapsed[2]:.2f}x"
    )
    print(
        json.dumps(
            {
                "plan_two_actor_speedup": headline["two_actor_speedup"],
                "plan_ray_overhead": headline["ray_overhead"],
                "batch_two_cpu_speedup": elapsed[1] / elapsed[2],
                "settings": rows,
            },
            sort_keys=True,
        )
    )


if __name__ == "__main__":
    main()
