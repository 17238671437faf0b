"""Verification (planning/verify.py): a plan is replayed on particles it was not planned on
before it is returned, and one that loses some is not returned while time is left."""

import json

import numpy as np
import pytest

from bilba_dist import load_task, plan
from bilba_dist.belief.particles import make_particle
from bilba_dist.planning import bilba, verify
from bilba_dist.planning.verify import VERIFY_SEED, verify_particles, within_budget
from bilba_dist.record.reader import read_log
from bilba_dist.task.loader import with_planner, with_preset
from bilba_dist.workers.rollout_worker import RolloutWorker
from tests.conftest import write_task
from tests.test_task_files import run_cli


def test_verification_particles_are_a_fixed_draw_inside_the_bounds_at_three_frictions():
    task = load_task("puzzle", ["grasp.x=1cm"])
    assert task.spec.planner.verify_particles == 14  # the default
    particles = verify_particles(task, 0.5)
    assert len(particles) == 14 * 3
    assert [p.friction_scale for p in particles[:6]] == [0.5, 1.0, 1.5] * 2
    xs = np.array([p.offsets["grasp.x"] for p in particles])
    assert np.all(np.abs(xs) <= 0.01) and len(set(xs.round(9))) == 14
    assert verify_particles(task, 0.5) == particles  # seed VERIFY_SEED, not the planning seed
    assert VERIFY_SEED not in (0, 1)  # `bilba validate`'s usual held-out draws
    without_margin = verify_particles(task, 0.0)
    assert [p.friction_scale for p in without_margin] == [1.0] * 14
    assert verify_particles(with_preset(task, "paper"), 0.0) == ()  # the authors: none


@pytest.mark.parametrize(
    ("budget", "offsets"), [(0, 1), (29, 1), (30, 2), (10_000, 14)]
)  # 3 particles an offset, 5 motions: 15 rollouts an offset
def test_verification_spends_at_most_its_share_of_the_search(budget, offsets):
    particles = verify_particles(load_task("puzzle", ["grasp.x=1cm"]), 0.5)
    assert within_budget(particles, 3, 5, budget) == particles[: 3 * offsets]


def test_a_verified_plan_says_so_in_its_file_and_log(tmp_path):
    out, log = tmp_path / "p.json", tmp_path / "l.mcap"
    result = run_cli("plan", "peg-in-hole", "--workers", "0", "--out", str(out), "--log", str(log))
    assert result.exit_code == 0, result.output
    assert "verified   passed on" in result.output
    document = json.loads(out.read_text())
    check = document["verification"]
    assert check["passed"] and check["plan"] == 1 and check["particles"] % 3 == 0
    assert check["held"] == {"0.5": 1.0, "1": 1.0, "1.5": 1.0}
    (logged,) = read_log(log).json("/verify")
    assert logged == check
    (outcome,) = read_log(log).json("/outcome")
    assert outcome["verified"] is True
    # its replay is counted: more rollouts than the same search without it
    task = with_planner(load_task("peg-in-hole"), verify_particles=0)
    plain = plan(task, RolloutWorker(task), "bilba-variable", seed=0)
    motions = len(document["motions"])
    assert document["rollouts"] == plain.rollouts + check["particles"] * motions


def test_a_plan_that_fails_verification_is_not_returned_while_time_is_left(monkeypatch):
    """A verification particle the first plan does not bring home (the hole 3 cm away) fails
    it: that particle becomes a check particle and the search starts over; with no
    plan that passes within 3x the first one's time, the one that held best comes back,
    marked failed."""
    task = with_planner(load_task("peg-in-hole"), verify_effort=3.0)
    worker = RolloutWorker(task)
    first = plan(task, worker, "bilba-fixed", seed=0)  # verified: the nominal particles pass
    assert first.verification is not None and first.verification.passed
    lost = make_particle(task, {"env.y": 0.03})
    home = make_particle(task, {})
    monkeypatch.setattr(bilba, "verify_particles", lambda task, f: (home, lost))
    added = []
    more_checks = verify.with_more_checks

    def spy(task, b0, extra):
        added.extend(extra)
        return more_checks(task, b0, extra)

    monkeypatch.setattr(bilba, "with_more_checks", spy)
    result = plan(task, worker, "bilba-fixed", seed=0, timeout_s=12)
    assert added[:1] == [lost]
    assert result.success and result.verification is not None
    assert not result.verification.passed and result.verification.held == {"1": 0.5}
    assert result.reason.startswith("no plan passed verification within 3x the time of the first")
    assert [m.G_d for m in result.motions] == [m.G_d for m in first.motions]


@pytest.mark.parametrize(
    ("planner", "words"),
    [
        ({"verify_min": 2}, "verify_min"),
        ({"verify_particles": -1}, "verify_particles"),
        ({"verify_share": 0}, "verify_share"),
        ({"verify_effort": 0.5}, "verify_effort"),
    ],
)
def test_a_verification_setting_out_of_range_is_one_line(tmp_path, peg_yaml, planner, words):
    path = write_task(tmp_path, {**peg_yaml, "planner": planner})
    result = run_cli("plan", str(path), "--workers", "0", "--no-log")
    assert result.exit_code == 2 and words in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_with_a_friction_axis_the_verification_particles_draw_their_own_friction():
    """Robust acceptance is off then (the particles span the friction the user gave), and the
    verification particles are drawn on every axis, friction included: one fraction."""
    task = load_task("peg-in-hole", ["grasp.pitch=2deg", "friction=30%"])
    particles = verify_particles(task, 0.0)
    frictions = [p.friction_scale for p in particles]
    assert len(particles) == 14 and len(set(frictions)) == 14
    assert all(0.7 <= f <= 1.3 for f in frictions)
    result = plan(task, RolloutWorker(task), "bilba-fixed", seed=0)
    assert result.success and result.verification is not None
    assert list(result.verification.held) == ["all"]


def test_a_search_whose_plans_keep_failing_stops_at_its_effort_limit(monkeypatch):
    """With a verification particle no plan can bring home (its hole half a metre away), the
    search gives up at verify_effort times its first plan's time, long before the timeout,
    and returns that plan, marked failed."""
    task = with_planner(load_task("peg-in-hole"), verify_effort=2.0)
    monkeypatch.setattr(
        bilba, "verify_particles", lambda task, f: (make_particle(task, {"env.y": 0.5}),)
    )
    result = plan(task, RolloutWorker(task), "bilba-fixed", seed=0, timeout_s=600)
    assert result.success and result.verification is not None
    assert not result.verification.passed and result.verification.held == {"1": 0.0}
    assert "within 2x the time of the first" in result.reason
    assert result.first_plan_s > 0 and result.planning_time_s < 2 * result.first_plan_s + 30


def test_a_search_out_of_time_before_its_effort_limit_says_the_timeout_ended_it(monkeypatch):
    """The same search with an effort limit it cannot reach: the timeout ends it, and the
    reason says so (not the effort limit)."""
    task = with_planner(load_task("peg-in-hole"), verify_effort=1000.0)
    monkeypatch.setattr(
        bilba, "verify_particles", lambda task, f: (make_particle(task, {"env.y": 0.5}),)
    )
    result = plan(task, RolloutWorker(task), "bilba-fixed", seed=0, timeout_s=8)
    assert result.success and result.verification is not None
    assert not result.verification.passed
    assert result.reason.startswith("no plan passed verification before the timeout after")
