"""The RolloutWorker as a Ray actor on a real local Ray instance: same results as in-process."""

import pickle

import numpy as np
import pytest

ray = pytest.importorskip("ray")

from bilba_dist.task.loader import load_task  # noqa: E402
from bilba_dist.workers.rollout_worker import RolloutWorker  # noqa: E402
from tests.conftest import planner_in_progress, raylets_of  # noqa: E402
from tests.test_physics import fixed_motion_set  # noqa: E402


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def test_ray_actor_gives_bit_identical_rollouts(local_ray):
    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    requests = fixed_motion_set(task, 6, seed=5)
    local = RolloutWorker(task, "panda").simulate(requests)
    actor = ray.remote(RolloutWorker).remote(task.spec, "panda")
    remote = ray.get(actor.simulate.remote(requests))
    # ... and as `RayPool` calls it: requests and results pickled by us.
    pickled = pickle.loads(ray.get(actor.simulate_pickled.remote(pickle.dumps(requests))))
    for results in (remote, pickled):
        assert [r.contacts for r in results] == [r.contacts for r in local]
        for a, b in zip(results, local, strict=True):
            assert np.array_equal(a.state.q, b.state.q)
            assert np.array_equal(a.state.X_WM.homogeneous, b.state.X_WM.homogeneous)


def test_seeded_plan_is_the_same_in_process_and_on_one_or_two_ray_workers(local_ray):
    from bilba_dist.planning.bilba import plan
    from bilba_dist.workers.pool import RayPool

    task = load_task("peg-in-hole", ["grasp.pitch=2deg"])
    local = plan(task, RolloutWorker(task, "panda"), seed=4)
    assert local.success
    for workers in (1, 2):
        pool = RayPool(task, workers)
        remote = plan(task, pool, seed=4)
        pool.close()
        assert remote.rollouts == local.rollouts
        assert [m.contact for m in remote.motions] == [m.contact for m in local.motions]
        for a, b in zip(remote.motions, local.motions, strict=True):
            assert np.array_equal(a.G_d.homogeneous, b.G_d.homogeneous)
            assert np.array_equal(a.K, b.K)


def test_a_pool_on_the_first_actor_shares_it_and_closing_it_kills_nothing(local_ray):
    from bilba_dist.workers.pool import RayPool

    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    requests = fixed_motion_set(task, 4, seed=6)
    pool = RayPool(task, 2)
    one = pool.first(1)
    assert one.actors == pool.actors[:1]
    pid = ray.get(pool.actors[0].pid.remote())
    on_one = one.simulate(requests)
    one.close()
    assert ray.get(pool.actors[0].pid.remote()) == pid  # still the same live process
    on_two = pool.simulate(requests)
    pool.close()
    for a, b in zip(on_one, on_two, strict=True):
        assert np.array_equal(a.state.X_WM.homogeneous, b.state.X_WM.homogeneous)


def _same(results, expected):
    assert [r.contacts for r in results] == [r.contacts for r in expected]
    for a, b in zip(results, expected, strict=True):
        assert np.array_equal(a.state.X_WM.homogeneous, b.state.X_WM.homogeneous)


def test_prefetched_rollouts_are_the_ones_asked_for_next(local_ray):
    """A pool of two runs the guessed next batch on an idle actor; asked for next, those
    results are reused (not rerun) and equal what in-process rollouts give."""
    from bilba_dist.workers.pool import RayPool

    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    first, then = fixed_motion_set(task, 2, seed=7), fixed_motion_set(task, 6, seed=8)
    local = RolloutWorker(task, "panda")
    pool = RayPool(task, 2)
    _same(pool.simulate(first, prefetch=then), local.simulate(first))
    _same(pool.simulate(then), local.simulate(then))
    pool.close()
    assert pool.guessed > 0 and pool.guessed_used == pool.guessed


