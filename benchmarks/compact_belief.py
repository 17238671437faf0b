"""Plan on a compact belief, measure on the full one (the paper's Appendix 2).

    .venv/bin/python benchmarks/compact_belief.py [--alphas 0 1 2 3 4 5 6 7 8] [--seeds 5]
        [--planners bilba-variable bilba-fixed] [--jobs 2] [--timeout 300] [--figure PNG]

Peg-in-hole with the grasp uncertain on three axes at once: x ±1 cm, z ±5 mm, pitch ±3°.
b_full is the 6 extremal particles (±n on one axis each) and 8 drawn inside the ellipsoid of
the bounds (the task's `extremal+random` belief, seed 0). b_plan(α) is the 6 extremal ones
and α of the 8, drawn without replacement (seeded by the plan's seed); b_plan(8) = b_full.
Each (planner, α, seed) plans in-process (one job per CPU with --jobs) and its plan is replayed on
b_full: its success is the fraction of b_full's 14 particles that end in the goal contact.

Prints one row per planner and α (median planning time ± MAD over the seeds, timeouts
counted at the timeout; plans found; median and lowest success on b_full, a plan not found
counting 0), ends with one JSON line, and with --figure draws time and success against α.
The paper (20 plans per α, its hardware): 35–154 s, success 0.93–1.0 (1.0 from α = 1 on,
except α = 3).
"""

import argparse
import json
import os
import platform
import statistics
import time
from concurrent.futures import ProcessPoolExecutor

BOUNDS = ["grasp.x=1cm", "grasp.z=5mm", "grasp.pitch=3deg"]
RANDOM = 8


def full_task():  # type: ignore[no-untyped-def]
    """The peg with the three bounds and b_full as its belief."""
    from bilba_dist.task.loader import build_task, load_task
    from bilba_dist.task.schema import ExtremalRandomBelief

    task = load_task("peg-in-hole", BOUNDS)
    belief = ExtremalRandomBelief(generator="extremal+random", random=RANDOM, seed=0)
    return build_task(task.spec.model_copy(update={"belief": belief}), task.source)


def plan_task(full, alpha: int, seed: int):  # type: ignore[no-untyped-def]
    """``full`` (from full_task) with b_plan(α) for this seed as its belief: explicit
    particles."""
    import numpy as np

    from bilba_dist.belief.particles import initial_belief
    from bilba_dist.task.loader import build_task
    from bilba_dist.task.schema import ExplicitBelief

    offsets = [p.offsets for p in initial_belief(full)]
    extremal, drawn = offsets[:-RANDOM], offsets[-RANDOM:]
    picked = np.random.default_rng(seed).choice(RANDOM, size=alpha, replace=False)
    particles = [
        {
            frame: {k.split(".")[1]: v for k, v in o.items() if k.startswith(f"{frame}.")}
            for frame in ("grasp", "env")
        }
        for o in [*extremal, *(drawn[i] for i in sorted(picked))]
    ]
    belief = ExplicitBelief.model_validate({"generator": "explicit", "particles": particles})
    return build_task(full.spec.model_copy(update={"belief": belief}), full.source)


def run(job: tuple[int, int, str, float]) -> dict:
    from bilba_dist.belief.particles import initial_belief
    from bilba_dist.planning.bilba import plan
    from bilba_dist.plans.replay import replay, success_fraction
    from bilba_dist.workers.rollout_worker import RolloutWorker

    planner, alpha, seed, timeout = job
    full = full_task()
    task = plan_task(full, alpha, seed)
    backend = RolloutWorker(task)
    start = time.perf_counter()
    result = plan(task, backend, planner, seed=seed, timeout_s=timeout)
    elapsed = time.perf_counter() - start
    success = 0.0
    if result.success:
        success = success_fraction(
            replay(full, result.motions, initial_belief(full), backend), full
        )
    backend.close()
    return {
        "planner": planner,
        "alpha": alpha,
        "seed": seed,
        "particles": len(task.spec.belief.particles),
        "found": result.success,
        "time_s": round(elapsed, 1),
        "rollouts": result.rollouts,
        "success": round(success, 3),
    }


def mad(values: list[float]) -> float:
    centre = statistics.median(values)
    return statistics.median(abs(v - centre) for v in values)


def draw(rows: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.5))
    for k, planner in enumerate(sorted({r["planner"] for r in rows})):
        colour = f"C{k}"
        mine = [r for r in rows if r["planner"] == planner]
        alphas = sorted({r["alpha"] for r in mine})
        at = [[r for r in mine if r["alpha"] == a] for a in alphas]
        left.plot(alphas, [statistics.median(r["time_s"] for r in rs) for rs in at], "o-",
                  color=colour, label=planner)  # fmt: skip
        right.plot(alphas, [statistics.median(r["success"] for r in rs) for rs in at], "o-",
                   color=colour, label=f"{planner}, median")  # fmt: skip
        right.plot(alphas, [min(r["success"] for r in rs) for rs in at], "x:",
                   color=colour, label=f"{planner}, lowest")  # fmt: skip
    left.set_xlabel("α: random particles planned on, with the 6 extremal")
    left.set_ylabel("median planning time [s]")
    left.legend()
    right.set_xlabel("α")
    right.set_ylabel("success on b_full (14 particles)")
    right.set_ylim(0, 1.05)
    right.legend(loc="lower right")
    fig.suptitle("Peg, grasp x ±1 cm, z ±5 mm, pitch ±3°: plan on b_plan(α), replay on b_full")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--alphas", nargs="+", type=int, default=list(range(RANDOM + 1)))
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument(
        "--planners",
        nargs="+",
        choices=["bilba-variable", "bilba-fixed", "b-est"],
        default=["bilba-variable", "bilba-fixed"],
    )
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=300.0)
    parser.add_argument("--figure", help="write the figure here (PNG)")
    args = parser.parse_args()
    if any(not 0 <= a <= RANDOM for a in args.alphas):
        parser.error(f"--alphas: each must be in 0..{RANDOM}")
    jobs = [
        (p, a, s, args.timeout)
        for p in args.planners
        for a in args.alphas
        for s in range(args.seeds)
    ]
    print(f"# {platform.node()}, {os.cpu_count()} CPUs; seeds 0..{args.seeds - 1}")
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(run, jobs))
    header = ("planner", "α", "particles", "time s", "found", "success", "lowest")
    print("{:<15} {:>2} {:>9} {:>13} {:>6} {:>8} {:>7}".format(*header))
    summary = {}
    for p in args.planners:
        for a in args.alphas:
            mine = [r for r in rows if r["planner"] == p and r["alpha"] == a]
            times = [r["time_s"] if r["found"] else args.timeout for r in mine]
            success = statistics.median(r["success"] for r in mine)
            lowest = min(r["success"] for r in mine)
            found = sum(r["found"] for r in mine)
            time_s = f"{statistics.median(times):.1f} ± {mad(times):.1f}"
            print(f"{p:<15} {a:>2} {mine[0]['particles']:>9} {time_s:>13} "
                  f"{found:>3}/{len(mine):<2} {success:>8.3f} {lowest:>7.3f}")  # fmt: skip
            summary[f"{p}/{a}"] = {
                "median_time_s": statistics.median(times),
                "success": success,
                "lowest": lowest,
            }
    if args.figure:
        draw(rows, args.figure)
    print(json.dumps({"rows": rows, "summary": summary}))


if __name__ == "__main__":
    main()
