"""The RolloutWorker as a Ray actor on a real local Ray instance: same results as in-process."""

import numpy as np
import pytest

ray = pytest.importorskip("ray")

from bilba_dist.task.loader import load_task  # noqa: E402
from tests.test_physics import fixed_motion_set  # noqa: E402
from workers.rollout_worker import RolloutWorker  # noqa: E402


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
    assert [r.contacts for r in remote] == [r.contacts for r in local]
    for a, b in zip(remote, local, strict=True):
        assert np.array_equal(a.state.q, b.state.q)
        assert np.array_equal(a.state.X_WM.homogeneous, b.state.X_WM.homogeneous)
