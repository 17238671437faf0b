import math

import pytest

from bilba_dist.task.units import parse_angle, parse_length


@pytest.mark.parametrize(
    ("text", "metres"),
    [(0.5, 0.5), ("1cm", 0.01), ("2.5 mm", 0.0025), ("-3m", -3.0), ("1e-3", 0.001), (2, 2.0)],
)
def test_lengths_convert_to_metres(text, metres):
    assert parse_length(text) == pytest.approx(metres)


@pytest.mark.parametrize(("text", "rad"), [("180deg", math.pi), ("0.1rad", 0.1), (-1, -1.0)])
def test_angles_convert_to_radians(text, rad):
    assert parse_angle(text) == pytest.approx(rad)


@pytest.mark.parametrize(
    ("parse", "text", "complaint"),
    [
        (parse_angle, "2cm", "not an angle unit"),
        (parse_length, "2deg", "not a length unit"),
        (parse_length, "two cm", "cannot read"),
        (parse_length, True, "expected a length"),
        (parse_length, [1], "expected a length"),
    ],
)
def test_bad_quantities_name_the_problem(parse, text, complaint):
    with pytest.raises(ValueError, match=complaint):
        parse(text)


@pytest.mark.parametrize(
    ("rpy", "error"),
    [
        ([3.1416, 0, 0], None),  # π rounded up, as a printed pose often is
        (["270deg", 0, "-200deg"], None),  # the same turns written the other way round
        ([180, 0, 0], "outside ±360 deg"),  # 180 rad: the unit forgotten
        (["361deg", 0, 0], "outside ±360 deg"),
    ],
)
def test_a_pose_angle_may_be_any_turn_but_not_a_forgotten_unit(rpy, error):
    from pydantic import ValidationError

    from bilba_dist.task.schema import PoseSpec

    if error is None:
        pose = PoseSpec.model_validate({"xyz": [0, 0, 0], "rpy": rpy})
        assert pose.rpy[0] == pytest.approx(parse_angle(rpy[0]))
    else:
        with pytest.raises(ValidationError, match=error):
            PoseSpec.model_validate({"xyz": [0, 0, 0], "rpy": rpy})


def test_a_start_joint_past_a_half_turn_is_a_unit_forgotten():
    """Pose angles take a whole turn; a Panda joint angle stays within ±180° (no joint of
    the arm turns past ±166°)."""
    from pydantic import ValidationError

    from bilba_dist.task.schema import RobotStartSpec

    posture = [0.0, 0.0, 0.0, -1.5, 0.0, 1.5, 0.8]
    assert RobotStartSpec.model_validate({"joints": posture}).joints == tuple(posture)
    with pytest.raises(ValidationError, match=r"229\.183 deg is outside ±180 deg"):
        RobotStartSpec.model_validate({"joints": [4.0, *posture[1:]]})
