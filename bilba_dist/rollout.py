"""The rollout interface: the only way the planner reaches a simulator.

The planner builds `RolloutRequest`s — one particle, its current state, one compliant
motion — and hands batches to a `RolloutBackend`; results come back in request order.
`workers/` implements the backend in-process and on Ray; nothing here imports pybullet.
"""

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal, Protocol

import numpy as np
import pinocchio as pin

from bilba_dist.belief.particles import Particle
from bilba_dist.errors import BilbaError
from bilba_dist.geometry.contact import ContactSet
from bilba_dist.task.loader import Task

DynamicsModel = Literal["panda", "floating"]


def _frozen(array: np.ndarray | Sequence[float] | None, shape: tuple[int, ...]) -> np.ndarray:
    a = np.array(array if array is not None else np.zeros(shape), dtype=float)
    if a.shape != shape:
        raise ValueError(f"expected shape {shape}, got {a.shape}")
    a.flags.writeable = False
    return a


@lru_cache(maxsize=1024)
def is_symmetric_psd(K_bytes: bytes) -> bool:
    """Whether the 6×6 matrix (as bytes) is symmetric positive semi-definite. Cached: a
    contact's candidate motions share one K, and an eigendecomposition costs ~80 µs."""
    K = np.frombuffer(K_bytes).reshape(6, 6)
    return bool(np.allclose(K, K.T, atol=1e-9) and np.linalg.eigvalsh(K).min() >= -1e-9)


def damping(K: np.ndarray) -> np.ndarray:
    """``D = 2·sqrtm(K)``: the symmetric square root of the stiffness, doubled — the damping
    the simulated controller pairs with ``K`` (and plan files record)."""
    w, V = np.linalg.eigh(np.asarray(K, dtype=float))
    return 2.0 * (V * np.sqrt(np.clip(w, 0.0, None))) @ V.T


@dataclass(frozen=True)
class Motion:
    """A compliant motion ``u = (K, G_d)`` run for ``timeout_s``: ``K`` is the 6×6 Cartesian
    stiffness at the gripper, rotation first [N·m/rad, N/m], in world axes; ``G_d`` the
    gripper setpoint ``X_WG`` at the end of the ramp."""

    K: np.ndarray
    G_d: pin.SE3
    timeout_s: float = 5.0

    def __post_init__(self) -> None:
        K = _frozen(self.K, (6, 6))
        if not is_symmetric_psd(K.tobytes()):
            raise ValueError("stiffness K must be symmetric positive semi-definite")
        object.__setattr__(self, "K", K)
        if self.timeout_s <= 0:
            raise ValueError(f"timeout must be positive, got {self.timeout_s}")


@dataclass(frozen=True)
class ParticleState:
    """Where one particle's robot is: arm joints (Panda model) and the manipuland's pose and
    twist in the world (both models; the floating model moves only these)."""

    X_WM: pin.SE3
    q: np.ndarray = field(default_factory=lambda: np.zeros(7))
    dq: np.ndarray = field(default_factory=lambda: np.zeros(7))
    V_WM: np.ndarray = field(default_factory=lambda: np.zeros(6))  # angular, linear [world]
    #: Why the real arm would have stopped here (a joint at its limit: a reflex); None while
    #: it runs. A stopped particle stays where it is and in no contact for every later motion.
    stopped: str | None = None
    #: The environment's pieces that the arm or hand (not the part) touches here, by name
    #: (Panda model): the fingers on a rim, a link against a wall. A real gripper is not
    #: meant to press there; `bilba execute` and the log say so.
    arm_touches: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", _frozen(self.q, (7,)))
        object.__setattr__(self, "dq", _frozen(self.dq, (7,)))
        object.__setattr__(self, "V_WM", _frozen(self.V_WM, (6,)))


@dataclass(frozen=True)
class RolloutRequest:
    particle: Particle
    state: ParticleState
    motion: Motion


@dataclass(frozen=True)
class RolloutResult:
    """The end of one rollout: the new state, the contact set ``D(q)``, the joint setpoint
    ``q_d`` the motion used (Panda model), simulated time, and whether it stopped early
    because everything had settled. Panda model: the spring's peak wrench per axis (at the
    hand, world axes, rotation first: N·m, N) and its peak torque per joint [N·m] over the
    rollout — in contact, the load the robot's collision detection sees."""

    state: ParticleState
    contacts: ContactSet
    q_d: np.ndarray
    sim_time_s: float
    settled: bool
    reachable: bool = True
    peak_wrench: np.ndarray | None = None
    peak_joint_torque: np.ndarray | None = None


class RolloutBackend(Protocol):
    """Simulate (particle, motion) pairs; results in request order.

    ``prefetch``: requests the caller will probably ask for next (the same objects). A
    backend with idle workers may start them now; either way a rollout's result depends
    only on its request, so the answer to the later call is the same."""

    def simulate(
        self, requests: Sequence[RolloutRequest], prefetch: Sequence[RolloutRequest] = ()
    ) -> list[RolloutResult]: ...


def require_world(task: Task, backend: RolloutBackend) -> None:
    """Refuse a backend whose worlds are another task's: a world carries the task's friction,
    parts and time step (a particle only scales them), so replaying ``with_friction(task,
    0.5)`` on a worker made for ``task`` would silently run at ``task``'s friction. Backends
    that cannot tell (no ``simulates``) pass."""
    simulates = getattr(backend, "simulates", None)
    if simulates is not None and not simulates(task):
        raise BilbaError(
            "the rollout backend was made for another task's world (friction, parts, time "
            "step or controller settings differ): make it from this task, e.g. "
            "RolloutWorker(task)"
        )
