"""`bilba report DIR`: the paper-style table of a batch (median ± MAD planning time per cell,
success counts, timeouts as the paper's "*") and a PNG of the same."""

import statistics
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bilba_dist.errors import BilbaError
from bilba_dist.schedulers.batch import RECORDS, read_records


@dataclass(frozen=True)
class Cell:
    task: str
    setting: str
    planner: str
    runs: int
    successes: int
    timeouts: int
    errors: int
    median_s: float | None  # over successful runs
    mad_s: float | None
    median_rollouts: float | None
    #: Successful runs whose plan passed verification (planner.verify_particles); None when
    #: no successful run says (verification off, or records from before it)
    verified: int | None = None


def cells(records: list[dict[str, Any]]) -> list[Cell]:
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = defaultdict(list)
    for r in records:
        groups[(r["task"], r["setting"], r["planner"])].append(r)
    table = []
    for (task, setting, planner), runs in groups.items():
        good = [r for r in runs if r["status"] == "success"]
        times = [r["planning_time_s"] for r in good]
        median = statistics.median(times) if times else None
        table.append(
            Cell(
                task,
                setting,
                planner,
                runs=len(runs),
                successes=len(good),
                timeouts=sum(r["status"] == "timeout" for r in runs),
                errors=sum(r["status"] == "error" for r in runs),
                median_s=median,
                mad_s=statistics.median(abs(t - median) for t in times) if times else None,
                median_rollouts=statistics.median(r["rollouts"] for r in good) if good else None,
                verified=(
                    sum(r.get("verified") is True for r in good)
                    if any(isinstance(r.get("verified"), bool) for r in good)
                    else None
                ),
            )
        )
    return table


def format_table(table: list[Cell]) -> str:
    # a user's task is named by its path in the jobs file: columns as wide as their longest
    wt = max([13, *(len(c.task) for c in table)]) + 1
    ws = max([11, *(len(c.setting) for c in table)]) + 1
    wp = max([15, *(len(c.planner) for c in table)]) + 1
    lines = [
        f"{'task':<{wt}}{'setting':<{ws}}{'planner':<{wp}}{'time s (median ± MAD)':>22}"
        f"{'success':>9}{'verified':>10}{'rollouts':>10}",
    ]
    for c in table:
        if c.median_s is None:
            time_text = "*"
        else:
            time_text = f"{c.median_s:.1f} ± {c.mad_s:.1f}" + (" *" if c.timeouts else "")
        rollouts = f"{c.median_rollouts:.0f}" if c.median_rollouts is not None else "-"
        verified = f"{c.verified}/{c.successes}" if c.verified is not None else "-"
        lines.append(
            f"{c.task:<{wt}}{c.setting:<{ws}}{c.planner:<{wp}}{time_text:>22}"
            f"{f'{c.successes}/{c.runs}':>9}{verified:>10}{rollouts:>10}"
        )
    lines.append("* = some runs timed out (all, when no time is given); times over successes")
    if any(c.verified is not None for c in table):
        lines.append(
            "verified = plans that passed verification, of those found (the rest: the best "
            "plan when verification kept failing)"
        )
    return "\n".join(lines)


def plot(table: list[Cell], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    groups = list(dict.fromkeys((c.task, c.setting) for c in table))
    planners = list(dict.fromkeys(c.planner for c in table))
    width = 0.8 / len(planners)
    fig, ax = plt.subplots(figsize=(max(5, 1.6 * len(groups)), 4), constrained_layout=True)
    for k, planner in enumerate(planners):
        x, y, err = [], [], []
        for g, group in enumerate(groups):
            cell = next(
                (c for c in table if (c.task, c.setting) == group and c.planner == planner), None
            )
            if cell is None or cell.median_s is None:
                continue
            x.append(g + (k - (len(planners) - 1) / 2) * width)
            y.append(cell.median_s)
            err.append(cell.mad_s)
            ax.annotate(
                f"{cell.successes}/{cell.runs}",
                (x[-1], y[-1]),
                ha="center",
                va="bottom",
                fontsize=7,
            )
        ax.bar(x, y, width, yerr=err, capsize=3, label=planner)
    ax.set_xticks(np.arange(len(groups)), [f"{t}\n{s}" for t, s in groups], fontsize=8)
    ax.set_ylabel("planning time [s] (median ± MAD)")
    ax.legend(fontsize=8)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def report(folder: Path, png: Path | None = None) -> tuple[str, Path]:
    if not (folder / RECORDS).exists():
        raise BilbaError(f"{folder}: no {RECORDS} here; is it a `bilba batch --out` folder?")
    records = read_records(folder)
    if not records:
        lines = (folder / RECORDS).read_bytes().count(b"\n")
        plural = "s" if lines != 1 else ""
        other = f" ({lines} line{plural}, none a job record of `bilba batch`)" if lines else ""
        raise BilbaError(f"{folder / RECORDS}: no job records yet{other}")
    table = cells(records)
    png = png or folder / "report.png"
    try:
        png.parent.mkdir(parents=True, exist_ok=True)
        plot(table, png)
    except OSError as exc:
        raise BilbaError(f"{png}: cannot write the figure: {exc.strerror or exc}") from None
    return format_table(table), png
