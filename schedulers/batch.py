"""Running a grid of planning jobs on Ray, one JSON-lines record per finished job.

Each job is one Ray task (one CPU) that plans with its rollouts in-process: across a grid,
jobs side by side keep every core busy with no batching overhead, where splitting one plan's
small rollout batches over actors does not (docs/cluster.md, Scaling). The job sends its plan
text and MCAP log back to the driver, which alone writes under DIR — so a cluster needs no shared
filesystem, and a job is recorded exactly once: when its result arrives. Ray re-runs a job
whose node or worker process died (``max_retries``); a seeded plan comes out the same.

``DIR/records.jsonl`` is appended and fsynced per job; ``--resume`` skips every job with a
record and runs the rest (those never started and those interrupted). A torn last line (a
killed driver) is ignored and that job runs again. When Ray itself dies under the driver (its
local raylet), the batch stops with one line and records nothing for the jobs left.
"""

import json
import os
import platform
import re
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from bilba_dist.errors import BilbaError, first_line
from bilba_dist.schedulers.jobs import Batch, Job
from bilba_dist.task.loader import build_task
from bilba_dist.task.schema import TaskSpec

RECORDS = "records.jsonl"
#: Ray re-runs a job this many times after a system failure (a dead node or process).
JOB_RETRIES = 3
#: The last lines of a failed job's traceback kept in its record.
TRACEBACK_LINES = 12


def execute_job(job: Job, spec: TaskSpec, source: str, actors: int = 0) -> dict[str, Any]:
    """Plan one job in this process, its rollouts here too or, with ``actors``, on that many
    Ray actors of its own (`--portfolio N --search-actors K`); return its outcome, plan text
    and log bytes."""
    from bilba_dist.planning.bilba import plan
    from bilba_dist.plans.file import dumps, plan_document
    from bilba_dist.record.writer import LogWriter
    from bilba_dist.workers.pool import RayPool
    from bilba_dist.workers.rollout_worker import RolloutWorker

    task = build_task(spec, source)
    worker: RolloutWorker | RayPool = (
        RayPool(task, actors, job.model) if actors else RolloutWorker(task, job.model)
    )
    panda = RolloutWorker(task, "panda") if job.model == "floating" else None
    try:
        with tempfile.TemporaryDirectory() as folder:
            log = LogWriter(
                Path(folder) / "log.mcap", task, job.planner, job.seed, job.model == "panda"
            )
            result = plan(
                task,
                worker,
                job.planner,
                job.seed,
                job.timeout_s,
                recorder=log,
                validate_on=panda,
            )
            text = dumps(plan_document(result, task))
            log.finish(text, result.outcome())
            log_bytes = log.path.read_bytes()
    finally:  # also when a portfolio cancels this search: its actors go with it
        worker.close()
        if panda is not None:
            panda.close()
    if result.success:
        status = "success"
    elif result.timed_out:
        status = "timeout"
    else:
        status = "no-plan"
    return {
        "status": status,
        **result.outcome(),
        "host": platform.node(),
        **({"rollout_actors": actors} if actors else {}),
        "plan_text": text,
        "log_bytes": log_bytes,
    }


@dataclass
class Counts:
    total: int
    skipped: int = 0
    done: int = 0
    failed: int = 0  # no plan, timeout or error
    running: int = 0
    elapsed_s: float = 0.0  # from submitting the first job to recording the last


#: What every record holds, by type: a line without them is not a record of ours.
RECORD_FIELDS: dict[str, type | tuple[type, ...]] = {
    "task": str, "setting": str, "planner": str, "seed": int, "status": str,
}  # fmt: skip
#: ... and what a successful one holds besides.
SUCCESS_FIELDS: dict[str, type | tuple[type, ...]] = {
    "planning_time_s": (int, float), "rollouts": int,
}  # fmt: skip


def is_record(value: Any) -> bool:
    """Whether ``value`` is a job record as ``run_batch`` writes it (an edited or damaged
    line is not: `report` and `--resume` skip it, and `--resume` runs that job again)."""
    if not isinstance(value, dict):
        return False
    fields = {**RECORD_FIELDS, **(SUCCESS_FIELDS if value.get("status") == "success" else {})}
    return all(
        isinstance(value.get(key), kind) and not isinstance(value.get(key), bool)
        for key, kind in fields.items()
    )


def read_records(out: Path) -> list[dict[str, Any]]:
    """The records in DIR, skipping a torn last line and any line that is not a record."""
    path = out / RECORDS
    if not path.exists():
        return []
    records = []
    for line in path.read_bytes().decode("utf-8", errors="replace").splitlines():
        try:
            value = json.loads(line)
        except json.JSONDecodeError:
            continue
        if is_record(value):
            records.append(value)
    return records


def _drop_torn_line(out: Path) -> None:
    """Cut a last line that a killed driver left half-written, so appends stay lines."""
    path = out / RECORDS
    if not path.exists():
        return
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        path.write_bytes(data[: data.rfind(b"\n") + 1])


def _append(out: Path, record: dict[str, Any]) -> None:
    with (out / RECORDS).open("a", encoding="utf-8") as f:
        f.write(json.dumps(record, sort_keys=True) + "\n")
        f.flush()
        os.fsync(f.fileno())


