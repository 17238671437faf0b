"""The sentence a user gets when no plan is found, from the failed attempts' records."""

from bilba_dist.geometry.contact import ContactPair
from bilba_dist.planning.diagnosis import Blocked, explain

CHAMFER = ContactPair("wall/chamfer", "peg/-z")
GOAL = ContactPair("floor/top", "peg/bottom")


def test_no_failures_no_sentence():
    assert explain([]) == ""


def test_a_contact_without_region_says_the_parts_cannot_touch_that_way():
    text = explain([Blocked(GOAL, 0, 3, 3, 0.01, 0.0)])
    assert text.startswith(f"blocked by {GOAL} (1 of 1 failed attempts): it has no region")


def test_the_most_frequent_contact_with_its_best_count_and_a_spread_wider_than_its_region():
    failures = [
        Blocked(CHAMFER, 1, 3, 0, 0.004, 0.010),
        Blocked(GOAL, 1, 3, 0, 0.020, 0.0055),
        Blocked(GOAL, 2, 3, 1, 0.020, 0.0055),
    ]
    text = explain(failures)
    assert text.startswith(f"blocked by {GOAL} (2 of 3 failed attempts): ")
    assert "no motion brought more than 2 of 3 particles into it" in text
    assert "no region at the rotations of 1 of 3 particles" in text
    assert "spread 20.0 mm across, wider than its region (5.5 mm)" in text


def test_a_region_wider_than_the_spread_is_not_blamed():
    text = explain([Blocked(CHAMFER, 2, 3, 0, 0.004, 0.010)])
    assert "spread" not in text and text.endswith("2 of 3 particles into it")


def test_all_particles_in_but_check_particles_out_names_robust_acceptance():
    failures = [
        Blocked(CHAMFER, 7, 7, 0, 0.004, 0.010, checked=9, n_check=14),
        Blocked(CHAMFER, 7, 7, 0, 0.004, 0.010, checked=11, n_check=14),
        Blocked(CHAMFER, 6, 7, 0, 0.004, 0.010, checked=13, n_check=14),
    ]
    text = explain(failures)
    assert "all 7 particles into it, but no more than 11 of its 14 check particles" in text
    assert "planner.check_friction" in text and "more than 7 of 7" not in text


def test_check_particles_are_not_blamed_while_particles_are_missing():
    text = explain([Blocked(CHAMFER, 6, 7, 0, 0.004, 0.010, checked=14, n_check=14)])
    assert text.endswith("no motion brought more than 6 of 7 particles into it")


def test_a_goal_met_at_its_edge_is_warned_of(peg):
    """The peg's default plan ends on the floor's top alone: no warning. The same final
    belief with particle 1 touching the floor's side face too (the peg hanging on the edge
    of a floor wider than its hole, as one of our tasks did): a warning naming both."""
    import dataclasses

    from bilba_dist.planning.bilba import plan
    from bilba_dist.planning.diagnosis import goal_edge_warning
    from bilba_dist.workers.rollout_worker import RolloutWorker

    result = plan(peg, RolloutWorker(peg), "bilba-variable", seed=0, timeout_s=120)
    final = result.final_belief
    assert result.success and final is not None
    assert goal_edge_warning(peg.goal, final) is None
    edge = ContactPair("floor/+y", peg.goal.manip)
    contacts = tuple(c | {edge} if i == 1 else c for i, c in enumerate(final.contacts))
    warning = goal_edge_warning(peg.goal, dataclasses.replace(final, contacts=contacts))
    assert warning is not None and warning.startswith("particles 1 end in the goal")
    assert f"touching also {edge}" in warning and "floor/+z exposed" in warning
    other = ContactPair("wall_px/inner", peg.goal.manip)  # another piece: not the goal's edge
    contacts = tuple(c | {other} for c in final.contacts)
    assert goal_edge_warning(peg.goal, dataclasses.replace(final, contacts=contacts)) is None


def test_a_part_that_ends_on_the_edge_of_its_goal_face_is_a_warning():
    """Our open-ended card slot let a plan slide the card out until its fingers cleared the
    walls, 7 % of its bottom on the floor. Here the chamfered-tip peg (32 mm square bottom on
    a 41 mm floor): home, all of it; moved 30 mm aside (kept level), 9/32 of it."""
    import dataclasses

    import numpy as np
    import pinocchio as pin
    import pytest

    from bilba_dist.belief.particles import make_particle
    from bilba_dist.belief.start import start_belief
    from bilba_dist.planning.diagnosis import goal_overlap, goal_overlap_warning
    from bilba_dist.task.loader import load_task

    task = load_task("tests/data/chamfer-tip.yaml", [])
    home = task.X_WO * pin.SE3(np.eye(3), np.array([0, 0, 0.02]))  # tip on the floor's top
    belief = start_belief(task, [make_particle(task, {})] * 2)
    aside = pin.SE3(home.rotation, home.translation + np.array([0.03, 0, 0]))
    final = dataclasses.replace(
        belief,
        states=(dataclasses.replace(belief.states[0], X_WM=home),
                dataclasses.replace(belief.states[1], X_WM=aside)),
        contacts=(frozenset({task.goal}),) * 2,
    )  # fmt: skip
    assert goal_overlap(task, final, 0) == pytest.approx(1.0)
    assert goal_overlap(task, final, 1) == pytest.approx((16 + 20.5 - 30) / 32, abs=1e-6)
    warning = goal_overlap_warning(task, final)
    assert warning is not None and warning.startswith("particles 1 end with only 20%–20%")
    assert (
        goal_overlap_warning(
            task, dataclasses.replace(final, contacts=(frozenset({task.goal}), frozenset()))
        )
        is None
    )
