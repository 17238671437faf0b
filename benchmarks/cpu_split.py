"""Where a plan's time goes on Ray: CPU seconds by process group — the driver (this
process: the planner's own work and Ray's client threads), the rollout actors, and the rest
of Ray (the raylet, GCS and agents, which ``ray.init`` starts as this process's
descendants) — and the planner's serial time, the wall time with no rollout batch in flight.

Used by `scaling.py`: on one actor the serial time is what a second actor cannot share, so
it bounds the speed-up of one plan (Amdahl's law).
"""

import time
from collections.abc import Collection, Mapping, Sequence

try:
    import psutil
except ImportError:  # the dev extra has it; the main install does not
    raise SystemExit(
        "psutil is missing (it comes with the dev extra): .venv/bin/pip install -e '.[dev]'"
    ) from None

from bilba_dist.rollout import RolloutBackend, RolloutRequest, RolloutResult

GROUPS = ("driver", "actors", "ray")


def _cpu(process: psutil.Process) -> float:
    times = process.cpu_times()
    return times.user + times.system


def cpu_seconds(actor_pids: Collection[int]) -> dict[str, float]:
    """CPU seconds used so far by the driver, the processes in ``actor_pids`` and the rest
    of the driver's descendants. A process that ended since the last call takes its time
    with it (Ray's daemons and actors live as long as the session)."""
    me = psutil.Process()
    split = dict.fromkeys(GROUPS, 0.0)
    split["driver"] = _cpu(me)
    for child in me.children(recursive=True):
        try:
            split["actors" if child.pid in actor_pids else "ray"] += _cpu(child)
        except psutil.NoSuchProcess:
            continue
    return split


def spent(before: dict[str, float], after: dict[str, float]) -> dict[str, float]:
    return {k: after[k] - before[k] for k in GROUPS}


class TimedBackend:
    """A rollout backend that adds up the wall time spent inside ``simulate`` [s]."""

    def __init__(self, backend: RolloutBackend) -> None:
        self.backend = backend
        self.inside_s = 0.0

    def simulate(
        self, requests: Sequence[RolloutRequest], prefetch: Sequence[RolloutRequest] = ()
    ) -> list[RolloutResult]:
        started = time.perf_counter()
        try:
            return self.backend.simulate(requests, prefetch)
        finally:
            self.inside_s += time.perf_counter() - started


def serial_bound(serial_s: float, wall_s: float, actors: int = 2) -> float:
    """The most ``actors`` actors can speed up a plan that took ``wall_s`` on one actor, of
    which ``serial_s`` had no rollout in flight (the planner's work between batches: the
    next batch depends on it), if the rest divided perfectly among them."""
    serial = min(max(serial_s / wall_s, 0.0), 1.0) if wall_s > 0 else 1.0
    return 1.0 / (serial + (1.0 - serial) / actors)


def batch_speedup(one: Mapping[str, float], two: Mapping[str, float]) -> float:
    """How much faster the rollout batches ran on the second split than on the first (each
    with ``wall`` and ``serial`` seconds): the wall time with a batch in flight, one over the
    other. With no serial work at all, the plans themselves would differ by this much."""
    return (one["wall"] - one["serial"]) / (two["wall"] - two["serial"])
