"""`bilba graph TASK`: the contact modes, their graph and the contact schedule."""

from pathlib import Path

import click

from bilba_dist.belief.particles import initial_belief
from bilba_dist.belief.start import check_gripper_reaches_goal, check_gripper_start, start_joints
from bilba_dist.cli.errors import user_errors
from bilba_dist.cli.options import split_uncertainty, task_argument, uncertainty_option
from bilba_dist.cli.outputs import refuse_overwriting, task_file, write_output
from bilba_dist.errors import TaskError
from bilba_dist.geometry.contact import FREE
from bilba_dist.modes.schedule import SliceCache, belief_graph
from bilba_dist.robot.gripper import too_wide
from bilba_dist.task.loader import load_task


@click.command()
@task_argument
@uncertainty_option
@click.option("--dot", type=click.Path(dir_okay=False, path_type=Path), help="Write Graphviz DOT.")
@user_errors
def graph(task: str, uncertainty: tuple[str, ...], dot: Path | None) -> None:
    """Print the modes, edges and contact schedule of TASK (a built-in name or a YAML path)."""
    refuse_overwriting({"--dot": dot}, task_file(task))
    loaded = load_task(task, split_uncertainty(uncertainty))
    particles = initial_belief(loaded)
    mode_graph, schedule = belief_graph(loaded, particles, loaded.X_WG0, SliceCache(loaded))
    cslice = mode_graph.cslice
    click.echo(
        f"task {loaded.name}: {len(particles)} particles, slice of {len(cslice.polytopes)} "
        f"polytopes, {len(cslice.vertices)} boundary vertices"
    )
    click.echo(f"modes ({len(mode_graph.modes)}):")
    for mode in mode_graph.modes:
        n = mode_graph.normal(mode).round(3).tolist()
        click.echo(f"  {mode}  normal {n}  edges {mode_graph.graph.out_degree(mode)}")
    click.echo(f"edges: {mode_graph.graph.number_of_edges()} (directed)")
    for u, v, cost in sorted(mode_graph.graph.edges(data="cost")):
        if u == FREE:
            click.echo(f"  {u} -> {v}  cost {cost:.6f}")
    click.echo("schedule: " + " -> ".join(str(m) for m in schedule))
    try:  # the geometry is fine, but the robot must also start where the task says
        start_joints(loaded)
    except TaskError as exc:
        click.echo(f"bilba: warning: {exc} (bilba plan refuses this start)", err=True)
    try:  # ... and the gripper fit where the part goes
        check_gripper_start(loaded, particles)
        check_gripper_reaches_goal(loaded)
    except TaskError as exc:
        click.echo(f"bilba: warning: {exc} (bilba plan refuses this task)", err=True)
    if wide := too_wide(loaded.manipuland, loaded.X_GM):
        click.echo(f"bilba: warning: {wide}", err=True)
    if dot is not None:
        write_output(dot, mode_graph.to_dot())
        click.echo(f"wrote {dot}")
