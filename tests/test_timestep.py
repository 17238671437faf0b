"""The physics step read off a task's parts, and plans verified at the fine step."""

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from bilba_dist.belief.particles import initial_belief
from bilba_dist.belief.start import start_belief
from bilba_dist.planning.verify import verify_particles
from bilba_dist.rollout import Motion, RolloutRequest
from bilba_dist.task.loader import load_task, with_planner
from bilba_dist.task.timestep import COARSE_STEP_S, FINE_STEP_S, goal_play
from bilba_dist.workers.rollout_worker import RolloutWorker
from tests.conftest import prism_file, prism_task


@pytest.mark.parametrize(
    ("name", "play_mm", "step"),
    [
        ("peg-in-hole", 5.5, COARSE_STEP_S),
        ("hex-peg", 3.0, FINE_STEP_S),
        ("puzzle", 0.5, FINE_STEP_S),
    ],
)
def test_a_builtin_task_plans_at_the_step_its_goal_play_allows(name, play_mm, step):
    task = load_task(name)
    X_OM = task.X_WO.inverse() * task.X_WG0 * task.X_GM
    assert goal_play(task.environment, task.manipuland, task.goal, X_OM) == pytest.approx(
        play_mm / 1000, abs=2e-5
    )
    assert task.timestep_s == step and task.spec.planner.sim_timestep_s == step


@pytest.mark.parametrize(("clearance_mm", "step"), [(6, COARSE_STEP_S), (2, FINE_STEP_S)])
def test_a_task_of_our_own_gets_its_step_from_its_clearance(tmp_path, clearance_mm, step):
    task = prism_task(tmp_path, 8, clearance_mm / 1000)
    assert task.timestep_s == step


def test_a_step_the_file_sets_is_kept(tmp_path):
    task = prism_task(tmp_path, 8, 0.006, {"sim_timestep_s": 0.002})
    assert task.timestep_s == 0.002
    # ... and one unset again is read off the parts
    assert with_planner(task, sim_timestep_s=None).timestep_s == COARSE_STEP_S


def test_verification_particles_run_at_the_fine_step_on_a_coarse_task():
    coarse = load_task("peg-in-hole", ["grasp.x=1cm"])
    assert coarse.timestep_s == COARSE_STEP_S
    assert {p.timestep_s for p in verify_particles(coarse, 0.5)} == {FINE_STEP_S}
    fine = with_planner(coarse, sim_timestep_s=FINE_STEP_S)
    assert {p.timestep_s for p in verify_particles(fine, 0.5)} == {None}  # the task's own


def test_a_particle_at_its_own_step_is_simulated_in_a_world_at_that_step():
    """The same motion on the same particle at the task's step, at the fine step (in a world
    of its own, built at that step) and at the task's step again: the first and last agree
    bit for bit, the fine one ends nearby but not on the same bits."""
    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    nominal = initial_belief(task)[0]
    fine = replace(nominal, timestep_s=FINE_STEP_S)
    state = start_belief(task, [nominal]).states[0]
    G_d = pin.SE3(task.X_WG0.rotation, task.X_WG0.translation - [0.0, 0.0, 0.02])
    motion = Motion(np.diag([500.0] * 3 + [50.0] * 3), G_d, 1.0)
    with RolloutWorker(task) as worker:
        coarse_1, at_fine, coarse_2 = worker.simulate(
            [RolloutRequest(p, state, motion) for p in (nominal, fine, nominal)]
        )
        assert worker.panda_sim(nominal.X_GM).settings.timestep_s == COARSE_STEP_S
        assert worker.panda_sim(nominal.X_GM, FINE_STEP_S).settings.timestep_s == FINE_STEP_S
    assert coarse_1.sim_time_s == coarse_2.sim_time_s
    assert (coarse_1.state.q == coarse_2.state.q).all()
    assert (at_fine.state.q != coarse_1.state.q).any()
    assert abs(at_fine.state.q - coarse_1.state.q).max() < 1e-2


class Recording:
    """A real worker, with the step of every particle it is asked to simulate written down."""

    def __init__(self, worker: RolloutWorker) -> None:
        self.worker, self.steps = worker, list[float | None]()

    def simulate(self, requests, prefetch=()):
        self.steps += [r.particle.timestep_s for r in requests]
        return self.worker.simulate(requests, prefetch)


def test_a_plan_made_at_the_coarse_step_is_verified_at_the_fine_step():
    from bilba_dist.planning.bilba import plan

    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    with RolloutWorker(task) as worker:
        backend = Recording(worker)
        result = plan(task, backend, "bilba-variable", seed=0, timeout_s=300)
    assert result.success and result.verification is not None and result.verification.passed
    fine = backend.steps.count(FINE_STEP_S)
    # every verification rollout at the fine step (more if a plan failed and its lost
    # particles became check particles), the search's at the task's own
    assert fine >= result.verification.particles * len(result.motions) > 0
    assert backend.steps.count(None) == result.rollouts - fine


@pytest.mark.parametrize(
    ("clearance_mm", "says"), [(6, "at 120 Hz, verified at 240 Hz"), (2, "at 240 Hz")]
)
def test_bilba_plan_says_the_step_of_a_task_of_our_own(tmp_path, clearance_mm, says):
    from tests.test_task_files import run_cli

    path = prism_file(tmp_path, 8, clearance_mm / 1000)
    out = tmp_path / "plan.json"
    result = run_cli("plan", str(path), "--workers", "0", "--no-log", "--out", str(out))
    assert result.exit_code == 0, result.output
    (planner,) = [line for line in result.output.splitlines() if line.startswith("planner")]
    assert planner.endswith(f"physics {says}")
    assert "plan found" in result.output
