"""`bilba export PLAN --target DRIVER` and `bilba execute PLAN`: a plan toward a real Panda."""

import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import click

from bilba_dist.cli.errors import user_errors
from bilba_dist.cli.options import Bounded
from bilba_dist.cli.outputs import refuse_overwriting, write_output
from bilba_dist.errors import BilbaError
from bilba_dist.plans.file import read_plan
from bilba_dist.robot.drivers import DRIVER_NAMES, DRIVERS
from bilba_dist.task.loader import Task, with_planner

if TYPE_CHECKING:
    from bilba_dist.workers.rollout_worker import RolloutWorker

EXIT_MISSED = 1


class Offset(click.ParamType):
    """``--ee-offset Z`` (along panda_hand's z) or ``X,Y,Z`` [m], each within ±0.5 m."""

    name = "Z or X,Y,Z [m]"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        parts = str(value).replace(",", " ").split()
        numbers = [Bounded(-0.5, 0.5, unit=" m").convert(v, param, ctx) for v in parts]
        if len(numbers) not in (1, 3):
            self.fail(f"{value!r}: give one number (along z) or three (x,y,z)", param, ctx)
        return tuple(numbers)


ee_offset_option = click.option(
    "--ee-offset",
    type=Offset(),
    help="The driver's EE (Desk TCP) origin in the panda_hand frame [m]: Z, or X,Y,Z "
    "[default: the plan's, 0.1034 along z for the Franka Hand].",
)


@click.command("export")
@click.argument("plan_path", metavar="PLAN", type=click.Path(path_type=Path))
@click.option("--target", type=click.Choice(DRIVER_NAMES), required=True, help="Franka driver.")
@ee_offset_option
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="File to write [default: PLAN's name with -TARGET.py, or -franka-ros.yaml].",
)
@user_errors
def export(
    plan_path: Path, target: str, ee_offset: tuple[float, ...] | None, out: Path | None
) -> None:
    """Write PLAN as a script for a Franka driver (a parameter file for franka-ros): homing
    to the start joints, the payload, and every motion in the driver's frame, axis order and
    form of stiffness. Every approximation is printed as a warning with its size."""
    from bilba_dist.plans.execute import ee_offset_of
    from bilba_dist.plans.export import driver_motions, export_text, with_thresholds

    suffix = "-franka-ros.yaml" if target == "franka-ros" else f"-{target}.py"
    out = out or plan_path.with_name(plan_path.stem + suffix)
    refuse_overwriting({"--out": out}, {"the plan": plan_path})
    plan = read_plan(plan_path)
    if not plan.motions:
        raise BilbaError(f"{plan_path}: the plan has no motions to export")
    exported = driver_motions(plan, DRIVERS[target], ee_offset_of(plan, ee_offset))
    exported = with_thresholds(plan, exported)
    text = export_text(plan, exported, plan_path.name)
    write_output(out, text)
    for warning in exported.warnings:
        click.echo(f"warning: {warning}", err=True)
    driver = DRIVERS[target]
    click.echo(f"{out}: {len(exported.motions)} motions for {target} ({driver.robot})")


@click.command("execute")
@click.argument("plan_path", metavar="PLAN", type=click.Path(path_type=Path))
@click.option(
    "--particle",
    "particles",
    multiple=True,
    metavar="AXIS=VALUE[,...]",
    help="One more particle, offset from nominal, e.g. --particle grasp.x=3mm,env.y=-1mm "
    "(repeatable); the plan's own particles always run.",
)
@click.option(
    "--driver",
    type=click.Choice(DRIVER_NAMES),
    help="Run each motion as this driver would (its stiffness form and limits, a Cartesian "
    "ramp, its wrench clip or none) [default: as planned].",
)
@ee_offset_option
@click.option("--gui", is_flag=True, help="Show the PyBullet viewer (needs a display).")
@user_errors
def execute(
    plan_path: Path,
    particles: tuple[str, ...],
    driver: str | None,
    ee_offset: tuple[float, ...] | None,
    gui: bool,
) -> None:
    """Run PLAN in simulation on the Panda, motion by motion, printing the contact each
    particle reached against the one intended. Exit 0 when every particle ends in the goal,
    1 when one does not."""
    from bilba_dist.plans.execute import (
        describe,
        ee_offset_of,
        final_misses,
        parse_particle,
        particles_for,
        steps_of,
    )
    from bilba_dist.plans.export import driven_motions, driver_motions

    if gui and sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
        raise BilbaError("--gui needs a display (DISPLAY is not set)")
    plan = read_plan(plan_path)
    task = plan.task()
    extra = [parse_particle(text) for text in particles]
    exported = None
    if driver is not None:
        exported = driver_motions(plan, DRIVERS[driver], ee_offset_of(plan, ee_offset))
        task = with_planner(task, driver=driver)  # the worker simulates as it runs
        _check_start_within(task, plan_path, driver)
    motions = driven_motions(plan, exported)
    belief_particles = particles_for(task, extra)
    click.echo(
        f"plan       {plan_path} ({len(motions)} motions, task {task.name}, "
        f"{len(belief_particles)} particles, "
        + (f"as {driver} runs it)" if driver else "as planned)")
    )
    for warning in exported.warnings if exported else []:
        click.echo(f"driver     {warning}")
    backend = _backend(task, gui)
    final = None
    try:
        for k, (step, belief) in enumerate(steps_of(task, motions, belief_particles, backend), 1):
            final = belief
            n = sum(step.reached)
            click.echo(
                f"motion {k:<3} meant {step.intended}: {n} of {len(step.reached)} reached; "
                f"peak load {max(step.load.wrench[:3]):.1f} N, {max(step.load.wrench[3:]):.1f} "
                f"N·m, joints {max(step.load.joint_torque):.1f} N·m"
            )
            for piece, touching in sorted(step.arm_touches.items()):
                click.echo(
                    f"           the arm or hand touches {piece} (particles "
                    f"{', '.join(map(str, touching))}): a real gripper is not meant to press there"
                )
            for i, ok in enumerate(step.reached):
                if not ok:
                    click.echo(
                        f"           particle {i} ({describe(belief.particles[i])}) "
                        f"{step.contacts[i]}"
                    )
    finally:
        backend.close()
    if final is None:
        raise BilbaError(f"{plan_path}: the plan has no motions to execute")
    misses = final_misses(task, final)
    n = len(final)
    click.echo(f"goal       {task.goal}: {n - len(misses)} of {n} particles")
    if misses:
        which = ", ".join(f"{i} ({describe(final.particles[i])})" for i in misses)
        click.echo(f"missed by  particle {which}")
        sys.exit(EXIT_MISSED)


def _check_start_within(task: Task, plan_path: Path, driver: str) -> None:
    """A plan whose start the driven arm cannot reach within its joint limits (a Panda plan
    run as an FR3 driver runs it) is one line saying so, not the task file's advice."""
    from bilba_dist.belief.start import start_joints
    from bilba_dist.errors import TaskError

    try:
        start_joints(task)
    except TaskError:
        arm = " and ".join(DRIVERS[driver].arms)
        raise BilbaError(
            f"{plan_path}: its start is past the joint limits of the {arm} that {driver} "
            f"drives, so it cannot run there; plan again with --driver {driver}"
        ) from None


def _backend(task: Task, gui: bool) -> "RolloutWorker":
    """An in-process worker; it simulates as ``task.spec.planner.driver`` runs a motion."""
    from bilba_dist.workers.rollout_worker import RolloutWorker
    from bilba_dist.workers.settings import SimSettings

    return RolloutWorker(task, "panda", SimSettings(gui=gui))
