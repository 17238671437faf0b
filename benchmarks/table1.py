"""The paper's Table 1 from our batches, beside the paper's own figures.

    .venv/bin/bilba batch deploy/jobs/paper.yaml --out batches/paper
    .venv/bin/bilba batch deploy/jobs/paper-best.yaml --out batches/paper-best
    .venv/bin/bilba batch deploy/jobs/paper-puzzle.yaml --out batches/paper-puzzle
    .venv/bin/python benchmarks/table1.py batches/paper batches/paper-best batches/paper-puzzle

Prints a Markdown table: per task and setting, our median ± MAD planning time (successful
runs) and successes for BILBA-Variable, BILBA-Fixed and B-EST, the paper's three figures
(its hardware; "*" a timeout, "–" not reported; "4 verified" where some plans found did not
pass verification, the best plan of a search whose plans kept failing it), and BILBA / B-EST
(the faster BILBA median over B-EST's, B-EST runs out of time counted at their timeout: "≤",
an upper bound, where any ran out). Ends with one JSON line of the figures the targets read
(issue 22: every peg median ≤ 10 s, every puzzle median ≤ 60 s, 5/5 everywhere, BILBA /
B-EST ≤ 0.1).
"""

import argparse
import json
import statistics
import sys
from pathlib import Path

from bilba_dist.schedulers.batch import read_records
from bilba_dist.schedulers.report import Cell, cells

#: Table 1 of the paper: median planning time [s] (BILBA-Variable, BILBA-Fixed, B-EST); None
#: where it reports none, "*" a timeout.
PAPER: dict[tuple[str, str], tuple[float | str | None, ...]] = {
    ("peg-in-hole", "pitch1"): (10.478, 10.247, 133.955),
    ("peg-in-hole", "pitch2"): (11.046, 10.925, 118.031),
    ("peg-in-hole", "pitch3"): (15.365, 21.149, 264.086),
    ("peg-in-hole", "pitch4"): (70.035, 33.058, 326.984),
    ("peg-in-hole", "x1"): (20.125, 21.054, 186.954),
    ("peg-in-hole", "x2"): (23.362, 39.625, 324.610),
    ("peg-in-hole", "y1"): (29.306, 52.163, 154.711),
    ("peg-in-hole", "y2"): (101.856, 63.38, 383.281),
    ("puzzle", "pitch1"): (155.558, None, 877.72),
    ("puzzle", "pitch2"): (455.588, 741.13, "*"),
    ("puzzle", "x1"): (260.314, 322.438, "*"),
    ("puzzle", "y1"): (566.448, 543.427, "*"),
}
PLANNERS = ("bilba-variable", "bilba-fixed", "b-est")


def shown(value: float | str | None) -> str:
    if value is None:
        return "–"
    return value if isinstance(value, str) else f"{value:.1f}"


def plans(c: Cell) -> str:
    """Plans found of runs, and how many of them passed verification where some did not."""
    unverified = c.verified is not None and c.verified < c.successes
    return f"{c.successes}/{c.runs}" + (f", {c.verified} verified" if unverified else "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("batches", type=Path, nargs="+")
    args = parser.parse_args()
    records = [r for folder in args.batches for r in read_records(folder)]
    by_key = {(c.task, c.setting, c.planner): c for c in cells(records)}
    timeout_of = {(r["task"], r["setting"], r["planner"]): r["timeout_s"] for r in records}
    print("| task | setting | BILBA-V | BILBA-F | B-EST | paper V / F / B-EST | BILBA / B-EST |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    summary: dict[str, object] = {"cells": {}}
    for (task, setting), paper in PAPER.items():
        ours = []
        for planner in PLANNERS:
            c = by_key.get((task, setting, planner))
            if c is None:
                ours.append("not run")
            elif c.median_s is None:
                ours.append(f"* ({plans(c)})")
            else:
                ours.append(f"{c.median_s:.1f} ± {c.mad_s:.1f} ({plans(c)})")
        ratio = "–"
        bilba = [by_key.get((task, setting, p)) for p in PLANNERS[:2]]
        medians = [c.median_s for c in bilba if c is not None and c.median_s is not None]
        best = by_key.get((task, setting, "b-est"))
        if best is not None and medians:
            runs = [
                r["planning_time_s"] if r["status"] == "success" else timeout_of[key]
                for r in records
                if (key := (r["task"], r["setting"], r["planner"])) == (task, setting, "b-est")
            ]
            bound = "≤ " if len(runs) > best.successes else ""
            ratio = f"{bound}{min(medians) / statistics.median(runs):.3f}"
        paper_text = " / ".join(shown(v) for v in paper)
        print(f"| {task} | {setting} | {' | '.join(ours)} | {paper_text} | {ratio} |")
        summary["cells"][f"{task}/{setting}"] = {  # type: ignore[index]
            p: (by_key[(task, setting, p)].median_s if (task, setting, p) in by_key else None)
            for p in PLANNERS
        } | {"bilba_over_best": None if ratio == "–" else float(ratio.removeprefix("≤ "))}
    json.dump(summary, sys.stdout)
    print()


if __name__ == "__main__":
    main()
