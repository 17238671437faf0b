"""`bilba validate PLAN`: replay a plan on its planning belief and on held-out particles."""

from pathlib import Path

import click

from bilba_dist.cli.errors import user_errors
from bilba_dist.cli.options import SEED, Bounded, workers_option
from bilba_dist.errors import BilbaError
from bilba_dist.plans.file import read_plan
from bilba_dist.plans.replay import validate_plan
from bilba_dist.task.loader import build_task


@click.command("validate")
@click.argument("plan_path", metavar="PLAN", type=click.Path(path_type=Path))
@click.option("--task", "task_name", help="Task name or file [default: the task the plan holds].")
@click.option(
    "--held-out",
    type=Bounded(0, 10_000, int),
    default=0,
    show_default=True,
    help="Extra particles drawn inside the uncertainty bounds.",
)
@click.option("--friction-scale", type=Bounded(0.01, 10), default=1.0, show_default=True)
@click.option(
    "--seed", type=SEED, default=0, show_default=True, help="Seed for the held-out particles."
)
@workers_option
@user_errors
def validate(
    plan_path: Path,
    task_name: str | None,
    held_out: int,
    friction_scale: float,
    seed: int,
    workers: int,
) -> None:
    """Replay PLAN and print the fraction of particles that end in the goal contact."""
    if friction_scale <= 0:
        raise BilbaError(f"--friction-scale must be positive, got {friction_scale}")
    plan = read_plan(plan_path)
    task = plan.task(task_name)
    if friction_scale != 1.0:
        spec = task.spec.model_copy(update={"friction": task.spec.friction * friction_scale})
        task = build_task(spec, task.source)
    from bilba_dist.schedulers.session import (
        rollout_backend,  # imports pybullet: after input checks
    )

    with rollout_backend(task, workers) as backend:
        result = validate_plan(task, plan.motions, backend, held_out, seed)
    click.echo(f"plan       {plan_path} ({len(plan.motions)} motions, task {task.name})")
    click.echo(f"planning belief: {result.planning:.3f} of {result.n_planning} reach {task.goal}")
    if result.held_out is not None:
        click.echo(
            f"held out:        {result.held_out:.3f} of {held_out} (seed {seed}, "
            f"friction x{friction_scale:g})"
        )
