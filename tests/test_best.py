"""B-EST, the baseline: real rollouts, in-process; plans that replay, seeds that repeat."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from bilba_dist.belief.particles import initial_belief
from bilba_dist.belief.start import start_belief
from bilba_dist.planning.best import POSITION_BINS, QUATERNION_BINS, _cell, mean_pose, workspace
from bilba_dist.planning.bilba import plan
from bilba_dist.plans.file import plan_document, read_plan, write_plan
from bilba_dist.plans.replay import replay
from bilba_dist.task.loader import load_task
from bilba_dist.workers.rollout_worker import RolloutWorker

FLAT = str(Path(__file__).parent / "data" / "flat.yaml")


@pytest.fixture(scope="module")
def flat():
    task = load_task(FLAT, ["grasp.x=1cm"])
    return task, RolloutWorker(task, "panda")


def test_b_est_plan_brings_every_particle_to_the_goal_and_replays(flat, tmp_path):
    task, worker = flat
    result = plan(task, worker, "b-est", seed=3, timeout_s=120)
    assert result.success and result.motions and result.rollouts % 3 == 0
    assert all(task.goal in c for c in result.final_belief.contacts)
    path = tmp_path / "plan.json"
    write_plan(plan_document(result, task), path)
    loaded = read_plan(path)
    assert loaded.document["planner"] == "b-est"
    final = replay(task, loaded.motions, initial_belief(task), worker)
    assert final.contacts == result.final_belief.contacts


def test_b_est_is_deterministic_per_seed(flat):
    task, worker = flat
    a, b = (plan(task, worker, "b-est", seed=5, timeout_s=120) for _ in range(2))
    assert a.rollouts == b.rollouts and len(a.motions) == len(b.motions)
    for x, y in zip(a.motions, b.motions, strict=True):
        assert np.array_equal(x.G_d.homogeneous, y.G_d.homogeneous) and x.timeout_s == y.timeout_s


def test_b_est_out_of_time_says_so():
    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    result = plan(task, RolloutWorker(task, "panda"), "b-est", seed=0, timeout_s=0.5)
    assert not result.success and result.timed_out and result.reason.startswith("timeout")
    assert "tree nodes" in result.reason and result.motions == []


def test_mean_pose_ignores_quaternion_sign_and_averages_positions():
    rng = np.random.default_rng(0)
    X = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3))
    flipped = pin.SE3(pin.Quaternion(-pin.Quaternion(X.rotation).coeffs()).matrix(), X.translation)
    mean = mean_pose([X, flipped, X])
    assert np.allclose(mean.homogeneous, X.homogeneous, atol=1e-12)
    shifted = pin.SE3(X.rotation, X.translation + np.array([0.2, 0, 0]))
    assert np.allclose(mean_pose([X, shifted]).translation, X.translation + np.array([0.1, 0, 0]))


def test_density_cells_cover_the_workspace(flat):
    task, _ = flat
    low, high = workspace(task)
    assert np.all(high > low) and high[2] > task.X_WG0.translation[2]
    cell = _cell(start_belief(task, initial_belief(task)), low, high)
    assert len(cell) == 7
    assert all(0 <= c < POSITION_BINS for c in cell[:3])
    assert all(0 <= c < QUATERNION_BINS for c in cell[3:])
