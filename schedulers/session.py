"""Where rollouts run: in-process, on a local Ray instance the command starts and stops
(the default: two CPUs, no dashboard), or on an existing Ray cluster (``--address``)."""

import logging
import socket
from collections.abc import Iterator
from contextlib import contextmanager

from bilba_dist.errors import BilbaError, first_line
from bilba_dist.rollout import DynamicsModel, RolloutBackend
from bilba_dist.task.loader import Task


@contextmanager
def ray_session(workers: int, address: str | None) -> Iterator[None]:
    """Start a local Ray instance with ``workers`` CPUs, or join the cluster at ``address``."""
    import ray

    if address and address != "auto":
        check_reachable(address)
    try:
        ray.init(
            address=address,
            num_cpus=None if address else workers,
            include_dashboard=False,
            log_to_driver=False,
            logging_level=logging.ERROR,
            configure_logging=True,
        )
    except (ConnectionError, RuntimeError, ValueError) as exc:
        where = f"the Ray cluster at {address}" if address else "a local Ray instance"
        first = first_line(exc, type(exc).__name__)
        raise BilbaError(f"cannot start or reach {where}: {first}") from None
    try:
        yield
    except (ray.exceptions.LocalRayletDiedError, ray.exceptions.RayActorError) as exc:
        if getattr(exc, "actor_init_failed", False):  # an actor's constructor raised: ours
            raise
        raise BilbaError(ray_lost(exc)) from None
    finally:
        ray.shutdown()


def ray_lost(exc: Exception) -> str:
    """The line for Ray gone under a command: its local raylet died (`ray stop`, the OOM
    killer), or an actor's node did and Ray could not restart it (the pool's actors restart
    without limit, so an actor that stays dead means Ray itself is gone)."""
    first = first_line(exc)
    return (
        f"Ray died under this command ({type(exc).__name__}: {first}); what was written "
        "so far is kept: run it again"
    )


def check_reachable(address: str, timeout_s: float = 3.0) -> None:
    """Fail fast, in one line, when nothing listens at HOST:PORT (ray.init would retry for
    minutes)."""
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise BilbaError(f"--address {address!r}: write auto or HOST:PORT")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            pass
    except OSError as exc:
        raise BilbaError(
            f"cannot reach the Ray cluster at {address}: {exc.strerror or exc}"
        ) from None


@contextmanager
def rollout_backend(
    task: Task,
    workers: int = 2,
    address: str | None = None,
    model: DynamicsModel = "panda",
) -> Iterator[RolloutBackend]:
    """``workers`` = 0 runs in-process; otherwise a pool of that many Ray actors."""
    if workers == 0:
        from bilba_dist.workers.rollout_worker import RolloutWorker

        worker = RolloutWorker(task, model)
        try:
            yield worker
        finally:
            worker.close()
        return
    from bilba_dist.workers.pool import RayPool

    with ray_session(workers, address):
        pool = RayPool(task, workers, model)
        try:
            yield pool
        finally:
            pool.close()
