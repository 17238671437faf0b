"""Planning time, success and rollouts for the paper's settings, both BILBA variants.

    .venv/bin/python benchmarks/planning.py [--seeds 5] [--workers 2] [--timeout 300]
        [--settings peg-pitch peg-x peg-y puzzle-x] [--planners bilba-variable bilba-fixed b-est]
        [--model panda|floating] [--sample-patience N] [--race-contacts N] [--near-edges M]
        [--press M]

Each plan runs on a pool of Ray rollout actors (local, --workers CPUs) started once per
setting; the time quoted is the planner's own (Ray and actor start-up excluded), including,
with `--model floating`, the replay that validates each plan on the Panda.
`--sample-patience`, `--race-contacts`, `--near-edges` and `--press` replace the task
files' `planner.sample_patience`, `planner.race_contacts`, `planner.near_edge_m` and
`planner.setpoint_press_m` (to compare settings without copying a task file). Prints a
table of median ± MAD per cell and ends with one JSON line (times in keys ending `_s`).
Targets (issue 4, this 2-core machine): peg-in-hole median ≤ 10 s, puzzle ≤ 60 s, all
successful.
"""

import argparse
import json
import os
import platform
import statistics
import sys

from bilba_dist.planning.bilba import PLANNERS, plan
from bilba_dist.schedulers.session import ray_session
from bilba_dist.task.loader import load_task, with_planner
from bilba_dist.workers.pool import RayPool
from bilba_dist.workers.rollout_worker import RolloutWorker

SETTINGS = {
    "peg-pitch": ("peg-in-hole", "grasp.pitch=2deg"),
    "peg-x": ("peg-in-hole", "grasp.x=1cm"),
    "peg-y": ("peg-in-hole", "env.y=1cm"),
    "puzzle-x": ("puzzle", "grasp.x=1cm"),
}


def count(text: str) -> int:
    """A planner count, 0 or more, checked here so a bad one fails before Ray starts."""
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {value}")
    return value


def at_least_one(text: str) -> int:
    """A count of CPUs, actors, searches or seeds: 1 or more."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be 1 or more, got {value}")
    return value


def metres(text: str) -> float:
    """A planner length in metres, 0 or more."""
    value = float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {value}")
    return value


def mad(values: list[float]) -> float:
    centre = statistics.median(values)
    return statistics.median(abs(v - centre) for v in values)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=300.0)
    parser.add_argument("--settings", nargs="+", default=list(SETTINGS), choices=list(SETTINGS))
    parser.add_argument(
        "--planners",
        nargs="+",
        default=["bilba-variable", "bilba-fixed"],  # b-est (minutes per run) only when asked
        choices=list(PLANNERS),
    )
    parser.add_argument("--model", choices=["panda", "floating"], default="panda")
    parser.add_argument("--sample-patience", type=count, default=None)
    parser.add_argument("--race-contacts", type=count, default=None)
    parser.add_argument("--near-edges", type=metres, default=None, metavar="M")
    parser.add_argument("--press", type=metres, default=None, metavar="M")
    args = parser.parse_args()
    overrides = {
        key: value
        for key, value in (
            ("sample_patience", args.sample_patience),
            ("race_contacts", args.race_contacts),
            ("near_edge_m", args.near_edges),
            ("setpoint_press_m", args.press),
        )
        if value is not None
    }
    rows = {}
    with ray_session(args.workers, None):
        for setting in args.settings:
            name, bound = SETTINGS[setting]
            task = with_planner(load_task(name, [bound]), **overrides)
            pool = RayPool(task, args.workers, args.model)
            panda = RolloutWorker(task, "panda") if args.model == "floating" else None
            for planner in args.planners:
                runs = []
                for seed in range(args.seeds):
                    r = plan(
                        task,
                        pool,
                        planner,  # type: ignore[arg-type]
                        seed,
                        args.timeout,
                        validate_on=panda,
                    )
                    runs.append(r)
                    print(
                        f"  {setting} {planner} seed {seed}: {r.success} "
                        f"{r.planning_time_s:.1f} s {r.rollouts} rollouts {r.reason}",
                        file=sys.stderr,
                        flush=True,
                    )
                times = [r.planning_time_s for r in runs]
                rows[setting, planner] = {
                    "median_s": statistics.median(times),
                    "mad_s": mad(times),
                    "success": sum(r.success for r in runs),
                    "runs": len(runs),
                    "median_rollouts": statistics.median(r.rollouts for r in runs),
                }
            pool.close()
    print(
        f"machine: {platform.node()} {platform.machine()}, {os.cpu_count()} cores; "
        f"{args.workers} Ray workers; {args.seeds} seeds; timeout {args.timeout:g} s; "
        f"{args.model} model; planner parameters from the task files"
        + "".join(f", {key} {value}" for key, value in overrides.items())
    )
    print(
        f"{'setting':<10} {'planner':<15} {'median s':>9} {'MAD s':>7} {'success':>8} "
        f"{'rollouts':>9}"
    )
    for (setting, planner), r in rows.items():
        print(
            f"{setting:<10} {planner:<15} {r['median_s']:9.1f} {r['mad_s']:7.1f} "
            f"{r['success']:>4}/{r['runs']:<3} {r['median_rollouts']:9.0f}"
        )
    figures = {
        f"{setting.replace('-', '_')}_{planner.replace('-', '_')}_{key}": value
        for (setting, planner), r in rows.items()
        for key, value in r.items()
    }
    meta = {"model": args.model, **overrides}
    print(json.dumps({**figures, **meta}, sort_keys=True))


if __name__ == "__main__":
    main()
