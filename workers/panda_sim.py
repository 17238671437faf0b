"""The Panda model of one grasp: τ = K_q(q_d − q) − B_q q̇ + g(q) + null-space posture.

``K_q = Jᵀ K J`` and ``B_q = Jᵀ B J`` with ``B = 2√K``; J (hand, world axes, rotation
first) and g(q) come from Pinocchio on the same URDF, including the part's mass. The joint
setpoint ``q_d`` (IK of ``G_d``) is approached along a straight joint-space ramp.
"""

import math
import shutil

import numpy as np
import pinocchio as pin
import pybullet as p

from bilba_dist.errors import UnreachableError
from bilba_dist.robot.panda import ARM_JOINTS, TORQUE_LIMITS, PandaModel
from bilba_dist.rollout import Motion, ParticleState, RolloutResult
from bilba_dist.task.loader import Task
from workers.motion import clip_norm, damping, label_final_contacts, ramp_steps
from workers.scene import EnvironmentBodies, connect
from workers.settings import SimSettings
from workers.urdf import PART_LINK, panda_with_part, part_centre


class PandaSim:
    """A PyBullet world with the Panda holding the part at one grasp ``X_GM``."""

    def __init__(self, task: Task, X_GM: pin.SE3, settings: SimSettings) -> None:
        self.task, self.X_GM, self.settings = task, X_GM, settings
        self.client = connect(settings.timestep_s, -9.81)
        mass = task.spec.manipuland.mass
        urdf = panda_with_part(task.manipuland, X_GM, mass)
        self.robot = p.loadURDF(
            str(urdf),
            useFixedBase=True,
            flags=p.URDF_USE_INERTIA_FROM_FILE,
            physicsClientId=self.client,
        )
        shutil.rmtree(urdf.parent, ignore_errors=True)
        names = {
            p.getJointInfo(self.robot, j, physicsClientId=self.client)[1].decode(): j
            for j in range(p.getNumJoints(self.robot, physicsClientId=self.client))
        }
        self.joints = [names[n] for n in ARM_JOINTS]
        self.part_link = names[f"{PART_LINK}_joint"]
        p.changeDynamics(
            self.robot, self.part_link, lateralFriction=1.0, physicsClientId=self.client
        )
        p.setJointMotorControlArray(
            self.robot,
            self.joints,
            p.VELOCITY_CONTROL,
            forces=[0.0] * 7,
            physicsClientId=self.client,
        )
        self.env = EnvironmentBodies.create(task.environment, task.spec.friction, self.client)
        self.model = PandaModel(mass, X_GM, part_centre(task.manipuland))
        self.clean = p.saveState(physicsClientId=self.client)

    def close(self) -> None:
        p.disconnect(physicsClientId=self.client)

    def reset(self, X_WO: pin.SE3, q: np.ndarray, dq: np.ndarray) -> None:
        """Put the world in a known state: no history carries over between rollouts."""
        p.restoreState(self.clean, physicsClientId=self.client)
        self.env.place(X_WO)
        for j, qi, dqi in zip(self.joints, q, dq, strict=True):
            p.resetJointState(self.robot, j, qi, dqi, physicsClientId=self.client)

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        states = p.getJointStates(self.robot, self.joints, physicsClientId=self.client)
        return np.array([s[0] for s in states]), np.array([s[1] for s in states])

    def part_pose(self) -> tuple[pin.SE3, np.ndarray]:
        state = p.getLinkState(
            self.robot,
            self.part_link,
            computeLinkVelocity=1,
            computeForwardKinematics=1,
            physicsClientId=self.client,
        )
        X_WM = pin.XYZQUATToSE3(np.array([*state[4], *state[5]]))
        return X_WM, np.array([*state[7], *state[6]])

    def rollout(self, X_WO: pin.SE3, start: ParticleState, motion: Motion) -> RolloutResult:
        self.reset(X_WO, start.q, start.dq)
        try:
            q_d = self.model.ik(motion.G_d, start.q)
        except UnreachableError:
            return self._result(X_WO, start.q, 0.0, settled=False, reachable=False)
        steps, settled = self._run(start.q, q_d, motion)
        return self._result(X_WO, q_d, steps * self.settings.timestep_s, settled, True)

    def _run(self, q0: np.ndarray, q_d: np.ndarray, motion: Motion) -> tuple[int, bool]:
        s = self.settings
        K, B = motion.K, damping(motion.K)
        n_ramp = ramp_steps(self.model.fk(q0), motion.G_d, s)
        n_max = math.ceil(motion.timeout_s / s.timestep_s - 1e-9)
        n_window = math.ceil(s.settle_window_s / s.timestep_s)
        eye6, eye7 = np.eye(6), np.eye(7)
        still = 0
        for k in range(n_max):
            q, dq = self.read()
            J, g = self.model.jacobian_and_gravity(q)
            q_ref = q0 + min(1.0, (k + 1) / n_ramp) * (q_d - q0)
            error = q_ref - q
            wrench = clip_norm(K @ (J @ error), s.spring_limit) - B @ (J @ dq)
            null = eye7 - J.T @ np.linalg.solve(J @ J.T + 1e-6 * eye6, J)
            tau = J.T @ wrench + g + null @ (s.null_stiffness * error - s.null_damping * dq)
            tau = np.clip(tau, -TORQUE_LIMITS, TORQUE_LIMITS)
            p.setJointMotorControlArray(
                self.robot, self.joints, p.TORQUE_CONTROL, forces=tau, physicsClientId=self.client
            )
            p.stepSimulation(physicsClientId=self.client)
            if s.early_stop and k + 1 >= n_ramp:
                still = still + 1 if np.abs(dq).max() < s.settle_joint_speed else 0
                if still >= n_window:
                    return k + 1, True
        return n_max, False

    def _result(
        self, X_WO: pin.SE3, q_d: np.ndarray, sim_time: float, settled: bool, reachable: bool
    ) -> RolloutResult:
        q, dq = self.read()
        X_WM, V_WM = self.part_pose()
        contacts = label_final_contacts(
            self.env,
            self.task.manipuland,
            X_WO,
            X_WM,
            self.robot,
            self.part_link,
            self.settings.contact_distance_m,
        )
        state = ParticleState(X_WM=X_WM, q=q, dq=dq, V_WM=V_WM)
        return RolloutResult(state, contacts, np.asarray(q_d), sim_time, settled, reachable)
