"""The floating model: the manipuland as a free body, pulled by the same 6-D spring–damper
that the Panda's controller applies at the gripper, with gravity compensated exactly.

It has a virtual inertia near the Panda's effective one (its real 1e-4 kg·m² with rotational
damping blows up under explicit integration: docs/physics.md). Faster than the Panda model;
plans made with it must be validated on the Panda model before they are returned.
"""

import math
import tempfile
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet as p

from bilba_dist.geometry.piece import Part
from bilba_dist.rollout import Motion, ParticleState, RolloutResult
from bilba_dist.task.loader import Task
from bilba_dist.workers.motion import (
    SimStats,
    blend_steps,
    damping,
    label_final_contacts,
    ramp_fractions,
    ramp_poses,
    ramp_steps,
)
from bilba_dist.workers.scene import EnvironmentBodies, OwnsClient, connect, quat_xyzw
from bilba_dist.workers.settings import SimSettings
from bilba_dist.workers.urdf import write_obj


def part_compound(part: Part, client: int) -> int:
    """One collision shape of all the part's pieces, in the part frame (boxes exact)."""
    kinds, halves, files, positions, orientations = [], [], [], [], []
    with tempfile.TemporaryDirectory(prefix="bilba_part_") as folder:
        for piece in part.pieces:
            X = piece.X_PB if piece.X_PB is not None else pin.SE3.Identity()
            if piece.box_size is not None:
                kinds.append(p.GEOM_BOX)
                halves.append((piece.box_size / 2).tolist())
                files.append("")
            else:
                path = Path(folder) / f"{piece.name}.obj"
                write_obj(piece, path)
                kinds.append(p.GEOM_MESH)
                halves.append([0.0, 0.0, 0.0])
                files.append(str(path))
            positions.append(X.translation.tolist())
            orientations.append(quat_xyzw(X.rotation))
        return p.createCollisionShapeArray(
            kinds,
            halfExtents=halves,
            fileNames=files,
            collisionFramePositions=positions,
            collisionFrameOrientations=orientations,
            physicsClientId=client,
        )


