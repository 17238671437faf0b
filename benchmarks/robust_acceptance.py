"""What robust acceptance (`planner.check_friction`) costs and buys, on the peg.

    .venv/bin/python benchmarks/robust_acceptance.py [--settings x1 y1 pitch2] [--seed 0]
        [--check 0.5] [--check-random 0] [--jobs 2] [--timeout 300]

For each setting and BILBA variant, plans seed 0 in-process twice — the defaults, then with
``check_friction`` (and ``check_random``) — and replays each plan on 14 held-out particles
drawn inside the bounds (seed 1) at 0.5, 1 and 1.5 times the task's friction. Prints one
row per plan (planning time, rollouts, held-out fraction per friction) and a JSON line with
the time ratio with/without per cell and the minimum held-out fraction of each side.
"""

import argparse
import json
import os
import platform
import time
from concurrent.futures import ProcessPoolExecutor

SETTINGS = {
    "pitch2": "grasp.pitch=2deg",
    "x1": "grasp.x=1cm",
    "x2": "grasp.x=2cm",
    "y1": "env.y=1cm",
    "y2": "env.y=2cm",
}
FRICTIONS = (0.5, 1.0, 1.5)


def run(job: tuple[str, str, int, float, int, float]) -> dict:
    from bilba_dist.planning.bilba import plan
    from bilba_dist.plans.replay import validate_plan
    from bilba_dist.task.loader import load_task, with_friction, with_planner
    from bilba_dist.workers.rollout_worker import RolloutWorker

    setting, variant, seed, check, check_random, timeout = job
    task = with_planner(
        load_task("peg-in-hole", [SETTINGS[setting]]),
        check_friction=check,
        check_random=check_random,
        timeout_s=timeout,
    )
    start = time.perf_counter()
    result = plan(task, RolloutWorker(task), variant, seed=seed)
    row = {
        "setting": setting,
        "variant": variant,
        "check": check,
        "success": result.success,
        "time_s": round(time.perf_counter() - start, 1),
        "rollouts": result.rollouts,
    }
    for scale in FRICTIONS:
        scaled = with_friction(task, scale)
        held = validate_plan(scaled, result.motions, RolloutWorker(scaled), 14, seed=1)
        row[f"x{scale:g}"] = round(held.held_out or 0.0, 3) if result.success else None
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--settings", nargs="+", choices=list(SETTINGS), default=["x1", "y1"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--check", type=float, default=0.5)
    parser.add_argument("--check-random", type=int, default=0)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=300.0)
    args = parser.parse_args()
    jobs = [
        (s, v, args.seed, check, args.check_random if check else 0, args.timeout)
        for s in args.settings
        for v in ("bilba-fixed", "bilba-variable")
        for check in (0.0, args.check)
    ]
    print(f"# {platform.node()}, {os.cpu_count()} CPUs; peg-in-hole, seed {args.seed}")
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(run, jobs))
    print(
        f"{'setting':<8}{'variant':<16}{'check':>6}{'time s':>8}{'rollouts':>9}  x0.5   x1   x1.5"
    )
    for r in rows:
        held = "  ".join(
            "  -  " if r[f"x{f:g}"] is None else f"{r[f'x{f:g}']:.3f}" for f in FRICTIONS
        )
        print(f"{r['setting']:<8}{r['variant']:<16}{r['check']:>6g}{r['time_s']:>8.1f}"
              f"{r['rollouts']:>9}  {held}")  # fmt: skip
    pairs = {}
    for off, on in zip(rows[::2], rows[1::2], strict=True):
        key = f"{off['setting']}/{off['variant']}"
        pairs[key] = {
            "time_ratio": round(on["time_s"] / max(off["time_s"], 1e-9), 2),
            "held_min_off": min((off[f"x{f:g}"] or 0.0) for f in FRICTIONS),
            "held_min_on": min((on[f"x{f:g}"] or 0.0) for f in FRICTIONS),
        }
    print(json.dumps(pairs))


if __name__ == "__main__":
    main()
