"""The Panda model of one grasp: τ = K_q(q_d − q) − B_q q̇ + g(q) + null-space posture.

``K_q = Jᵀ K J`` and ``B_q = Jᵀ B J`` with ``B = 2√K``; J (hand, world axes, rotation
first) and g(q) come from Pinocchio on the same URDF, including the part's mass. The joint
setpoint ``q_d`` (IK of ``G_d``) is approached along a straight joint-space ramp.
"""

import math
import shutil
import time
from dataclasses import dataclass, replace
from operator import itemgetter

import numpy as np
import pinocchio as pin
import pybullet as p

from bilba_dist.errors import UnreachableError
from bilba_dist.robot.drivers import planning_arms
from bilba_dist.robot.panda import ARM_JOINTS, TORQUE_LIMITS, PandaModel
from bilba_dist.rollout import Motion, ParticleState, RolloutResult
from bilba_dist.task.loader import Task
from bilba_dist.workers.control_step import joint_torque
from bilba_dist.workers.motion import (
    SimStats,
    blend_steps,
    damping,
    label_final_contacts,
    ramp_fractions,
    ramp_poses,
    ramp_steps,
)
from bilba_dist.workers.scene import EnvironmentBodies, OwnsClient, connect, paced
from bilba_dist.workers.settings import SimSettings
from bilba_dist.workers.urdf import PART_LINK, panda_with_part


@dataclass(frozen=True)
class JointImpedance:
    """The motion's Cartesian impedance as constant joint-space gains, linearised once per
    motion at the joint setpoint: ``K_q = Jᵀ K J + k_n N``, ``B_q = Jᵀ B J + d_n N`` with
    ``N`` the null-space projector of J there (the posture term: the redundant arm does not
    drift). The spring wrench ``K J (q_ref − q)`` is clipped in norm before mapping back.

    Per step one 13×14 product of ``[[−K J, 0], [−K_q, −B_q]]`` with ``[q; q̇]``, plus the
    reference's share ``[K J; K_q] q_ref`` computed for the whole ramp at once, gives both
    the wrench (to test the clip) and the torque."""

    state_gains: np.ndarray  # [[-K J, 0], [-K_q, -B_q]] acting on [q; q̇], 13×14
    ref_gains: np.ndarray  # [K J; K_q] acting on q_ref, 13×7
    Jt: np.ndarray  # Jᵀ, 7×6 (past the spring limit: the wrench's share to take off)
    limit: float

    @classmethod
    def at(
        cls, model: PandaModel, q_d: np.ndarray, K: np.ndarray, s: SimSettings
    ) -> "JointImpedance":
        J, _ = model.jacobian_and_gravity(q_d)
        N = np.eye(7) - J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(6), J)
        KJ, K_null = K @ J, s.null_stiffness * N
        B_q = J.T @ damping(K) @ J + s.null_damping * N
        ref_gains = np.vstack([KJ, J.T @ KJ + K_null])
        state_gains = np.hstack([-ref_gains, np.vstack([np.zeros((6, 7)), -B_q])])
        return cls(state_gains, ref_gains, J.T.copy(), s.spring_limit)