class FloatingSim(OwnsClient):
    """A PyBullet world with the environment and the manipuland as one free body."""

    def __init__(self, task: Task, settings: SimSettings) -> None:
        self.task, self.settings = task, settings
        self.client = connect(settings.timestep_s, 0.0, settings.gui)
        compound = part_compound(task.manipuland, self.client)
        self.body = p.createMultiBody(
            settings.virtual_mass_kg, compound, -1, physicsClientId=self.client
        )
        inertia = [settings.virtual_inertia_kg_m2] * 3
        p.changeDynamics(
            self.body,
            -1,
            lateralFriction=1.0,
            collisionMargin=0.0,
            localInertiaDiagonal=inertia,
            linearDamping=0.0,
            angularDamping=0.0,
            physicsClientId=self.client,
        )
        self.env = EnvironmentBodies.create(task.environment, task.spec.friction, self.client)
        self.clean = p.saveState(physicsClientId=self.client)
        self.stats = SimStats()
        self.friction = 1.0  # the friction factor in force

    def reset(self, X_WO: pin.SE3, X_WM: pin.SE3, V_WM: np.ndarray, friction: float = 1.0) -> None:
        """``friction``: the particle's scale factor (the floating model's mass is the
        hand's virtual mass, so a mass axis does not act on it)."""
        p.restoreState(self.clean, physicsClientId=self.client)
        if friction != self.friction:  # dynamics parameters outlive restoreState
            self.env.set_friction(self.task.spec.friction * friction)
            self.friction = friction
        self.env.forget_contacts()
        self.env.place(X_WO)
        p.resetBasePositionAndOrientation(
            self.body,
            X_WM.translation.tolist(),
            quat_xyzw(X_WM.rotation),
            physicsClientId=self.client,
        )
        p.resetBaseVelocity(
            self.body, V_WM[3:].tolist(), V_WM[:3].tolist(), physicsClientId=self.client
        )

    def read(self) -> tuple[pin.SE3, np.ndarray]:
        position, orientation = p.getBasePositionAndOrientation(
            self.body, physicsClientId=self.client
        )
        linear, angular = p.getBaseVelocity(self.body, physicsClientId=self.client)
        X_WM = pin.XYZQUATToSE3(np.array([*position, *orientation]))
        return X_WM, np.array([*angular, *linear])

    def rollout(
        self,
        X_WO: pin.SE3,
        X_GM: pin.SE3,
        start: ParticleState,
        motion: Motion,
        friction: float = 1.0,
    ) -> RolloutResult:
        self.reset(X_WO, start.X_WM, start.V_WM, friction)
        steps, settled = self._run(X_GM, start.X_WM * X_GM.inverse(), motion)
        X_WM, V_WM = self.read()
        contacts = label_final_contacts(
            self.env,
            self.task.manipuland,
            X_WO,
            X_WM,
            self.body,
            -1,
            self.settings.contact_distance_m,
        )
        state = ParticleState(X_WM=X_WM, V_WM=V_WM, q=start.q)
        return RolloutResult(state, contacts, start.q, steps * self.settings.timestep_s, settled)

    def _run(self, X_GM: pin.SE3, X_WG0: pin.SE3, motion: Motion) -> tuple[int, bool]:
        s, body, client = self.settings, self.body, self.client
        K, B = motion.K, damping(motion.K)
        p_MG, R_MG = X_GM.inverse().translation, X_GM.inverse().rotation
        fractions = ramp_fractions(ramp_steps(X_WG0, motion.G_d, s), blend_steps(s))
        n_ramp = len(fractions)
        ramp_R, ramp_p = ramp_poses(X_WG0, motion.G_d, n_ramp, fractions)
        n_max = math.ceil(motion.timeout_s / s.timestep_s - 1e-9)
        n_window = math.ceil(s.settle_window_s / s.timestep_s)
        world, step, timer, log3 = p.WORLD_FRAME, p.stepSimulation, time.perf_counter, pin.log3
        pose, twist, matrix = (
            p.getBasePositionAndOrientation,
            p.getBaseVelocity,
            p.getMatrixFromQuaternion,
        )
        force, torque = p.applyExternalForce, p.applyExternalTorque
        still, physics, limit = 0, 0.0, s.spring_limit
        error, velocity, R_WM = np.empty(6), np.empty(6), np.empty((3, 3))
        flat_R = R_WM.reshape(9)  # a view: R_WM is filled in place
        # physicsClientId passed by position: PyBullet's keyword parsing costs ~2 µs a call
        for k in range(n_max):
            position, orientation = pose(body, client)
            linear, angular = twist(body, client)
            flat_R[:] = matrix(orientation)
            r = R_WM @ p_MG  # from the part's origin to the gripper point, world
            p_G = r + position
            i = k if k < n_ramp else n_ramp - 1
            error[:3] = log3(ramp_R[i] @ (R_WM @ R_MG).T)
            error[3:] = ramp_p[i] - p_G
            velocity[:3] = angular
            wx, wy, wz = angular
            rx, ry, rz = r
            velocity[3] = linear[0] + wy * rz - wz * ry  # v + ω × r, without np.cross's cost
            velocity[4] = linear[1] + wz * rx - wx * rz
            velocity[5] = linear[2] + wx * ry - wy * rx
            spring = K @ error
            norm = math.sqrt(spring @ spring)
            if norm > limit:
                spring *= limit / norm
            wrench = spring - B @ velocity
            forces = wrench.tolist()  # pybullet reads lists ~2.5× faster than arrays
            force(body, -1, forces[3:], p_G.tolist(), world, client)
            torque(body, -1, forces[:3], world, client)
            t0 = timer()
            step(client)
            physics += timer() - t0
            if s.early_stop and k + 1 >= n_ramp:
                calm = (
                    linear[0] ** 2 + linear[1] ** 2 + linear[2] ** 2 < s.settle_speed_m_s**2
                    and angular[0] ** 2 + angular[1] ** 2 + angular[2] ** 2
                    < s.settle_speed_rad_s**2
                )
                still = still + 1 if calm else 0
                if still >= n_window:
                    self.stats.add(k + 1, physics)
                    return k + 1, True
        self.stats.add(n_max, physics)
        return n_max, False
