"""What logging costs: planning time with and without the MCAP log, and bytes per transition.

    .venv/bin/python benchmarks/mcap_logging.py [--seeds 5]

(Not "logging.py": a script of that name in benchmarks/ shadows the standard library
module for every other script run from this folder.)

peg-in-hole at grasp.pitch=2deg, rollouts in-process (one worker, so Ray adds no noise),
runs with and without a log interleaved per seed. Two measures of the overhead: the ratio of
median planning times (end to end, but two noisy numbers), and the time spent inside the
writer's hooks over the planning time of the same run (exact, what logging itself costs).
Prints a table and one JSON line. Target (issue 6): overhead ≤ 5 %.
"""

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from bilba_dist.planning.bilba import plan
from bilba_dist.record.writer import LogWriter
from bilba_dist.task.loader import load_task
from bilba_dist.workers.rollout_worker import RolloutWorker


class Timed:
    """The writer, with the time spent in its planner hooks added up."""

    HOOKS = ("schedule", "pruned", "transition", "gp_round")

    def __init__(self, writer: LogWriter) -> None:
        self.writer, self.seconds = writer, 0.0

    def __getattr__(self, name: str) -> Any:
        hook = getattr(self.writer, name)
        if name not in self.HOOKS:
            return hook

        def timed(*args: Any, **kwargs: Any) -> None:
            start = time.perf_counter()
            hook(*args, **kwargs)
            self.seconds += time.perf_counter() - start

        return timed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    task = load_task("peg-in-hole", ["grasp.pitch=2deg"])
    worker = RolloutWorker(task, "panda")
    plan(task, worker, seed=0)  # warm the worlds
    plain, logged, per_transition, inside = [], [], [], []
    with tempfile.TemporaryDirectory() as folder:
        for seed in range(args.seeds):
            # Alternate which run goes first, so neither always gets the warmer caches.
            for with_log in (seed % 2 == 0, seed % 2 == 1):
                if not with_log:
                    plain.append(plan(task, worker, seed=seed).planning_time_s)
                    continue
                log = LogWriter(Path(folder) / f"{seed}.mcap", task, "bilba-variable", seed)
                timed = Timed(log)
                result = plan(task, worker, seed=seed, recorder=timed)  # type: ignore[arg-type]
                inside.append(timed.seconds / result.planning_time_s)
                log.finish(
                    "{}",
                    {"success": result.success, "reason": "", "planning_time_s": 0, "rollouts": 0},
                )
                logged.append(result.planning_time_s)
                per_transition.append(log.path.stat().st_size / max(1, log.transitions))
    ratio = statistics.median(logged) / statistics.median(plain)
    print(
        f"machine: {platform.node()} {platform.machine()}, {os.cpu_count()} cores; "
        f"{args.seeds} seeds, in-process rollouts"
    )
    print(f"without log: median {statistics.median(plain):.2f} s")
    print(f"with log:    median {statistics.median(logged):.2f} s  ({100 * (ratio - 1):+.1f} %)")
    print(f"time inside the writer: median {100 * statistics.median(inside):.2f} % of planning")
    print(f"bytes per transition: median {statistics.median(per_transition):.0f}")
    print(
        json.dumps(
            {
                "plain_median_s": statistics.median(plain),
                "logged_median_s": statistics.median(logged),
                "overhead_ratio": ratio,
                "writer_fraction": statistics.median(inside),
                "bytes_per_transition": statistics.median(per_transition),
            },
            sort_keys=True,
        )
    )


if __name__ == "__main__":
    main()
