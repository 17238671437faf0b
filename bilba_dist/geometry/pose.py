"""SE(3) helpers on top of Pinocchio.

Poses are ``pin.SE3``; frames are named in variables with Drake's monogram notation
(``X_WG``: gripper in world, ``X_GM``: manipuland in gripper, ``X_WO``: environment in world).
Translations are in metres, angles in radians.
"""

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

#: cos(π/2) and sin(π) are ~1e-16 in floating point; a wider window (it was 1e-12) snapped
#: some entries of a rotation by an angle of ~1e-12 rad and not others, leaving R·Rᵀ off the
#: identity by 1e-12 (found by the property test below).
_SNAP = 1e-15


def snap_rotation(R: np.ndarray) -> np.ndarray:
    """Round entries within 1e-15 of -1, 0 or 1, so 90° rotations are exact."""
    R = np.array(R, dtype=float)
    nearest = np.round(R)
    close = np.abs(R - nearest) < _SNAP
    R[close] = nearest[close]
    return R


def pose_from_xyz_rpy(xyz: Sequence[float], rpy: Sequence[float]) -> pin.SE3:
    """Pose with translation ``xyz`` [m] and roll-pitch-yaw ``rpy`` [rad] (Z·Y·X order)."""
    R = snap_rotation(pin.rpy.rpyToMatrix(np.asarray(rpy, dtype=float)))
    return pin.SE3(R, np.asarray(xyz, dtype=float))


def xyz_rpy(X: pin.SE3) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of `pose_from_xyz_rpy`."""
    return X.translation.copy(), pin.rpy.matrixToRpy(X.rotation)


def transform_points(X: pin.SE3, points: np.ndarray) -> np.ndarray:
    """Apply ``X`` to an (N, 3) array of points."""
    return np.asarray(points) @ X.rotation.T + X.translation


def rotation_key(R: np.ndarray, decimals: int = 9) -> bytes:
    """A hashable key of a rotation, equal for rotations that agree to ``decimals``."""
    return (np.round(np.asarray(R, dtype=float), decimals) + 0.0).tobytes()


def pose_json(X: pin.SE3) -> dict[str, Any]:
    """``X`` as JSON: ``xyz`` and ``quat_xyzw``."""
    return {
        "xyz": X.translation.tolist(),
        "quat_xyzw": pin.Quaternion(X.rotation).coeffs().tolist(),
    }


def setpoint_json(X: pin.SE3) -> dict[str, Any]:
    """A motion's setpoint as JSON: ``pose_json`` plus ``rotation``, the 3×3 matrix exactly
    as simulated (the quaternion's round trip can move it by ~1e-11; plan/file.py)."""
    return {**pose_json(X), "rotation": X.rotation.tolist()}
