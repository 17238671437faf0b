"""Portfolio planning: time to the first plan with N searches against one, on one Ray
instance.

    .venv/bin/python benchmarks/portfolio.py [--problems 10] [--setting peg-x2-fixed]
        [--ns 1 2] [--cpus 2] [--parallel 1] [--search-actors 0]

Problem p is planned with seed p alone (N = 1), then with seeds p, p + 1000, p + 2000, ...
side by side (each N of ``--ns``), in one Ray session of ``--cpus`` CPUs (a warm-up job on
every CPU first, so Numba's cache load and Ray's worker start-up are paid before timing).
``--parallel`` problems run at once (each search still has a CPU of its own: keep
``parallel * max(ns)`` within ``--cpus``). With ``--search-actors K`` each search runs its
rollouts on K actors of its own (`bilba plan --portfolio N --search-actors K`), N × K CPUs.
Prints each problem; for each N, its mean and median time to the first plan over
N = 1's, beside the median of the per-problem ratios (about 1 for any two independent
searches: the second seed is the slower on half the problems); and the time to the first
plan expected from N = 2, 8, 16, 64 seeds by order statistics over the N = 1 times (draws
with replacement from their empirical distribution: the expectation can only reach the
fastest seed measured, so more problems sharpen it). Ends with one JSON line.
"""

import argparse
import json
import os
import platform
import statistics
import time
from concurrent.futures import ThreadPoolExecutor

from planning import at_least_one, count  # benchmarks/planning.py

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


def timed(
    task, variant: str, seeds: list[int], timeout: float, actors: int = 0
) -> tuple[float, int | None]:
    start = time.perf_counter()
    found = run_portfolio(task, variant, seeds, timeout, actors=actors)
    return time.perf_counter() - start, found.winner


def problem(task, variant: str, p: int, ns: list[int], timeout: float, actors: int) -> dict:
    row: dict = {"problem": p}
    for n in ns:
        row[f"n{n}_s"], row[f"n{n}_winner"] = timed(
            task, variant, [p + 1000 * k for k in range(n)], timeout, actors
        )
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", type=at_least_one, default=10)
    parser.add_argument("--setting", choices=list(SETTINGS), default="peg-x2-fixed")
    parser.add_argument("--timeout", type=float, default=300.0)
    parser.add_argument("--ns", type=at_least_one, nargs="+", default=[1, 2])
    parser.add_argument("--cpus", type=at_least_one, default=2)
    parser.add_argument("--parallel", type=at_least_one, default=1)
    parser.add_argument("--search-actors", type=count, default=0)
    args = parser.parse_args()
    ns = sorted(set(args.ns) | {1})
    per_search = max(args.search_actors, 1)
    if args.parallel * max(ns) * per_search > args.cpus:
        parser.error(
            f"--parallel {args.parallel} × N {max(ns)} × {per_search} CPUs a search needs more "
            f"than {args.cpus} CPUs"
        )
    name, bound, variant = SETTINGS[args.setting]
    task = load_task(name, [bound])
    print(
        f"# {platform.node()}, {os.cpu_count()} CPUs; {args.setting}; Ray with {args.cpus} "
        f"CPUs; N = {ns}; {args.parallel} problem(s) at a time; "
        f"{args.search_actors or 'no'} rollout actors a search"
    )
    rows = []
    with ray_session(args.cpus, None):
        warm = [999_999 + k for k in range(args.cpus)]  # one short search on every CPU
        with ThreadPoolExecutor(args.cpus) as pool:
            list(pool.map(lambda seed: timed(task, variant, [seed], 5.0), warm))
        with ThreadPoolExecutor(args.parallel) as pool:
            for row in pool.map(
                lambda p: problem(task, variant, p, ns, args.timeout, args.search_actors),
                range(args.problems),
            ):
                rows.append(row)
                cells = "   ".join(
                    f"N={n} {row[f'n{n}_s']:6.1f} s (seed {row[f'n{n}_winner']})" for n in ns
                )
                print(f"problem {row['problem']}: {cells}", flush=True)
    singles = [r["n1_s"] for r in rows]
    figures: dict = {
        "setting": args.setting,
        "problems": len(rows),
        "cpus": args.cpus,
        "parallel": args.parallel,
        "search_actors": args.search_actors,
        "median_n1_s": round(statistics.median(singles), 2),
        "mean_n1_s": round(statistics.mean(singles), 2),
    }
    for n in ns[1:]:
        times = [r[f"n{n}_s"] for r in rows]
        mean = statistics.mean(times)
        figures[f"median_n{n}_s"] = round(statistics.median(times), 2)
        figures[f"mean_n{n}_s"] = round(mean, 2)
        figures[f"mean_ratio_n{n}_n1"] = round(mean / statistics.mean(singles), 3)
        ratio = statistics.median(r[f"n{n}_s"] / r["n1_s"] for r in rows)
        figures[f"median_ratio_n{n}_n1"] = round(ratio, 3)
        print(
            f"N={n} / N=1: mean time {figures[f'mean_ratio_n{n}_n1']:.3f}, median time "
            f"{figures[f'median_n{n}_s'] / figures['median_n1_s']:.3f}, median of the "
            f"per-problem ratios {ratio:.3f}"
        )
    figures.update(
        {f"expected_n{n}_s": round(expected_min(singles, n), 2) for n in (1, 2, 8, 16, 64)}
    )
    expected = ", ".join(f"N={n} {figures[f'expected_n{n}_s']} s" for n in (1, 2, 8, 16, 64))
    print(f"expected time to the first plan (order statistics of the N=1 times): {expected}")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
