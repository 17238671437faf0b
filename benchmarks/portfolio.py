"""Portfolio planning: time to the first plan with N searches against one, on one Ray
instance.

    .venv/bin/python benchmarks/portfolio.py [--problems 10] [--setting peg-x2-fixed]
        [--ns 1 2] [--cpus 2] [--parallel 1] [--search-actors 0]

Problem p is planned with seed p alone (N = 1), then with seeds p, p + 1000, p + 2000, ...
side by side (each N of ``--ns``), in one Ray session of ``--cpus`` CPUs (a warm-up job on
every CPU first, so Numba's cache load and Ray's worker start-up are paid before timing).
``--parallel`` problems run at once (each search still has a CPU of its own: keep
``parallel * max(ns)`` within ``--cpus``). With ``--search-actors K`` each search runs its
rollouts on K actors of its own (`bilba plan --portfolio N --search-actors K`), N × K CPUs
(K = 1 runs in-process, as K = 0: one actor would only add Ray's cost a rollout).
``--splits 16x1 4x4 1x16`` compares ways of spending the same CPUs on one problem instead:
NxC is N searches of C CPUs each (C = 1: rollouts in the search's process; C > 1: on C
actors of its own), every split of a problem with the same first seeds, back to back; the
first split is the baseline of the ratios.
Prints each problem; for each arm, its mean and median time to the first plan over the
baseline's (N = 1), beside the median of the per-problem ratios (about 1 for any two
independent searches: the second seed is the slower on half the problems); and, when the
baseline is one search (of any CPUs), the time to the first plan expected from N = 2, 8, 16, 64
seeds by order statistics over its times (draws with replacement from their empirical
distribution: the expectation can only reach the fastest seed measured, so more problems
sharpen it). Ends with one JSON line.
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


def split(text: str) -> tuple[int, int]:
    """``NxC``: N searches of C CPUs each, both 1 or more."""
    searches, sep, cpus = text.lower().partition("x")
    if not sep:
        raise argparse.ArgumentTypeError(f"must be NxC (searches x CPUs a search), got {text!r}")
    return at_least_one(searches), at_least_one(cpus)


def label(arm: tuple[int, int]) -> str:
    return f"{arm[0]}x{arm[1]}"


def problem(task, variant: str, p: int, arms: list[tuple[int, int]], timeout: float) -> dict:
    row: dict = {"problem": p}
    for n, cpus in arms:
        actors = cpus if cpus > 1 else 0
        key = label((n, cpus))
        row[f"{key}_s"], row[f"{key}_winner"] = timed(
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
    parser.add_argument("--splits", type=split, nargs="+")
    args = parser.parse_args()
    if args.splits:
        arms = list(dict.fromkeys(args.splits))
    else:  # one search of the same kind first: the baseline
        per_search = max(args.search_actors, 1)
        arms = [(n, per_search) for n in sorted(set(args.ns) | {1})]
    widest = max(arms, key=lambda arm: arm[0] * arm[1])
    if args.parallel * widest[0] * widest[1] > args.cpus:
        parser.error(
            f"--parallel {args.parallel} × N {widest[0]} × {widest[1]} CPUs a search needs "
            f"more than {args.cpus} CPUs"
        )
    name, bound, variant = SETTINGS[args.setting]
    task = load_task(name, [bound])
    print(
        f"# {platform.node()}, {os.cpu_count()} CPUs; {args.setting}; Ray with {args.cpus} "
        f"CPUs; searches x CPUs a search: {', '.join(map(label, arms))}; {args.parallel} "
        "problem(s) at a time"
    )
    rows = []
    with ray_session(args.cpus, None):
        warm = [999_999 + k for k in range(args.cpus)]  # one short search on every CPU
        with ThreadPoolExecutor(args.cpus) as pool:
            list(pool.map(lambda seed: timed(task, variant, [seed], 5.0), warm))
        with ThreadPoolExecutor(args.parallel) as pool:
            for row in pool.map(
                lambda p: problem(task, variant, p, arms, args.timeout), range(args.problems)
            ):
                rows.append(row)
                cells = "   ".join(
                    f"{label(arm)} {row[f'{label(arm)}_s']:6.1f} s "
                    f"(seed {row[f'{label(arm)}_winner']})"
                    for arm in arms
                )
                print(f"problem {row['problem']}: {cells}", flush=True)
    base = label(arms[0])
    singles = [r[f"{base}_s"] for r in rows]
    figures: dict = {
        "setting": args.setting,
        "problems": len(rows),
        "cpus": args.cpus,
        "parallel": args.parallel,
        "baseline": base,
        f"median_{base}_s": round(statistics.median(singles), 2),
        f"mean_{base}_s": round(statistics.mean(singles), 2),
    }
    for arm in arms[1:]:
        key = label(arm)
        times = [r[f"{key}_s"] for r in rows]
        mean = statistics.mean(times)
        figures[f"median_{key}_s"] = round(statistics.median(times), 2)
        figures[f"mean_{key}_s"] = round(mean, 2)
        figures[f"mean_ratio_{key}"] = round(mean / statistics.mean(singles), 3)
        ratio = statistics.median(r[f"{key}_s"] / r[f"{base}_s"] for r in rows)
        figures[f"median_ratio_{key}"] = round(ratio, 3)
        print(
            f"{key} / {base}: mean time {figures[f'mean_ratio_{key}']:.3f}, median time "
            f"{figures[f'median_{key}_s'] / figures[f'median_{base}_s']:.3f}, median of the "
            f"per-problem ratios {ratio:.3f}"
        )
    if arms[0][0] == 1:
        figures.update(
            {f"expected_n{n}_s": round(expected_min(singles, n), 2) for n in (1, 2, 8, 16, 64)}
        )
        expected = ", ".join(f"N={n} {figures[f'expected_n{n}_s']} s" for n in (1, 2, 8, 16, 64))
        print(f"expected time to the first plan (order statistics of the {base} times): {expected}")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
