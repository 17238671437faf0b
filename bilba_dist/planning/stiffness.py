"""Stiffness for a motion: BILBA-Fixed's constant "very stiff" gains, or BILBA-Variable's
gains shaped by the C-obs normal of the contact sought (paper §4.2).

Variable: translational ``K_t = R_C·diag(stiff, stiff, soft)·R_Cᵀ`` with R_C taking z to the
C-obs normal of the contact at a sampled particle; rotational the same around the rotational
part of the 6-D C-obs normal, found by finite differences of the contact facet's signed
distance over small rotations. ``K = blockdiag(K_r, K_t)`` (rotation first) [N·m/rad, N/m].
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from bilba_dist.cspace.polytope import minkowski_polytope
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.task.loader import Task


@dataclass(frozen=True)
class Gains:
    """Authors' values (docs/reference-values.md)."""

    rot_stiff: float = 100.0
    rot_soft: float = 60.0
    trans_stiff: float = 600.0
    trans_soft: float = 400.0
    rot_step: float = 0.02  # finite-difference step [rad]


VERY_STIFF = np.diag([100.0, 100.0, 100.0, 600.0, 600.0, 600.0])


def fixed_stiffness() -> np.ndarray:
    return VERY_STIFF.copy()


def frame_with_z(direction: np.ndarray) -> np.ndarray:
    """A rotation whose third column is the unit ``direction``."""
    z = direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def compliant_along(direction: np.ndarray | None, stiff: float, soft: float) -> np.ndarray:
    if direction is None or np.linalg.norm(direction) < 1e-9:
        return stiff * np.eye(3)
    R = frame_with_z(direction)
    return R @ np.diag([stiff, stiff, soft]) @ R.T


def driver_fit(task: Task) -> Callable[[np.ndarray, pin.SE3], np.ndarray]:
    """The task's ``planner.driver`` as a map (K, setpoint G_d) → the K that driver holds for
    that motion, in the plan's frame (docs/drivers.md: the EE offset turns with the hand, so
    the fit depends on G_d's rotation); the identity for ``none``."""
    planner = task.spec.planner
    if planner.driver == "none":
        return lambda K, G_d: K
    from bilba_dist.robot.drivers import DRIVERS, fit_hand

    driver, offset = DRIVERS[planner.driver], np.array(planner.ee_offset_m)
    return lambda K, G_d: fit_hand(K, G_d.rotation, driver, offset)[0]


def variable_stiffness(
    task: Task, mode: ContactPair, X_OM: pin.SE3, gains: Gains = Gains()
) -> np.ndarray:
    """Soft along the 6-D C-obs normal of ``mode`` at the manipuland pose ``X_OM``."""
    normal_t, normal_r = cobs_normal(task, mode, X_OM, gains.rot_step)
    K = np.zeros((6, 6))
    K[:3, :3] = compliant_along(normal_r, gains.rot_stiff, gains.rot_soft)
    K[3:, 3:] = compliant_along(normal_t, gains.trans_stiff, gains.trans_soft)
    return K


def cobs_normal(
    task: Task, mode: ContactPair, X_OM: pin.SE3, step: float
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Translational and rotational parts of the C-obs normal of ``mode`` near ``X_OM``:
    the gradient of the signed distance ``φ = n·p − b`` of the nearest facet carrying the
    mode, in position (n, unit) and in rotation (central differences about world axes)."""
    env, manip = task.environment.piece(mode.env), task.manipuland.piece(mode.manip)

    def phi(R: np.ndarray) -> tuple[float, np.ndarray] | None:
        polytope = minkowski_polytope(env, manip, R)
        facets = [f for f, label in enumerate(polytope.labels) if mode in label]
        if not facets:
            return None
        p = X_OM.translation
        distance = [abs(polytope.A[f] @ p - polytope.b[f]) for f in facets]
        f = facets[int(np.argmin(distance))]
        return float(polytope.A[f] @ p - polytope.b[f]), polytope.A[f]

    here = phi(X_OM.rotation)
    if here is None:
        return None, None
    gradient = np.zeros(3)
    for axis in range(3):
        twist = np.zeros(3)
        twist[axis] = step
        plus = phi(pin.exp3(twist) @ X_OM.rotation)
        minus = phi(pin.exp3(-twist) @ X_OM.rotation)
        if plus is None or minus is None:
            return here[1], None
        gradient[axis] = (plus[0] - minus[0]) / (2 * step)
    return here[1], gradient
