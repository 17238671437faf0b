"""Portfolio planning: time to the first plan with N searches against one, on one Ray
instance.

    .venv/bin/python benchmarks/portfolio.py [--problems 10] [--setting peg-x2-fixed]

Problem p is planned with seed p alone (N = 1), then with seeds p and p + 1000 side by side
(N = 2), in one Ray session of 2 CPUs (a warm-up job first, so Numba's compile and Ray's
worker start-up are paid before timing). Prints each pair, the median of the ratios, and the
time to the first plan expected from N = 8, 16, 64 seeds by order statistics over the N = 1
times (draws with replacement from their empirical distribution: the expectation can only
reach the fastest seed measured, so more problems sharpen it). Ends with one JSON line.
"""

import argparse
import json
import os
import platform
import statistics
import time

from bilba_dist.schedulers.portfolio import run_portfolio
from bilba_dist.schedulers.session import ray_session
from bilba_dist.task.loader import load_task

SETTINGS = {
    "peg-x2-fixed": ("peg-in-hole", "grasp.x=2cm", "bilba-fixed"),
    "peg-y2-variable": ("peg-in-hole", "env.y=2cm", "bilba-variable"),
    "puzzle-x-variable": ("puzzle", "grasp.x=1cm", "bilba-variable"),
    "puzzle-y-variable": ("puzzle", "env.y=1cm", "bilba-variable"),
}


def expected_min(times: list[float], n: int) -> float:
    """E[min of n draws with replacement from ``times``]."""
    ordered, m = sorted(times), len(times)
    return sum(t * ((m - i) ** n - (m - i - 1) ** n) / m**n for i, t in enumerate(ordered))


def timed(task, variant: str, seeds: list[int], timeout: float) -> tuple[float, int | None]:
    start = time.perf_counter()
    found = run_portfolio(task, variant, seeds, timeout)
    return time.perf_counter() - start, found.winner


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", type=int, default=10)
    parser.add_argument("--setting", choices=list(SETTINGS), default="peg-x2-fixed")
    parser.add_argument("--timeout", type=float, default=300.0)
    args = parser.parse_args()
    name, bound, variant = SETTINGS[args.setting]
    task = load_task(name, [bound])
    print(f"# {platform.node()}, {os.cpu_count()} CPUs; {args.setting}; Ray with 2 CPUs")
    rows = []
    with ray_session(2, None):
        timed(task, variant, [999_999], args.timeout)  # warm-up
        for p in range(args.problems):
            one, _ = timed(task, variant, [p], args.timeout)
            two, winner = timed(task, variant, [p, p + 1000], args.timeout)
            rows.append({"problem": p, "n1_s": one, "n2_s": two, "n2_winner": winner})
            print(
                f"problem {p}: N=1 {one:6.1f} s   N=2 {two:6.1f} s (seed {winner} won)", flush=True
            )
    ratios = [r["n2_s"] / r["n1_s"] for r in rows]
    singles = [r["n1_s"] for r in rows]
    figures = {
        "setting": args.setting,
        "problems": len(rows),
        "median_n1_s": round(statistics.median(singles), 2),
        "median_n2_s": round(statistics.median(r["n2_s"] for r in rows), 2),
        "median_ratio_n2_n1": round(statistics.median(ratios), 3),
        **{f"expected_n{n}_s": round(expected_min(singles, n), 2) for n in (1, 2, 8, 16, 64)},
    }
    print(f"median N=2 / N=1: {figures['median_ratio_n2_n1']:.3f}")
    expected = ", ".join(f"N={n} {figures[f'expected_n{n}_s']} s" for n in (1, 2, 8, 16, 64))
    print(f"expected time to the first plan (order statistics of the N=1 times): {expected}")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
