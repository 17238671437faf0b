"""What robust acceptance (`planner.check_friction`, on by default) costs and buys.

    .venv/bin/python benchmarks/robust_acceptance.py [--settings pitch1 ... y2 puzzle-x1]
        [--seeds 0] [--check 0.5] [--check-random 0] [--jobs 2] [--timeout 300]

For each setting, BILBA variant and seed, plans in-process twice — without robust acceptance
(``check_friction: 0``) and with ``--check`` (the default, 0.5) — and replays each plan on
14 held-out particles drawn inside the bounds (seed 1) at 0.5, 1 and 1.5 times the task's
friction. Every job of both arms runs in this one process pool, so the time ratio is
measured in the same conditions. Prints one row per plan (planning time, rollouts,
held-out fraction per friction), then per setting and variant the median time of each arm,
their ratio and the lowest held-out fraction of each arm, and a JSON line of the same.
Target (issue 21): with, every plan ≥ 0.95 at all three frictions on the peg (≥ 0.9 on the
puzzle), time within 2x of without.
"""

import argparse
import json
import os
import platform
import statistics
import time
from concurrent.futures import ProcessPoolExecutor

SETTINGS = {
    **{f"pitch{d}": ("peg-in-hole", f"grasp.pitch={d}deg") for d in (1, 2, 3, 4)},
    "x1": ("peg-in-hole", "grasp.x=1cm"),
    "x2": ("peg-in-hole", "grasp.x=2cm"),
    "y1": ("peg-in-hole", "env.y=1cm"),
    "y2": ("peg-in-hole", "env.y=2cm"),
    "puzzle-x1": ("puzzle", "grasp.x=1cm"),
}
FRICTIONS = (0.5, 1.0, 1.5)
VARIANTS = ("bilba-fixed", "bilba-variable")


def run(job: tuple[str, str, int, float, int, float]) -> dict:
    from bilba_dist.planning.bilba import plan
    from bilba_dist.plans.replay import validate_plan
    from bilba_dist.task.loader import load_task, with_friction, with_planner
    from bilba_dist.workers.rollout_worker import RolloutWorker

    setting, variant, seed, check, check_random, timeout = job
    name, axis = SETTINGS[setting]
    task = with_planner(
        load_task(name, [axis]), check_friction=check, check_random=check_random, timeout_s=timeout
    )
    start = time.perf_counter()
    worker = RolloutWorker(task)
    result = plan(task, worker, variant, seed=seed)
    worker.close()
    row = {
        "setting": setting,
        "variant": variant,
        "seed": seed,
        "check": check,
        "success": result.success,
        "time_s": round(time.perf_counter() - start, 1),
        "rollouts": result.rollouts,
    }
    for scale in FRICTIONS:
        scaled = with_friction(task, scale)
        worker = RolloutWorker(scaled)
        held = validate_plan(scaled, result.motions, worker, 14, seed=1)
        worker.close()
        row[f"x{scale:g}"] = round(held.held_out or 0.0, 3) if result.success else None
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--settings", nargs="+", choices=list(SETTINGS), default=list(SETTINGS))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--check", type=float, default=0.5)
    parser.add_argument("--check-random", type=int, default=0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=300.0)
    args = parser.parse_args()
    arms = (0.0, args.check)
    jobs = [
        (s, v, seed, check, args.check_random if check else 0, args.timeout)
        for s in args.settings
        for v in VARIANTS
        for seed in args.seeds
        for check in arms
    ]
    print(f"# {platform.node()}, {os.cpu_count()} CPUs; seeds {args.seeds}, {len(jobs)} plans")
    print(f"{'setting':<10}{'variant':<16}{'seed':>5}{'check':>6}{'time s':>8}{'rollouts':>9}"
          "  x0.5   x1    x1.5")  # fmt: skip
    rows = []
    with ProcessPoolExecutor(args.jobs, max_tasks_per_child=1) as pool:  # a fresh world each
        for r in pool.map(run, jobs):
            rows.append(r)
            held = "  ".join(
                "  -  " if r[f"x{f:g}"] is None else f"{r[f'x{f:g}']:.3f}" for f in FRICTIONS
            )
            print(f"{r['setting']:<10}{r['variant']:<16}{r['seed']:>5}{r['check']:>6g}"
                  f"{r['time_s']:>8.1f}{r['rollouts']:>9}  {held}", flush=True)  # fmt: skip
    print(f"\n{'setting':<10}{'variant':<16}{'median s off':>13}{'on':>7}{'ratio':>7}"
          f"{'rollouts ratio':>15}{'held min off':>13}{'on':>7}")  # fmt: skip
    summary = {}
    for s in args.settings:
        for v in VARIANTS:
            off, on = ([r for r in rows if (r["setting"], r["variant"], r["check"]) == (s, v, c)]
                       for c in arms)  # fmt: skip
            t_off, t_on = (
                statistics.median(_time(r, args.timeout) for r in rs) for rs in (off, on)
            )
            n_off, n_on = (sum(r["rollouts"] for r in rs) for rs in (off, on))
            h_off, h_on = (min(_held(r) for r in rs) for rs in (off, on))
            summary[f"{s}/{v}"] = {
                "time_ratio": round(t_on / max(t_off, 1e-9), 2),
                "rollout_ratio": round(n_on / max(n_off, 1), 2),
                "held_min_off": h_off,
                "held_min_on": h_on,
                "planned_on": sum(r["success"] for r in on),
            }
            print(f"{s:<10}{v:<16}{t_off:>13.1f}{t_on:>7.1f}{t_on / max(t_off, 1e-9):>7.2f}"
                  f"{n_on / max(n_off, 1):>15.2f}{h_off:>13.3f}{h_on:>7.3f}")  # fmt: skip
    total = {
        c: sum(_time(r, args.timeout) for r in rows if r["check"] == c) for c in arms
    }  # fmt: skip
    print(f"\nall plans: {total[arms[0]]:.0f} s without, {total[arms[1]]:.0f} s with "
          f"({total[arms[1]] / max(total[arms[0]], 1e-9):.2f}x)")  # fmt: skip
    print(json.dumps(summary))


def _time(row: dict, timeout: float) -> float:
    """Planning time; a run that found no plan counts as the timeout."""
    return row["time_s"] if row["success"] else timeout


def _held(row: dict) -> float:
    """The lowest held-out fraction over the frictions (0 for a run with no plan)."""
    return min((row[f"x{f:g}"] or 0.0) for f in FRICTIONS)


if __name__ == "__main__":
    main()
