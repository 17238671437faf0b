"""Plan a task, check the plan on particles it was not planned on, and keep a log.

    python examples/plan_validate_log.py [TASK] [OUT_FOLDER]

TASK is a built-in name or a task file (default: peg-in-hole, ±2° grasp pitch); the plan
(JSON) and the MCAP log (open it in Foxglove) go to OUT_FOLDER (default: out/).
"""

import sys
from pathlib import Path

from bilba_dist import (
    LogWriter,
    RolloutWorker,
    dumps,
    load_task,
    plan,
    plan_document,
    validate_plan,
    write_plan,
)  # fmt: skip

task_name = sys.argv[1] if len(sys.argv) > 1 else "peg-in-hole"
out = Path(sys.argv[2] if len(sys.argv) > 2 else "out")
task = load_task(task_name, ["grasp.pitch=2deg"] if task_name == "peg-in-hole" else None)
worker = RolloutWorker(task)  # in-process rollouts; rollout_backend(task, 2) for 2 Ray actors
log = LogWriter(out / f"{task.name}.mcap", task, "bilba-variable", seed=0)
result = plan(task, worker, "bilba-variable", seed=0, timeout_s=300, recorder=log)
document = plan_document(result, task)
write_plan(document, out / f"{task.name}.json")
log.finish(dumps(document), result.outcome())
if not result.success:
    sys.exit(f"no plan: {result.reason}")
# the task planned on: this one, or it on more particles when its first plan failed verification
planned = result.task or task
check = validate_plan(planned, result.motions, worker, held_out=14, seed=1)
print(f"{len(result.motions)} motions in {result.planning_time_s:.1f} s; reach {task.goal}:")
print(f"{check.planning:.2f} of the planning belief, {check.held_out:.2f} of 14 held out")
