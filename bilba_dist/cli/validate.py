"""`bilba validate PLAN`: replay a plan on its planning belief and on held-out particles."""

from pathlib import Path

import click

from bilba_dist.cli.errors import user_errors
from bilba_dist.cli.options import SEED, Bounded, workers_option
from bilba_dist.cli.outputs import make_folder
from bilba_dist.errors import BilbaError
from bilba_dist.plans.file import read_plan
from bilba_dist.plans.replay import success_map, validate_plan
from bilba_dist.task.loader import parse_axis_items, with_friction, with_planner
from bilba_dist.task.schema import TIMESTEP_RANGE_S


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
    "--timestep",
    type=Bounded(*TIMESTEP_RANGE_S),
    help="Replay at this physics time step [s], e.g. 0.002 to check a plan in a finer "
    "simulation than it was planned in [default: the plan's].",
)
@click.option(
    "--seed", type=SEED, default=0, show_default=True, help="Seed for the held-out particles."
)
@click.option(
    "--map",
    "maps",
    multiple=True,
    metavar="AXIS=BOUND",
    help="Also map success over a grid of one or two axes from -BOUND to +BOUND (the others "
    "nominal), e.g. --map grasp.x=2cm --map friction=50%; writes PNG and CSV.",
)
@click.option(
    "--points",
    type=Bounded(2, 101, int),
    default=11,
    show_default=True,
    help="Grid points per --map axis.",
)
@click.option(
    "--map-out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Where the map goes: PREFIX.png and PREFIX.csv, its folder made if missing "
    "[default: PLAN without .json, -map].",
)
@workers_option
@user_errors
def validate(
    plan_path: Path,
    task_name: str | None,
    held_out: int,
    friction_scale: float,
    timestep: float | None,
    seed: int,
    maps: tuple[str, ...],
    points: int,
    map_out: Path | None,
    workers: int,
) -> None:
    """Replay PLAN and print the fraction of particles that end in the goal contact."""
    if friction_scale <= 0:
        raise BilbaError(f"--friction-scale must be positive, got {friction_scale}")
    bounds = map_bounds(maps)
    plan = read_plan(plan_path)
    task = plan.task(task_name)
    csv, png = map_paths(map_out or plan_path.with_name(plan_path.stem + "-map"))
    if bounds:  # a folder the map cannot go into: said before its rollouts, not after
        make_folder(csv)
    if friction_scale != 1.0:
        task = with_friction(task, friction_scale)
    if timestep is not None:
        task = with_planner(task, sim_timestep_s=timestep)
    step = f", step {task.timestep_s * 1000:g} ms"
    from bilba_dist.schedulers.session import (
        rollout_backend,  # imports pybullet: after input checks
    )

    with rollout_backend(task, workers) as backend:
        result = validate_plan(task, plan.motions, backend, held_out, seed)
        grid = success_map(task, plan.motions, backend, bounds, points) if bounds else None
    click.echo(f"plan       {plan_path} ({len(plan.motions)} motions, task {task.name}{step})")
    click.echo(f"planning belief: {result.planning:.3f} of {result.n_planning} reach {task.goal}")
    if result.held_out is not None:
        click.echo(
            f"held out:        {result.held_out:.3f} of {held_out} (seed {seed}, "
            f"friction x{friction_scale:g})"
        )
    if grid is not None:
        prefix = csv.with_suffix("")
        try:
            csv.write_text(grid.csv(), encoding="utf-8")
            grid.png(png, f"{plan_path.name}, friction x{friction_scale:g}{step}")
        except OSError as exc:
            raise BilbaError(f"{prefix}: cannot write the map: {exc.strerror or exc}") from None
        axes = " x ".join(f"{a} ±{maps[k].partition('=')[2]}" for k, a in enumerate(grid.axes))
        click.echo(
            f"map:             {grid.success.mean():.3f} of {grid.success.size} over {axes} "
            f"-> {png}, {csv}"
        )


def map_paths(prefix: Path) -> tuple[Path, Path]:
    """PREFIX.csv and PREFIX.png; a PREFIX that ends in .png or .csv loses that ending, any
    other dot stays (``run.v2`` → ``run.v2.png``, not ``run.png``)."""
    name = prefix.stem if prefix.suffix.lower() in (".png", ".csv") else prefix.name
    return prefix.with_name(name + ".csv"), prefix.with_name(name + ".png")


def map_bounds(maps: tuple[str, ...]) -> dict[str, float]:
    """``--map`` options as {axis: bound}: one or two distinct axes, bounds > 0."""
    if len(maps) > 2:
        raise BilbaError("--map: give one or two axes")
    bounds = parse_axis_items(maps, "--map", "grasp.x=2cm")
    bad = [k for k, v in bounds.items() if v <= 0]
    if bad:
        raise BilbaError(f"--map: bounds must be > 0: {', '.join(bad)}")
    return bounds
