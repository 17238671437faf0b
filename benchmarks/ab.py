"""Two batches of the same jobs, compared run by run: is a change better, or luck?

    .venv/bin/bilba batch JOBS.yaml --out batches/a        # the default
    .venv/bin/bilba batch JOBS-B.yaml --out batches/b      # the change (a task-file copy)
    .venv/bin/python benchmarks/ab.py batches/a batches/b --ignore-task

Runs are paired by task, setting, planner and seed (`--ignore-task`: by setting, planner and
seed, for a change made in a copy of the task file). A seed's rollouts are the same on any
machine, so the paired ratio of rollouts B / A is free of the machine's drift; its spread is
the search's own: one seed of the puzzle swings 10x either way under a small change. So the
script gives each ratio with a 90 % bootstrap interval over the pairs (seeded): a change whose
interval straddles 1 is not shown better or worse by these runs. Per cell it prints plans and
verified plans in A → B, median planning times and the geometric mean of the per-seed ratios;
overall, the ratio of total rollouts (what a grid costs) and the geometric mean (what a
typical seed gains). A run out of time counts its rollouts so far, a lower bound ("≥").
Ends with one JSON line of the overall figures.
"""

import argparse
import json
import statistics
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from bilba_dist.schedulers.batch import read_records

Key = tuple[str, ...]


def pairs(a: list[dict[str, Any]], b: list[dict[str, Any]], ignore_task: bool) -> dict:
    """(task, setting, planner, seed) → (record in A, record in B), where both ran it to an
    outcome (a job that crashed is no search to compare)."""

    def key(r: dict[str, Any]) -> Key:
        k = (r["setting"], r["planner"], str(r["seed"]))
        return k if ignore_task else (r["task"], *k)

    left = {key(r): r for r in a if r["status"] != "error"}
    return {k: (left[k], r) for r in b if (k := key(r)) in left and r["status"] != "error"}


def interval(
    x: np.ndarray, y: np.ndarray, statistic: str, seed: int, level: float = 0.9
) -> tuple[float, float, float]:
    """``statistic`` of the pairs (x, y) — "total": Σy / Σx, "geomean": exp(mean log(y/x))
    — and its bootstrap interval (low, high) at ``level``, resampling pairs."""

    def total(x_: np.ndarray, y_: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.sum(y_, axis=axis) / np.sum(x_, axis=axis)

    def geomean(x_: np.ndarray, y_: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.exp(np.mean(np.log(y_ / x_), axis=axis))

    f = total if statistic == "total" else geomean
    value = float(f(x, y))
    if len(x) < 2 or np.all(y / x == (y / x)[0]):
        return value, value, value
    ci = stats.bootstrap(
        (x, y),
        f,
        paired=True,
        vectorized=True,
        confidence_level=level,
        method="percentile",
        n_resamples=4999,
        rng=np.random.default_rng(seed),
    ).confidence_interval
    return value, float(ci.low), float(ci.high)


def shown(value: float, low: float, high: float, censored: bool) -> str:
    bound = "≥ " if censored else ""
    return f"{bound}{value:.2f} [{low:.2f}, {high:.2f}]"


def median_time(records: list[dict[str, Any]]) -> str:
    times = [r["planning_time_s"] for r in records if r["status"] == "success"]
    return f"{statistics.median(times):.1f}" if times else "–"


def tally(records: list[dict[str, Any]]) -> tuple[int, int]:
    """Plans found, and plans that passed verification."""
    return (
        sum(r["status"] == "success" for r in records),
        sum(bool(r.get("verified")) for r in records),
    )


def counts(records: list[dict[str, Any]]) -> str:
    plans, verified = tally(records)
    return f"{plans}/{len(records)}, {verified} verified"


def table(matched: dict, seed: int) -> tuple[list[str], dict[str, Any]]:
    cells: dict[Key, list[Key]] = defaultdict(list)
    for k in matched:
        cells[k[:-1]].append(k)
    lines = [
        "| cell | pairs | plans A → B | median s A → B | rollouts B / A, geomean [90 %] |",
        "| --- | --- | --- | --- | --- |",
    ]
    for cell, keys in sorted(cells.items()):
        a, b = [matched[k][0] for k in keys], [matched[k][1] for k in keys]
        x, y = _rollouts(a), _rollouts(b)
        censored = any(r["status"] == "timeout" for r in b)
        lines.append(
            f"| {' '.join(cell)} | {len(keys)} | {counts(a)} → {counts(b)} | "
            f"{median_time(a)} → {median_time(b)} | "
            f"{shown(*interval(x, y, 'geomean', seed), censored)} |"
        )
    a, b = [r for r, _ in matched.values()], [r for _, r in matched.values()]
    x, y = _rollouts(a), _rollouts(b)
    tot, geo = interval(x, y, "total", seed), interval(x, y, "geomean", seed)
    lines += [
        "",
        f"all {len(matched)} pairs: plans {counts(a)} → {counts(b)}; rollouts "
        f"{int(x.sum())} → {int(y.sum())}, total B / A {shown(*tot, False)}, "
        f"geomean {shown(*geo, False)}",
    ]
    (plans_a, verified_a), (plans_b, verified_b) = tally(a), tally(b)
    figures = {
        "pairs": len(matched),
        "plans": [plans_a, plans_b],
        "verified": [verified_a, verified_b],
        "rollouts": [int(x.sum()), int(y.sum())],
        "total_ratio": [round(v, 3) for v in tot],
        "geomean_ratio": [round(v, 3) for v in geo],
    }
    return lines, figures


def _rollouts(records: list[dict[str, Any]]) -> np.ndarray:
    """Each run's rollouts (at least one, so a ratio is defined)."""
    return np.array([max(int(r.get("rollouts") or 0), 1) for r in records], dtype=float)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("a", type=Path, help="the baseline batch folder")
    parser.add_argument("b", type=Path, help="the changed batch folder")
    parser.add_argument(
        "--ignore-task", action="store_true", help="pair by setting, planner and seed only"
    )
    parser.add_argument("--seed", type=int, default=0, help="the bootstrap's seed")
    args = parser.parse_args(argv)
    if args.seed < 0:
        sys.exit("error: --seed must be ≥ 0")
    records = []
    for folder in (args.a, args.b):
        found = read_records(folder) if folder.is_dir() else []
        if not found:
            sys.exit(f"error: no batch records in {folder}")
        records.append(found)
    matched = pairs(*records, args.ignore_task)
    if not matched:
        hint = "" if args.ignore_task else " (a change made in a task-file copy: --ignore-task)"
        sys.exit(f"error: no run of {args.b} has a twin in {args.a}{hint}")
    lines, figures = table(matched, args.seed)
    print("\n".join(lines))
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