def _store(out: Path, job: Job, result: dict[str, Any]) -> dict[str, Any]:
    """Write the job's plan and log under DIR; return its record."""
    record: dict[str, Any] = asdict(job)
    record["uncertainty"] = list(job.uncertainty)
    if "plan_text" in result:
        plan, log = Path("plans") / f"{job.id}.json", Path("logs") / f"{job.id}.mcap"
        for relative, data in ((plan, result["plan_text"].encode()), (log, result["log_bytes"])):
            (out / relative).parent.mkdir(parents=True, exist_ok=True)
            (out / relative).write_bytes(data)
        record.update(plan=str(plan), log=str(log))
    record.update({k: v for k, v in result.items() if k not in ("plan_text", "log_bytes")})
    record["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    return record


def open_batch_folder(out: Path, resume: bool) -> set[str]:
    """The ids of the jobs recorded in ``out``, made and opened for appending; raises before
    any job runs when ``out`` holds records and ``resume`` is off, or cannot be written (so no
    result is lost to it)."""
    recorded = {r["id"] for r in read_records(out) if isinstance(r.get("id"), str)}
    if recorded and not resume:
        raise BilbaError(
            f"{out} already holds {len(recorded)} job records; "
            "add --resume to run only what is missing, or choose another --out"
        )
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / RECORDS).open("a").close()
    except OSError as exc:
        raise BilbaError(f"{out}: cannot write the batch there: {exc.strerror or exc}") from None
    _drop_torn_line(out)
    return recorded


def run_batch(
    batch: Batch,
    out: Path,
    resume: bool = False,
    workers: int = 2,
    address: str | None = None,
    on_progress: Callable[[Counts], None] = lambda counts: None,
) -> Counts:
    """Run every job of ``batch`` not yet recorded in ``out``; return the counts."""
    import ray

    from bilba_dist.schedulers.session import ray_session

    recorded = open_batch_folder(out, resume)
    todo = [job for job in batch.jobs if job.id not in recorded]
    counts = Counts(total=len(batch.jobs), skipped=len(batch.jobs) - len(todo))
    on_progress(counts)
    if not todo:
        return counts
    with ray_session(workers, address):
        started = time.perf_counter()
        remote = ray.remote(num_cpus=1, max_retries=JOB_RETRIES)(execute_job)
        pending = {
            remote.remote(job, batch.spec(job), batch.tasks[(job.task, job.setting)].source): job
            for job in todo
        }
        cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
        while pending:
            counts.running = min(len(pending), cpus)
            on_progress(counts)
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)
            for ref in ready:
                job = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except ray.exceptions.LocalRayletDiedError:
                    raise _ray_lost(out, counts, len(pending) + 1) from None
                except ray.exceptions.RayError as exc:
                    result = error_result(exc)
                _append(out, _store(out, job, result))
                counts.done += 1
                counts.failed += result["status"] != "success"
        counts.running = 0
        counts.elapsed_s = time.perf_counter() - started
        on_progress(counts)
    return counts


def _ray_lost(out: Path, counts: Counts, left: int) -> BilbaError:
    """Ray itself is gone (this machine's raylet died: `ray stop`, the OOM killer), not the
    job: every pending job would fail the same way, so none is recorded and ``--resume`` runs
    them."""
    return BilbaError(
        f"Ray's local raylet died after {counts.skipped + counts.done} of {counts.total} jobs "
        f"were recorded in {out}; the other {left} were not run: rerun with --resume"
    )


def error_result(exc: Exception) -> dict[str, Any]:
    """The record of a job that raised: the job's own exception and where (Ray wraps it in a
    RayTaskError whose text opens with colour codes), its traceback kept for a bug report.

    ``ray.get`` raises the wrapper as an instance of the job's exception class too, an
    object without ``traceback_str`` (asking for it asks the job's exception): its text is
    the traceback."""
    import ray

    if isinstance(exc, ray.exceptions.RayTaskError) and exc.cause is not None:
        trace = re.sub(r"\x1b\[[0-9;]*m", "", str(exc)).strip().splitlines()
        return {**_error_line(exc.cause), "traceback": trace[-TRACEBACK_LINES:]}
    return _error_line(exc)


def _error_line(exc: BaseException) -> dict[str, Any]:
    first = first_line(exc)
    return {"status": "error", "reason": f"{type(exc).__name__}: {first}"}


def progress_bar(total: int) -> tuple[Callable[[Counts], None], Callable[[], None]]:
    """A tqdm bar showing done/running/failed; returns (update, close). The bar appears at
    the first update, so what `run_batch` refuses before its first progress is one line."""
    from tqdm import tqdm

    bars: list[tqdm] = []

    def update(counts: Counts) -> None:
        if not bars:
            bars.append(tqdm(total=total, unit=" jobs", file=sys.stderr, dynamic_ncols=True))
        bar = bars[0]
        bar.set_postfix_str(
            f"running {counts.running}, failed {counts.failed}, skipped {counts.skipped}",
            refresh=False,
        )
        bar.update(counts.skipped + counts.done - bar.n)

    def close() -> None:
        while bars:
            bars.pop().close()

    return update, close
