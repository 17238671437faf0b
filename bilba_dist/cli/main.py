"""The `bilba` command: one module per sub-command, errors as one line and exit code 2."""

import click

from bilba_dist import __version__


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="bilba")
def cli() -> None:
    """Plan robot assembly under uncertainty with BILBA."""


def main() -> None:
    register()
    cli(prog_name="bilba")


def register() -> None:
    """Attach the sub-commands (imported here so `bilba --help` stays quick)."""
    from bilba_dist.cli import batch, graph, logs, plan, robot, tasks, validate

    for command in (
        tasks.tasks,
        graph.graph,
        plan.plan_command,
        validate.validate,
        robot.execute,
        robot.export,
        logs.logs,
        batch.batch,
        batch.report,
    ):
        cli.add_command(command)
