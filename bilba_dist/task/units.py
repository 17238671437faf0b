"""Quantities with units in task files: lengths in m/cm/mm, angles in deg/rad.

A bare number is taken in SI units (metres, radians). A string is a number followed by a unit,
e.g. ``"2deg"``, ``"1.5 cm"``. The wrong kind of unit (``"2cm"`` for an angle) is an error,
and so is a number that is not finite, a length outside the workspace (±2 m: the Panda
reaches 0.855 m from its base, and parts' frames sit near it) or an angle beyond a
turn either way (±360°: a pose written with 270° or with π rounded up is a pose; a bare 180
is 180 rad, a unit forgotten).
"""

import math
import re
from typing import Annotated

from pydantic import AfterValidator, BeforeValidator

LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
#: A relative spread: "50%" or 0.5.
FRACTION_UNITS = {"%": 0.01}
_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zA-Z%]*)\s*$")


def parse_quantity(value: object, units: dict[str, float], kind: str) -> float:
    """Return ``value`` in SI units; raise ValueError naming the allowed units."""
    article = "an" if kind[0] in "aeiou" else "a"
    if isinstance(value, bool):
        raise ValueError(f"expected {article} {kind}, got {value!r}")
    if isinstance(value, int | float):
        try:
            return float(value)
        except OverflowError:  # YAML reads 1000…0 (400 digits) as an int
            raise ValueError(
                f"expected {article} {kind}, got an integer of {len(str(value))} digits"
            ) from None
    if not isinstance(value, str):
        raise ValueError(f"expected {article} {kind} (number or string with unit), got {value!r}")
    match = _QUANTITY.match(value)
    if match is None:
        example = f"2{next(iter(units))}"
        raise ValueError(f"cannot read {value!r} as {article} {kind}; write e.g. '{example}'")
    number, unit = float(match.group(1)), match.group(2)
    if unit and unit not in units:
        allowed = ", ".join(sorted(units))
        raise ValueError(f"unit {unit!r} is not {article} {kind} unit; use one of {allowed}")
    return number * units[unit] if unit else number


def within(limit: float, unit: str, scale: float = 1.0, what: str = ""):
    """A check that a quantity is finite and within ±``limit`` (SI), quoted in ``unit``
    (``scale`` SI units each)."""

    def check(value: float) -> float:
        if not math.isfinite(value):
            raise ValueError(f"must be a finite number, got {value}")
        if abs(value) > limit * (1 + 1e-12):
            shown = value / scale  # inf for 1e308 m quoted in cm: say "far outside" instead
            size = f"{shown:g} {unit} is" if math.isfinite(shown) else "it is far"
            raise ValueError(f"{size} outside ±{limit / scale:g} {unit}{what}")
        return value

    return check


#: Lengths anywhere in a task [m] and angles [rad].
WORKSPACE_M = 2.0
MAX_ANGLE = 2 * math.pi


def parse_length(value: object) -> float:
    return parse_quantity(value, LENGTH_UNITS, "length")


def parse_angle(value: object) -> float:
    return parse_quantity(value, ANGLE_UNITS, "angle")


def parse_fraction(value: object) -> float:
    return parse_quantity(value, FRACTION_UNITS, "fraction")


Length = Annotated[
    float,
    BeforeValidator(parse_length),
    AfterValidator(within(WORKSPACE_M, "m", what=" (the workspace)")),
]
Angle = Annotated[
    float, BeforeValidator(parse_angle), AfterValidator(within(MAX_ANGLE, "deg", math.pi / 180))
]
#: A Panda joint angle: none of its joints turns past ±166°, so ±180° catches a unit forgotten
#: without a model of the arm (its limits are checked where the start is solved).
JointAngle = Annotated[
    float, BeforeValidator(parse_angle), AfterValidator(within(math.pi, "deg", math.pi / 180))
]