class PandaSim(OwnsClient):
    """A PyBullet world with the Panda holding the part at one grasp ``X_GM``."""

    def __init__(self, task: Task, X_GM: pin.SE3, settings: SimSettings) -> None:
        self.task, self.X_GM, self.settings = task, X_GM, settings
        self.client = connect(settings.timestep_s, -9.81, settings.gui)
        mass = task.spec.manipuland.mass
        arms = planning_arms(task.spec.planner.driver)
        self.model = PandaModel(mass, X_GM, task.manipuland.centre(), arms)
        limits = (self.model.lower, self.model.upper)  # the simulated arm stops where the IK does
        urdf = panda_with_part(task.manipuland, X_GM, mass, limits=limits)
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
        self.clean = p.saveState(physicsClientId=self.client)
        self.stats = SimStats()
        info = p.getDynamicsInfo(self.robot, self.part_link, physicsClientId=self.client)
        self.inertia = tuple(info[2])  # the part's local inertia diagonal, from the URDF
        self.physics = (1.0, 1.0)  # friction and mass factors in force

    def _set_physics(self, friction: float, mass: float) -> None:
        """The particle's friction and mass factors. The part's inertia is scaled with its
        mass explicitly: given a mass alone, PyBullet recomputes a link's inertia from its
        collision shape, which changed every rollout's dynamics (and the puzzle's plans)."""
        self.env.set_friction(self.task.spec.friction * friction)
        p.changeDynamics(
            self.robot,
            self.part_link,
            mass=self.task.spec.manipuland.mass * mass,
            localInertiaDiagonal=(np.array(self.inertia) * mass).tolist(),
            physicsClientId=self.client,
        )
        self.physics = (friction, mass)

    def reset(
        self, X_WO: pin.SE3, q: np.ndarray, dq: np.ndarray, physics: tuple[float, float]
    ) -> None:
        """Put the world in a known state: no history carries over between rollouts.
        ``physics``: the particle's friction and mass scale factors, set when they change (the
        controller's model keeps the nominal payload: the robot does not know the mass)."""
        p.restoreState(self.clean, physicsClientId=self.client)
        if physics != self.physics:  # dynamics parameters outlive restoreState
            self._set_physics(*physics)
        self.env.forget_contacts()
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

    def rollout(
        self,
        X_WO: pin.SE3,
        start: ParticleState,
        motion: Motion,
        physics: tuple[float, float] = (1.0, 1.0),
    ) -> RolloutResult:
        if start.stopped:  # its arm stopped with a reflex: nothing moves any more
            return RolloutResult(start, frozenset(), start.q, 0.0, True)
        self.reset(X_WO, start.q, start.dq, physics)
        try:
            q_d = self.model.ik(motion.G_d, start.q)
        except UnreachableError:
            return self._result(X_WO, start.q, 0.0, settled=False, reachable=False)
        steps, settled, peaks = self._run(start.q, q_d, motion)
        result = self._result(X_WO, q_d, steps * self.settings.timestep_s, settled, True)
        result = replace(result, peak_wrench=peaks[:6], peak_joint_torque=peaks[6:13])
        stop = self._limit_reached(peaks[13:20], peaks[20:27])
        if stop is None:
            return result
        return replace(result, state=replace(result.state, stopped=stop), contacts=frozenset())

    def _limit_reached(self, low: np.ndarray, high: np.ndarray) -> str | None:
        """Why the real arm would have stopped: a joint that came within LIMIT_MARGIN_RAD of
        its limit (a Franka halts there with a joint-position-limit reflex; the simulated
        arm would rest on the stop and go on). None when every joint kept clear."""
        hit = self.model.limit_reached(low, high)
        if hit is None:
            return None
        joint, side, limit = hit
        return f"joint {joint} reached its {side} limit ({limit:.4f} rad)"

    def _run(self, q0: np.ndarray, q_d: np.ndarray, motion: Motion) -> tuple[int, bool, np.ndarray]:
        """Step the controller until the motion has settled or timed out. Also returns the
        spring's peak wrench per axis and its peak torque per joint (`joint_torque`).

        Our per-step Python rivals the physics step, so the loop makes four calls a step —
        read the joints, gravity (Pinocchio), the compiled torque and settle test, send the
        torques — into preallocated arrays (issue 3's overhead figure; benchmarks/rollouts.py)."""
        s, client, robot, joints = self.settings, self.client, self.robot, self.joints
        gains = JointImpedance.at(self.model, q_d, motion.K, s)
        n_ramp = ramp_steps(self.model.fk(q0), motion.G_d, s)
        ramp = self._ramp(q0, q_d, motion.G_d, n_ramp)
        n_ramp = len(ramp)  # longer by the blend where the driver eases the ramp
        feed = ramp @ gains.ref_gains.T  # the reference's share of [wrench; τ], per step
        n_max = math.ceil(motion.timeout_s / s.timestep_s - 1e-9)
        n_window = math.ceil(s.settle_window_s / s.timestep_s)
        model, data, gravity = self.model.model, self.model.data, pin.computeGeneralizedGravity
        read, command = p.getJointStates, p.setJointMotorControlArray
        torque_control, step, timer = p.TORQUE_CONTROL, p.stepSimulation, time.perf_counter
        if s.gui:
            step = paced(step, s.timestep_s)
        G, Jt = gains.state_gains, gains.Jt
        limit, last, tau_max = gains.limit, n_ramp - 1, TORQUE_LIMITS
        still, physics, calm, watch = 0, 0.0, s.settle_joint_speed, s.early_stop
        x, tau = np.empty(14), np.zeros(34)  # x = [q; q̇]; tau: torque, then the peaks
        tau[20:27], tau[27:] = np.inf, -np.inf  # and each joint's range (`joint_torque`)
        out = tau[:7]
        q, position, speed, unused = x[:7], itemgetter(0), itemgetter(1), [0.0] * 7
        # Every argument passed by position (physicsClientId last, the position-control
        # fields as zeros that torque control ignores): PyBullet's keyword parsing costs
        # 0.3-2 µs a call
        for k in range(n_max):
            states = read(robot, joints, client)
            x[:] = [*map(position, states), *map(speed, states)]
            i = k if k < last else last
            still_now = joint_torque(
                G, feed, i, x, Jt, limit, gravity(model, data, q), tau_max, tau, calm
            )
            command(
                robot, joints, torque_control, unused, unused, out.tolist(), unused, unused, client
            )
            t0 = timer()
            step(client)
            physics += timer() - t0
            if watch and k >= last:
                if still_now:
                    still += 1
                    if still >= n_window:
                        self.stats.add(k + 1, physics)
                        return k + 1, True, tau[7:].copy()
                else:
                    still = 0
        self.stats.add(n_max, physics)
        return n_max, False, tau[7:].copy()

    def _ramp(self, q0: np.ndarray, q_d: np.ndarray, G_d: pin.SE3, n: int) -> np.ndarray:
        """The joint reference at each ramp step, ending at ``q_d``: piecewise linear
        through knots spaced evenly along the ramp, ``n`` steps at the ramp's speed (plus
        ``blend_steps`` where the driver eases it in and out: `ramp_fractions`).

        The knots are just ``q0`` and ``q_d`` (a straight line in joint space) by default.
        With ``cartesian_ramp`` they add IK waypoints every ``ramp_waypoint_steps`` steps
        along the hand's SE(3) geodesic (as the floating model's setpoint moves): a straight
        joint ramp bows the hand ~2 mm off the line on an 8 cm descent, more than the
        puzzle's clearance."""
        knots = [q0]
        segments = math.ceil(n / self.settings.ramp_waypoint_steps)
        if self.settings.cartesian_ramp and segments >= 2:
            rotations, positions = ramp_poses(self.model.fk(q0), G_d, segments)
            try:
                for R, p_ in zip(rotations[:-1], positions[:-1], strict=True):
                    knots.append(self.model.ik(pin.SE3(R, p_), knots[-1]))
            except UnreachableError:  # a waypoint out of reach: the joint line after all
                knots = [q0]
        path = np.array([*knots, q_d])
        t = ramp_fractions(n, blend_steps(self.settings)) * (len(path) - 1)
        j = np.minimum(t.astype(int), len(path) - 2)
        return path[j] + (t - j)[:, None] * (path[j + 1] - path[j])

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
        touches = self.env.touching(self.robot, self.part_link, self.settings.contact_distance_m)
        state = ParticleState(X_WM=X_WM, q=q, dq=dq, V_WM=V_WM, arm_touches=touches)
        return RolloutResult(state, contacts, np.asarray(q_d), sim_time, settled, reachable)