def test_guesses_not_asked_for_are_dropped_and_one_actor_does_not_guess(local_ray):
    from bilba_dist.workers.pool import RayPool

    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    first, unused = fixed_motion_set(task, 2, seed=7), fixed_motion_set(task, 6, seed=8)
    other = fixed_motion_set(task, 3, seed=9)
    local = RolloutWorker(task, "panda")
    pool = RayPool(task, 2)
    one = pool.first(1)
    _same(pool.simulate(first, prefetch=unused), local.simulate(first))
    _same(pool.simulate(other), local.simulate(other))
    assert pool.guessed > 0 and pool.guessed_used == 0 and not pool._ahead
    _same(one.simulate(first, prefetch=unused), local.simulate(first))
    assert one.guessed == 0
    pool.close()


def test_a_job_that_raised_on_ray_becomes_an_error_record(local_ray):
    """What ``ray.get`` raises for a job's own exception (Ray's class that is both the
    wrapper and the job's exception) is recorded, as `bilba batch` records a failed job,
    rather than ending the batch."""
    from bilba_dist.schedulers.batch import error_result

    @ray.remote
    def job() -> None:
        raise AttributeError("'Belief' object has no attribute 'under'")

    with pytest.raises(ray.exceptions.RayTaskError) as raised:
        ray.get(job.remote())
    record = error_result(raised.value)
    assert record["reason"] == "AttributeError: 'Belief' object has no attribute 'under'"
    assert any("in job" in line for line in record["traceback"])


def test_killing_a_worker_process_mid_plan_still_gives_the_same_plan(local_ray):
    """The actor restarts (re-running its constructor) and its lost rollouts are retried."""
    import os
    import signal

    from bilba_dist.planning.bilba import Progress, plan
    from bilba_dist.workers.pool import RayPool

    task = load_task("peg-in-hole", ["grasp.pitch=2deg"])
    local = plan(task, RolloutWorker(task, "panda"), seed=4)
    pool = RayPool(task, 2)
    victim = ray.get(pool.actors[0].pid.remote())
    killed_at = []

    def kill_once(progress: Progress) -> None:
        if not killed_at and progress.rollouts >= 20:
            os.kill(victim, signal.SIGKILL)
            killed_at.append(progress.rollouts)

    remote = plan(task, pool, seed=4, progress=Progress(update=kill_once))
    restarted = ray.get(pool.actors[0].pid.remote())
    pool.close()
    assert killed_at and killed_at[0] < remote.rollouts  # killed mid-plan
    assert restarted != victim
    assert remote.rollouts == local.rollouts
    for a, b in zip(remote.motions, local.motions, strict=True):
        assert np.array_equal(a.G_d.homogeneous, b.G_d.homogeneous) and a.contact == b.contact


@pytest.mark.parametrize(
    ("address", "message"),
    [
        ("127.0.0.1:1", "cannot reach the Ray cluster at 127.0.0.1:1"),
        ("nowhere", "write auto or HOST:PORT"),
    ],
)
def test_unreachable_cluster_is_one_line_and_exit_2(address, message, tmp_path):
    from click.testing import CliRunner

    from bilba_dist.cli.main import cli, register

    register()
    result = CliRunner().invoke(
        cli,
        [
            "plan",
            "peg-in-hole",
            "--address",
            address,
            "--no-log",
            "--out",
            str(tmp_path / "p.json"),
        ],
    )
    assert result.exit_code == 2
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_ray_dying_under_a_plan_is_one_line_and_keeps_the_log(tmp_path):
    """The local raylet killed mid-plan (`ray stop`, the OOM killer): the actors cannot
    restart, which is Ray gone, not a bug of ours; the log written so far stays readable."""
    from bilba_dist.record.reader import read_log

    planner, log = planner_in_progress(tmp_path, workers=1)
    (raylet,) = raylets_of(planner.pid)
    raylet.kill()
    _, err = planner.communicate(timeout=120)
    assert planner.returncode == 2 and "Traceback" not in err, err[-2000:]
    (line,) = (x for x in err.splitlines() if x.startswith("bilba:"))
    assert line.startswith("bilba: error: Ray died under this command")
    assert read_log(log).json("/transition") and not (tmp_path / "p.json").exists()
