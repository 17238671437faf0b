"""`RolloutWorker`: simulates (particle, motion) pairs, keeping its PyBullet worlds alive.

One worker holds, for the current task, a Panda world per distinct grasp ``X_GM`` (the
grasp is built into the robot's URDF) and one floating world; each rollout only resets
state. The worlds are rebuilt only when the task's geometry changes. The same class runs
in-process and as a Ray actor (``ray.remote(RolloutWorker)``); a Ray actor gets its task
as a `TaskSpec`, which pickles, and builds its worlds in its own process.
"""

import os
import pickle
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import pinocchio as pin

from bilba_dist.rollout import DynamicsModel, RolloutRequest, RolloutResult
from bilba_dist.task.loader import Task, build_task
from bilba_dist.task.schema import TaskSpec
from bilba_dist.workers.floating_sim import FloatingSim
from bilba_dist.workers.panda_sim import PandaSim
from bilba_dist.workers.settings import SimSettings, driver_settings


def grasp_key(X_GM: pin.SE3) -> bytes:
    return np.round(X_GM.homogeneous, 12).tobytes()


class RolloutWorker:
    """Implements `bilba_dist.rollout.RolloutBackend` for one task at a time."""

    def __init__(
        self,
        task: Task | TaskSpec,
        model: DynamicsModel = "panda",
        settings: SimSettings | None = None,
    ) -> None:
        self.model = model
        self._panda: dict[bytes, PandaSim] = {}
        self._floating: dict[float, FloatingSim] = {}  # by step
        self.task = self._as_task(task)
        self._own = settings or SimSettings()
        self.settings = self._task_settings()

    def _task_settings(self) -> SimSettings:
        """The worker's own settings with the task's step, contact distance and ramp; a task
        planned for a driver runs as that driver would (`bilba_dist.robot.drivers`): the
        setpoint ramped along the hand's line, and no wrench clip where it has none."""
        planner = self.task.spec.planner
        settings = replace(
            self._own,
            timestep_s=self.task.timestep_s,
            contact_distance_m=planner.contact_distance_m,
            cartesian_ramp=self._own.cartesian_ramp or planner.cartesian_ramp,
        )
        if planner.driver != "none":
            settings = driver_settings(settings, planner.driver)
        return settings

    def simulates(self, task: Task) -> bool:
        """Whether a rollout here is one of ``task``'s (same worlds and controller settings)."""
        return world_key(task.spec) == world_key(self.task.spec)

    @staticmethod
    def _as_task(task: Task | TaskSpec) -> Task:
        return task if isinstance(task, Task) else build_task(task, task.name)

    def set_task(self, task: Task | TaskSpec) -> None:
        """Switch task; worlds are rebuilt only if the geometry or friction changed."""
        new = self._as_task(task)
        if _geometry(new.spec) != _geometry(self.task.spec):
            self.close()
        self.task = new
        self.settings = self._task_settings()
        for sim in [*self._panda.values(), *self._floating.values()]:
            # kept worlds follow the new task's settings, each at its own step
            sim.settings = self._settings_at(sim.settings.timestep_s)

    def simulate(
        self, requests: Sequence[RolloutRequest], prefetch: Sequence[RolloutRequest] = ()
    ) -> list[RolloutResult]:
        """Each request in turn (``prefetch`` is for backends with idle workers: unused)."""
        return [self._one(r) for r in requests]

    def simulate_pickled(self, requests: bytes) -> bytes:
        """``simulate`` for a pickled list of requests, its results pickled (how `RayPool`
        calls an actor)."""
        return pickle.dumps(self.simulate(pickle.loads(requests)), protocol=5)

    def _one(self, request: RolloutRequest) -> RolloutResult:
        particle = request.particle
        if self.model == "floating":
            return self._floating_sim(particle.timestep_s).rollout(
                particle.X_WO, particle.X_GM, request.state, request.motion, particle.friction_scale
            )
        physics = (particle.friction_scale, particle.mass_scale)
        sim = self.panda_sim(particle.X_GM, particle.timestep_s)
        return sim.rollout(particle.X_WO, request.state, request.motion, physics)

    def _settings_at(self, timestep_s: float | None) -> SimSettings:
        if timestep_s is None or timestep_s == self.settings.timestep_s:
            return self.settings
        return replace(self.settings, timestep_s=timestep_s)

    def panda_sim(self, X_GM: pin.SE3, timestep_s: float | None = None) -> PandaSim:
        """The world of grasp ``X_GM`` at the task's step, or at ``timestep_s``."""
        settings = self._settings_at(timestep_s)
        key = grasp_key(X_GM) + np.float64(settings.timestep_s).tobytes()
        if key not in self._panda:
            self._panda[key] = PandaSim(self.task, X_GM, settings)
        return self._panda[key]

    def _floating_sim(self, timestep_s: float | None = None) -> FloatingSim:
        settings = self._settings_at(timestep_s)
        if settings.timestep_s not in self._floating:
            self._floating[settings.timestep_s] = FloatingSim(self.task, settings)
        return self._floating[settings.timestep_s]

    def pid(self) -> int:
        """The process simulating (a Ray actor's worker process: tests kill it)."""
        return os.getpid()

    def __enter__(self) -> "RolloutWorker":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        for sim in self._panda.values():
            sim.close()
        self._panda.clear()
        for floating in self._floating.values():
            floating.close()
        self._floating.clear()


def world_key(spec: TaskSpec) -> tuple:
    """What a rollout depends on besides its request: the worlds and the settings a worker
    takes from its task."""
    planner = spec.planner
    return (*_geometry(spec), planner.contact_distance_m, planner.cartesian_ramp, planner.driver)


def _geometry(spec: TaskSpec) -> tuple:
    """What the worlds are built from: a change rebuilds them."""
    planner = spec.planner
    return (spec.manipuland, spec.environment, spec.friction, planner.sim_timestep_s)
