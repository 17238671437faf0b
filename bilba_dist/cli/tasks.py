"""`bilba tasks`: list the built-in tasks."""

import click

from bilba_dist.cli.errors import user_errors
from bilba_dist.task.loader import builtin_tasks, load_task


@click.command()
@user_errors
def tasks() -> None:
    """List the built-in tasks (each is a YAML file you can copy and edit)."""
    for name, path in sorted(builtin_tasks().items()):
        task = load_task(name)
        click.echo(f"{name:<14} {task.spec.description}")
        click.echo(f"{'':<14} {path}")
