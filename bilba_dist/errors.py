"""The exceptions of bilba_dist: one root, a few kinds a user can act on.

The CLI turns any `BilbaError` into one line on stderr and exit code 2.
"""

from collections.abc import Iterable


class BilbaError(Exception):
    """Root of every error bilba_dist raises on purpose."""


class TaskError(BilbaError):
    """A task file (or a built-in task name) is malformed or inconsistent."""


class GeometryError(BilbaError):
    """A part's geometry is unusable: degenerate, non-convex, or an unknown face."""


class NoScheduleError(BilbaError):
    """The mode graph holds no path from the free mode to the goal contact."""


class UnreachableError(BilbaError):
    """A gripper setpoint has no inverse-kinematics solution within the joint limits."""

    def __init__(self, message: str, residual: float = float("nan")) -> None:
        super().__init__(message)
        self.residual = residual  # the norm of the 6-D pose error IK stopped at [m, rad]


def first_line(exc: BaseException, default: str = "") -> str:
    """The first non-blank line of ``exc``'s text (``default`` when it has none): what a
    one-line error quotes of an exception from a library."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else default


def listed(items: Iterable[object], limit: int = 12) -> str:
    """``items`` for a one-line message: all of them, or the first ``limit`` and how many
    there are (a part split into hundreds of pieces, a log missing thousands of records)."""
    shown = [str(item) for item in items]
    if len(shown) <= limit:
        return ", ".join(shown)
    return f"{', '.join(shown[:limit])} … ({len(shown)} in all)"
