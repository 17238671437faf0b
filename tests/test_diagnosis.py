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
