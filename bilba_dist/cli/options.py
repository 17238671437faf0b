"""Options shared by the sub-commands that take a TASK."""

import click

task_argument = click.argument("task", metavar="TASK")
uncertainty_option = click.option(
    "--uncertainty",
    "-u",
    multiple=True,
    metavar="AXIS=VALUE",
    help="Replace the task's uncertainty bounds, e.g. -u grasp.pitch=2deg -u env.y=1cm "
    "(axes grasp.|env. x y z roll pitch yaw; units m cm mm deg rad).",
)

workers_option = click.option(
    "--workers",
    type=int,
    default=2,
    show_default=True,
    help="Ray rollout actors on a local Ray instance (or the cluster); 0 runs in-process.",
)


def split_uncertainty(values: tuple[str, ...]) -> list[str]:
    """Accept both ``-u a=1 -u b=2`` and ``-u "a=1 b=2"``."""
    return [item for value in values for item in value.split()]
