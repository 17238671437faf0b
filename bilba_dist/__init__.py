"""bilba_dist: bi-level belief assembly planning, distributed on Ray.

The Python API (docs/api.md; examples/plan_validate_log.py plans, validates and logs)::

    from bilba_dist import RolloutWorker, load_task, plan, plan_document, write_plan

    task = load_task("peg-in-hole", ["grasp.pitch=2deg"])  # a name or a task file
    result = plan(task, RolloutWorker(task), "bilba-variable", seed=0)
    write_plan(plan_document(result, task), Path("plan.json"))

Names are imported on first use, so `import bilba_dist` (and `bilba --help`) stays quick.
"""

from importlib import import_module
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

#: Public name -> module that defines it.
_EXPORTS = {
    # tasks
    "load_task": "bilba_dist.task.loader",
    "Task": "bilba_dist.task.loader",
    "TaskSpec": "bilba_dist.task.schema",
    "check_task": "bilba_dist.belief.start",
    # planning
    "plan": "bilba_dist.planning.bilba",
    "PLANNERS": "bilba_dist.planning.bilba",
    "Progress": "bilba_dist.planning.bilba",
    "PlanResult": "bilba_dist.planning.result",
    "PlannedMotion": "bilba_dist.planning.result",
    # rollouts: in-process, on Ray actors, or chosen like the CLI's --workers/--address
    "RolloutWorker": "bilba_dist.workers.rollout_worker",
    "RayPool": "bilba_dist.workers.pool",
    "ray_session": "bilba_dist.schedulers.session",
    "rollout_backend": "bilba_dist.schedulers.session",
    # one hard problem as N seeded searches side by side (`bilba plan --portfolio N`)
    "run_portfolio": "bilba_dist.schedulers.portfolio",
    "PortfolioResult": "bilba_dist.schedulers.portfolio",
    # plan files, replay, validation
    "plan_document": "bilba_dist.plans.file",
    "write_plan": "bilba_dist.plans.file",
    "read_plan": "bilba_dist.plans.file",
    "dumps": "bilba_dist.plans.file",
    "replay": "bilba_dist.plans.replay",
    "validate_plan": "bilba_dist.plans.replay",
    "Validation": "bilba_dist.plans.replay",
    # logs
    "LogWriter": "bilba_dist.record.writer",
    "read_log": "bilba_dist.record.reader",
    # errors
    "BilbaError": "bilba_dist.errors",
}

#: Kept literal for linters; tests/test_api.py checks it against _EXPORTS.
__all__ = [
    "PLANNERS",
    "BilbaError",
    "LogWriter",
    "PlanResult",
    "PlannedMotion",
    "PortfolioResult",
    "Progress",
    "RayPool",
    "RolloutWorker",
    "Task",
    "TaskSpec",
    "Validation",
    "__version__",
    "check_task",
    "dumps",
    "load_task",
    "plan",
    "plan_document",
    "ray_session",
    "read_log",
    "read_plan",
    "replay",
    "rollout_backend",
    "run_portfolio",
    "validate_plan",
    "write_plan",
]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'bilba_dist' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)


if TYPE_CHECKING:
    from bilba_dist.errors import BilbaError
    from bilba_dist.planning.bilba import PLANNERS, Progress, plan
    from bilba_dist.planning.result import PlannedMotion, PlanResult
    from bilba_dist.plans.file import dumps, plan_document, read_plan, write_plan
    from bilba_dist.plans.replay import Validation, replay, validate_plan
    from bilba_dist.record.reader import read_log
    from bilba_dist.record.writer import LogWriter
    from bilba_dist.schedulers.portfolio import PortfolioResult, run_portfolio
    from bilba_dist.schedulers.session import ray_session, rollout_backend
    from bilba_dist.task.loader import Task, load_task
    from bilba_dist.task.schema import TaskSpec
    from bilba_dist.workers.pool import RayPool
    from bilba_dist.workers.rollout_worker import RolloutWorker
