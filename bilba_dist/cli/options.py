"""Options shared by the sub-commands that take a TASK."""

import math

import click

from bilba_dist.files import clip_name


class Bounded(click.ParamType):
    """A finite number within [low, high] (click's FloatRange lets NaN through)."""

    def __init__(self, low: float, high: float, kind: type = float, unit: str = "") -> None:
        self.low, self.high, self.kind, self.unit = low, high, kind, unit
        self.name = f"{kind.__name__} in [{low:g}, {high:g}]{unit}"

    def convert(self, value, param, ctx):
        shown = clip_name(value, 30)  # a 400-digit seed is quoted by its length
        try:
            number = self.kind(value)
        except (TypeError, ValueError):
            self.fail(f"{shown!r} is not a number", param, ctx)
        # an int is finite (math.isfinite overflows on one past a float's range)
        finite = isinstance(number, int) or math.isfinite(number)
        if not finite or not self.low <= number <= self.high:
            self.fail(
                f"{shown} is not within [{self.low:g}, {self.high:.10g}]{self.unit}", param, ctx
            )
        return number


SEED = Bounded(0, 2**32 - 1, int)
TIMEOUT_S = Bounded(0, 7 * 86400, float, " s")  # 0: give up at once (a no-plan result)

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
    type=Bounded(0, 1024, int),
    default=2,
    show_default=True,
    help="Ray rollout actors on a local Ray instance (or the cluster); 0 runs in-process.",
)


def split_uncertainty(values: tuple[str, ...]) -> list[str]:
    """Accept both ``-u a=1 -u b=2`` and ``-u "a=1 b=2"``."""
    return [item for value in values for item in value.split()]
