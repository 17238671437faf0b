"""Particles and the belief generators of a task.

A particle is one guess of the uncertain transforms — the grasp ``X_GM`` and the environment
pose ``X_WO`` — and of the physical parameters given as axes (friction, the part's mass,
relative to the task's values). An offset on a pose axis is added to that pose's xyz [m] or
roll-pitch-yaw [rad] parameters, the way the task file writes poses (``grasp.pitch=2deg``
tilts the part about its own origin; ``env.y=1cm`` moves the environment along the world y
axis); ``friction=50%`` makes particles at 1.5 and 0.5 times the task's μ.
"""

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from sklearn.cluster import KMeans

from bilba_dist.geometry.pose import pose_from_xyz_rpy
from bilba_dist.task.loader import Task
from bilba_dist.task.schema import (
    AXES,
    ExplicitBelief,
    ExtremalRandomBelief,
    check_axis_key,
)


@dataclass(frozen=True)
class Particle:
    """One guess of the grasp ``X_GM``, the environment pose ``X_WO`` and, as scale factors
    on the task's values, the friction coefficient and the manipuland's mass."""

    X_GM: pin.SE3
    X_WO: pin.SE3
    offsets: Mapping[str, float] = field(default_factory=dict)  # axis -> offset [m|rad|1]
    #: The physics step it is simulated at; None: the task's (verification particles are
    #: simulated at the fine step when the task plans at a coarser one: task/timestep.py)
    timestep_s: float | None = None

    @property
    def friction_scale(self) -> float:
        return 1.0 + self.offsets.get("friction", 0.0)

    @property
    def mass_scale(self) -> float:
        return 1.0 + self.offsets.get("mass", 0.0)

    def X_OM(self, X_WG: pin.SE3) -> pin.SE3:
        """The manipuland in the environment frame with the gripper at ``X_WG``."""
        return self.X_WO.inverse() * X_WG * self.X_GM


def make_particle(task: Task, offsets: Mapping[str, float]) -> Particle:
    """The particle whose grasp and environment pose are offset per axis from nominal."""
    poses = {"grasp": task.spec.grasp, "env": task.spec.environment_pose}
    moved: dict[str, list[float]] = {k: [*p.xyz, *p.rpy] for k, p in poses.items()}
    for key, value in offsets.items():
        frame, axis = check_axis_key(key)
        if frame != "physical":  # friction and mass: read by the simulator from offsets
            moved[frame][AXES.index(axis)] += value
    return Particle(
        X_GM=pose_from_xyz_rpy(moved["grasp"][:3], moved["grasp"][3:]),
        X_WO=pose_from_xyz_rpy(moved["env"][:3], moved["env"][3:]),
        offsets=dict(offsets),
    )


def initial_belief(task: Task) -> tuple[Particle, ...]:
    """The task's initial belief, by its generator (deterministic: seeded where random)."""
    bounds = task.spec.bounds
    spec = task.spec.belief
    if isinstance(spec, ExplicitBelief):
        offsets = [
            {
                **{f"grasp.{a}": v for a, v in p.grasp.items()},
                **{f"env.{a}": v for a, v in p.env.items()},
            }
            for p in spec.particles
        ]
    elif isinstance(spec, ExtremalRandomBelief):
        offsets = extremal_offsets(bounds) + random_offsets(bounds, spec.random, spec.seed)
    else:
        offsets = [{}, *extremal_offsets(bounds), *inner_offsets(bounds, spec.points)]
    return tuple(make_particle(task, o) for o in offsets)


def extremal_offsets(bounds: Mapping[str, float]) -> list[dict[str, float]]:
    """+n and -n on each bounded axis, one axis at a time."""
    return [{key: sign * n} for key, n in bounds.items() for sign in (1.0, -1.0)]


def inner_offsets(bounds: Mapping[str, float], points: int) -> list[dict[str, float]]:
    """Between 0 and ±n on each bounded axis, evenly: for ``points`` = 5, ±n/2 (3: none)."""
    steps = (points - 1) // 2
    return [
        {key: sign * n * k / steps}
        for k in range(steps - 1, 0, -1)
        for key, n in bounds.items()
        for sign in (1.0, -1.0)
    ]


def stratified_offsets(bounds: Mapping[str, float], k: int, seed: int) -> list[dict[str, float]]:
    """``k`` offsets that cover the ellipsoid whose semi-axes are the bounds evenly, one in
    each cell of an even partition of it: with one bounded axis, one offset uniform in each of
    ``k`` equal slices of [-bound, +bound], in a shuffled order; with several, the centres of
    ``k`` k-means cells of a uniform draw (each axis measured against its bound), ordered
    farthest-first from a random one. Either way a prefix of the list spreads too."""
    keys = list(bounds)
    if not keys or k == 0:
        return []
    rng = np.random.default_rng(seed)
    if len(keys) == 1:
        (key,) = keys
        u = (rng.permutation(k) + rng.uniform(size=k)) / k
        return [{key: float((2 * x - 1) * bounds[key])} for x in u]
    scale = np.array([bounds[key] for key in keys])
    pool = np.array([[o[key] for key in keys] for o in random_offsets(bounds, 64 * k, seed)])
    cells = KMeans(n_clusters=k, n_init=1, random_state=seed).fit(pool / scale)
    centres = cells.cluster_centers_
    order = [int(rng.integers(k))]
    gap = np.linalg.norm(centres - centres[order[0]], axis=1)
    while len(order) < k:
        order.append(int(np.argmax(gap)))
        gap = np.minimum(gap, np.linalg.norm(centres - centres[order[-1]], axis=1))
    return [dict(zip(keys, (centres[i] * scale).tolist(), strict=True)) for i in order]


def random_offsets(bounds: Mapping[str, float], k: int, seed: int) -> list[dict[str, float]]:
    """``k`` offsets uniform inside the ellipsoid whose semi-axes are the bounds."""
    keys = list(bounds)
    if not keys or k == 0:
        return []
    rng = np.random.default_rng(seed)
    d = len(keys)
    direction = rng.normal(size=(k, d))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = rng.uniform(size=(k, 1)) ** (1.0 / d)
    unit = direction * radius
    scale = np.array([bounds[key] for key in keys])
    return [dict(zip(keys, (row * scale).tolist(), strict=True)) for row in unit]
