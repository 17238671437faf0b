"""Pieces both dynamics models share: time accounting, damping from stiffness (defined in
`bilba_dist.rollout`), the setpoint ramp's length, and labelling the final contacts."""

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from bilba_dist.geometry.contact import ContactSet
from bilba_dist.geometry.labels import label_points
from bilba_dist.geometry.piece import Part
from bilba_dist.rollout import damping as damping
from bilba_dist.workers.scene import EnvironmentBodies
from bilba_dist.workers.settings import SimSettings


@dataclass
class SimStats:
    """Where a world's time went: steps taken and seconds inside stepSimulation."""

    steps: int = 0
    physics_s: float = 0.0

    def add(self, steps: int, physics_s: float) -> None:
        self.steps += steps
        self.physics_s += physics_s


def ramp_steps(X_start: pin.SE3, X_goal: pin.SE3, settings: SimSettings) -> int:
    """Steps over which the setpoint moves from ``X_start`` to ``X_goal``."""
    delta = pin.log6(X_start.actInv(X_goal))
    seconds = max(
        float(np.linalg.norm(delta.linear)) / settings.ramp_speed_m_s,
        float(np.linalg.norm(delta.angular)) / settings.ramp_speed_rad_s,
        settings.min_ramp_s,
    )
    return max(1, math.ceil(seconds / settings.timestep_s))


def blend_steps(settings: SimSettings) -> int:
    """Steps over which the ramp's speed eases in (and out): 0 for a plain linear ramp."""
    return round(settings.ramp_blend_s / settings.timestep_s)


def ramp_fractions(n: int, blend: int) -> np.ndarray:
    """How far along the ramp the setpoint is at each of its ``n + blend`` steps: 1/n of the
    way a step, or with ``blend`` > 0 that speed eased in and out over ``blend`` steps by a
    raised cosine (continuous velocity and acceleration; it trails the linear ramp by
    ``blend / 2`` steps and ends ``blend`` steps later). The exported libfranka script runs
    the same profile in time (plans/export.py, ``fraction``)."""
    k = np.arange(1, n + blend + 1, dtype=float)
    if blend <= 0:
        return np.minimum(1.0, k / n)
    v, b = 1.0 / n, float(min(blend, n))

    def eased(u: np.ndarray) -> np.ndarray:
        return v * (u / 2 - b / (2 * np.pi) * np.sin(np.pi * u / b))

    plateau = v * (k - b / 2)
    out = np.where(k < b, eased(k), plateau)
    out = np.where(k > n, 1.0 - eased(np.maximum(n + b - k, 0.0)), out)
    return np.minimum(out, 1.0)


def label_final_contacts(
    env: EnvironmentBodies,
    manipuland: Part,
    X_WO: pin.SE3,
    X_WM: pin.SE3,
    body: int,
    link: int,
    distance: float,
) -> ContactSet:
    """The contact set between the manipuland (``body``/``link``) and the environment."""
    by_piece: dict[int, list] = {}
    for piece, on_env, on_part, normal in env.contact_points(body, link, distance):
        by_piece.setdefault(piece, []).append((on_env, on_part, normal))
    contacts: set = set()
    for piece, rows in by_piece.items():
        on_env, on_part, normal = (np.array(col) for col in zip(*rows, strict=True))
        contacts |= label_points(
            env.part.pieces[piece],
            manipuland,
            (on_env - X_WO.translation) @ X_WO.rotation,
            normal @ X_WO.rotation,
            (on_part - X_WM.translation) @ X_WM.rotation,
            X_WO.rotation.T @ X_WM.rotation,
        )
    return frozenset(contacts)


def ramp_poses(
    X_start: pin.SE3, X_goal: pin.SE3, n: int, fractions: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The setpoint at each of ``n`` ramp steps (or at each of ``fractions`` of the way),
    along the SE(3) geodesic: rotations and positions, ending at ``X_goal``."""
    delta = pin.log6(X_start.actInv(X_goal)).vector
    along = [(k + 1) / n for k in range(n)] if fractions is None else fractions
    poses = [X_start * pin.exp6(f * delta) for f in along]
    return np.array([X.rotation for X in poses]), np.array([X.translation for X in poses])
