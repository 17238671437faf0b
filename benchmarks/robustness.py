"""Do plans hold beyond their particles? Every plan of a batch replayed on held-out particles
at other frictions.

    .venv/bin/python benchmarks/robustness.py BATCH_DIR [--seeds 0] [--held-out 14]
        [--frictions 0.5 1 1.5] [--timestep S] [--draw 1] [--jobs 2]

For each successful job of the batch (`bilba batch`; seed 0 by default) the plan file is read
(the task it holds, or for a version-1 file the task of its name and bounds), and replayed
on its planning particles plus ``--held-out`` particles drawn uniformly inside its bounds
(seed ``--draw``, 1 by default, the same draw at every friction), with the task's friction
scaled by each factor;
with ``--timestep``, at that physics step instead of the plan's (a plan should not depend on
the step it was planned at).
Prints one row per plan (the held-out fraction per friction) and ends with one JSON line:
the minimum over plans per friction and how many plans fall below 0.95 anywhere.
Target (issue 21): every seed-0 peg plan ≥ 0.95 at ×0.5, ×1 and ×1.5.
"""

import argparse
import json
import os
import platform
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from planning import count  # benchmarks/planning.py


def check(job: tuple[str, list[float], int, float | None, int]) -> dict:
    from bilba_dist.plans.file import read_plan
    from bilba_dist.plans.replay import validate_plan
    from bilba_dist.task.loader import with_friction, with_planner
    from bilba_dist.workers.rollout_worker import RolloutWorker

    path, frictions, held_out, timestep, draw = job
    plan = read_plan(Path(path))
    task = plan.task()
    if timestep is not None:
        task = with_planner(task, sim_timestep_s=timestep)
    row: dict = {"plan": Path(path).stem}
    for scale in frictions:
        scaled = with_friction(task, scale)
        worker = RolloutWorker(scaled)
        result = validate_plan(scaled, plan.motions, worker, held_out, seed=draw)
        worker.close()
        row[f"x{scale:g}"] = round(result.held_out or 0.0, 3)
        row[f"planning_x{scale:g}"] = round(result.planning, 3)
    return row


def timestep(text: str) -> float:
    """A physics step [s] inside the task schema's range, checked before any replay."""
    from bilba_dist.task.schema import TIMESTEP_RANGE_S

    low, high = TIMESTEP_RANGE_S
    value = float(text)
    if not low <= value <= high:
        raise argparse.ArgumentTypeError(f"must be within [{low:g}, {high:g}] s, got {text}")
    return value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("batch", type=Path)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--held-out", type=int, default=14)
    parser.add_argument("--frictions", type=float, nargs="+", default=[0.5, 1.0, 1.5])
    parser.add_argument("--timestep", type=timestep, help="physics step [s] (default: the plan's)")
    parser.add_argument("--draw", type=count, default=1, help="seed of the held-out draw")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    records = [json.loads(line) for line in (args.batch / "records.jsonl").open()]
    plans = sorted(
        str(args.batch / r["plan"])
        for r in records
        if r["status"] == "success" and r["seed"] in args.seeds
    )
    step = f"step {args.timestep} s" if args.timestep else "each plan's step"
    step += f"; held-out draw seed {args.draw}"
    print(f"# {platform.node()}, {os.cpu_count()} CPUs; {len(plans)} plans of {args.batch}; {step}")
    jobs = [(p, args.frictions, args.held_out, args.timestep, args.draw) for p in plans]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(check, jobs))
    keys = [f"x{f:g}" for f in args.frictions]
    print(f"{'plan':<44} " + " ".join(f"{k:>6}" for k in keys))
    for row in rows:
        print(f"{row['plan']:<44} " + " ".join(f"{row[k]:>6.3f}" for k in keys))
    summary = {
        "plans": len(rows),
        "timestep_s": args.timestep,
        "draw": args.draw,
        "min": {k: min((r[k] for r in rows), default=None) for k in keys},
        "below_0.95": sum(any(r[k] < 0.95 for k in keys) for r in rows),
    }
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
