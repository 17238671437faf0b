"""The Franka Panda of pybullet_data, in Pinocchio: FK, Jacobian, gravity, and IK.

The finger joints are locked (the gripper holds the part rigidly) and the manipuland's mass
is added to the last link at its grasp, so gravity compensation includes the part. Frames:
``G`` is ``panda_hand``; the robot base is the world origin. Units: m, rad, kg, N·m.
"""

import os
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import pybullet_data

from bilba_dist.errors import UnreachableError

ARM_JOINTS = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGER_JOINTS = ("panda_finger_joint1", "panda_finger_joint2")
HAND = "panda_hand"
#: Torque limits of the seven arm joints [N·m] (Franka's datasheet; docs/reference-values.md).
TORQUE_LIMITS = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])
#: A joint this close to its limit has reached it: a Franka stops there with a reflex, so a
#: simulated rollout that comes this close ends its particle's run, and a start posture
#: keeps at least this far away [rad].
LIMIT_MARGIN_RAD = 1e-3
#: A comfortable mid-range posture: the IK's joint-centring target.
Q_CENTRE = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 2.0, np.pi / 4])

#: Joint position limits [rad] from Franka's robot specifications. The Panda URDF we load
#: (pybullet_data's) allows more (joint 5 ±2.9671 against the robot's ±2.8973), so the IK
#: keeps to these: a plan must run on the real arm. The Franka Research 3's are narrower at
#: joints 1, 5, 6 (from 0.5445) and joint 4's top; export checks a plan against them.
JOINT_LIMITS: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {
    "Panda": (
        (-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973),
        (2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973),
    ),
    "Franka Research 3": (
        (-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159),
        (2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159),
    ),
}


def panda_urdf() -> str:
    return os.path.join(pybullet_data.getDataPath(), "franka_panda", "panda.urdf")


@dataclass(frozen=True)
class IKSettings:
    damping: float = 1e-4  # damped least squares λ²
    centring: float = 0.05  # weight of the pull towards Q_CENTRE in the null space
    centring_until: float = 1e-3  # drop the pull below this error, to converge exactly
    max_iterations: int = 200
    tolerance: float = 1e-5  # norm of the 6-D error [m, rad]
    step: float = 1.0


def arm_limits(arms: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The joint limits [rad] within which every one of ``arms`` can go (JOINT_LIMITS)."""
    low, high = np.full(7, -np.inf), np.full(7, np.inf)
    for arm in arms:
        low, high = np.maximum(low, JOINT_LIMITS[arm][0]), np.minimum(high, JOINT_LIMITS[arm][1])
    return low, high


class PandaModel:
    """Pinocchio model of the arm with the fingers locked and an optional payload."""

    def __init__(
        self,
        payload_mass: float = 0.0,
        X_GM: pin.SE3 | None = None,
        com_M: np.ndarray | None = None,
        arms: tuple[str, ...] = ("Panda",),
    ) -> None:
        """``arms``: the IK keeps within the joint limits of every one (JOINT_LIMITS)."""
        full = pin.buildModelFromUrdf(panda_urdf())
        locked = [full.getJointId(name) for name in FINGER_JOINTS]
        self.model = pin.buildReducedModel(full, locked, pin.neutral(full))
        self.hand = self.model.getFrameId(HAND)
        if payload_mass > 0:
            X_GM = X_GM if X_GM is not None else pin.SE3.Identity()
            self._add_payload(payload_mass, X_GM, np.zeros(3) if com_M is None else com_M)
        self.data = self.model.createData()
        low, high = arm_limits(arms)
        self.lower = np.maximum(self.model.lowerPositionLimit, low)
        self.upper = np.minimum(self.model.upperPositionLimit, high)

    def limit_reached(self, low: np.ndarray, high: np.ndarray) -> tuple[int, str, float] | None:
        """The first joint whose range ``[low, high]`` (lowest and highest angle, or a
        posture given twice) came within LIMIT_MARGIN_RAD of its limit: (joint 1–7, "lower"
        or "upper", that limit [rad]); None when every joint kept clear."""
        for j in range(7):
            if low[j] <= self.lower[j] + LIMIT_MARGIN_RAD:
                return j + 1, "lower", float(self.lower[j])
            if high[j] >= self.upper[j] - LIMIT_MARGIN_RAD:
                return j + 1, "upper", float(self.upper[j])
        return None

    def _add_payload(self, mass: float, X_GM: pin.SE3, com_M: np.ndarray) -> None:
        frame = self.model.frames[self.hand]
        X_JM = frame.placement * X_GM  # the part's frame in the last joint's frame
        inertia = pin.Inertia(mass, X_JM.act(np.asarray(com_M, dtype=float)), np.eye(3) * 1e-4)
        self.model.inertias[frame.parentJoint] += inertia

    def fk(self, q: np.ndarray) -> pin.SE3:
        """``X_WG``: the hand in the world."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.hand].copy()

    def jacobian_and_gravity(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The hand's 6×7 Jacobian, rotation rows first, world-aligned; and g(q)."""
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        J = pin.getFrameJacobian(self.model, self.data, self.hand, pin.LOCAL_WORLD_ALIGNED)
        g = pin.computeGeneralizedGravity(self.model, self.data, q)
        return np.vstack([J[3:], J[:3]]), g

    def ik(
        self, X_WG: pin.SE3, q_seed: np.ndarray, settings: IKSettings = IKSettings()
    ) -> np.ndarray:
        """Joint angles putting the hand at ``X_WG``: damped least squares with a pull
        towards the centre posture in the null space, clipped to the joint limits."""
        q = np.clip(np.asarray(q_seed, dtype=float), self.lower, self.upper)
        eye = np.eye(6)
        for _ in range(settings.max_iterations):
            pin.framesForwardKinematics(self.model, self.data, q)
            error = pin.log6(self.data.oMf[self.hand].actInv(X_WG)).vector  # local frame
            if np.linalg.norm(error) < settings.tolerance:
                return q
            J = pin.computeFrameJacobian(self.model, self.data, q, self.hand, pin.LOCAL)
            JJt = J @ J.T + settings.damping * eye
            J_pinv = J.T @ np.linalg.solve(JJt, eye)
            dq = J_pinv @ error
            if np.linalg.norm(error) > settings.centring_until:  # damped J⁺ leaks: stop
                dq += settings.centring * (np.eye(7) - J_pinv @ J) @ (Q_CENTRE - q)
            q = np.clip(q + settings.step * dq, self.lower, self.upper)
        raise UnreachableError(
            f"no IK solution for the gripper at {np.round(X_WG.translation, 4).tolist()} m "
            f"(error {np.linalg.norm(error):.2g} after {settings.max_iterations} iterations)",
            float(np.linalg.norm(error)),
        )
