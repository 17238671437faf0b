"""One PyBullet world: the environment's pieces as static bodies, and either the Panda holding
the manipuland or the manipuland floating free.

Each environment piece is its own body so its collision margin can be zeroed (the margin acts
on a body's base only): a 5 mm clearance then really is 5 mm. Friction: the environment
carries the task's μ and everything else 1, since PyBullet multiplies the two.
"""

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import pybullet as p

from bilba_dist.errors import BilbaError
from bilba_dist.geometry.piece import ConvexPiece, Part

FAR = pin.SE3(np.eye(3), np.array([100.0, 100.0, 100.0]))  # out of every AABB of a world


_viewer: list[int] = []  # the process's one GUI client, once opened


def connect(timestep_s: float, gravity: float, gui: bool = False) -> int:
    """A new DIRECT client with the given step (with ``gui``, the viewer, if this process has
    none open yet: PyBullet allows one); always pass its id on."""
    gui = gui and not _viewer
    client = p.connect(p.GUI if gui else p.DIRECT)
    if client < 0:
        raise BilbaError("cannot open the PyBullet viewer (no display?)")
    if gui:
        _viewer.append(client)
    p.setTimeStep(timestep_s, physicsClientId=client)
    p.setGravity(0, 0, gravity, physicsClientId=client)
    p.setPhysicsEngineParameter(deterministicOverlappingPairs=1, physicsClientId=client)
    return client


class OwnsClient:
    """A world's own PyBullet connection (``self.client``, from `connect`), closed once: by
    ``close()``, or when the world is dropped without it. A dropped world used to keep its
    connection (~33 MB) until the process ended: a benchmark that made a RolloutWorker per
    plan and never closed it grew to 12 GB a process once verification gave each plan 14
    more grasps (benchmarks/HISTORY.md, twenty-eighth session)."""

    client: int = -1

    def close(self) -> None:
        if self.client >= 0:  # PyBullet reuses ids: never disconnect a stale one
            p.disconnect(physicsClientId=self.client)
            self.client = -1

    def __del__(self) -> None:
        try:  # noqa: SIM105 (at interpreter exit, contextlib may be torn down first)
            self.close()
        except Exception:  # ... and pybullet with it
            pass


def paced(step: Callable[[int], object], timestep_s: float) -> Callable[[int], None]:
    """``step`` slowed to real time (for the viewer: unpaced, a 5 s motion flashes by in a
    tenth of a second)."""
    clock = [time.perf_counter()]

    def step_in_real_time(client: int) -> None:
        step(client)
        clock[0] += timestep_s
        time.sleep(max(0.0, clock[0] - time.perf_counter()))

    return step_in_real_time


def quat_xyzw(R: np.ndarray) -> list[float]:
    return list(pin.Quaternion(np.asarray(R)).coeffs())  # x, y, z, w


def piece_shape(piece: ConvexPiece, client: int) -> tuple[int, pin.SE3]:
    """A collision shape for ``piece`` and the pose of its frame in the part frame."""
    if piece.box_size is not None and piece.X_PB is not None:
        shape = p.createCollisionShape(
            p.GEOM_BOX, halfExtents=list(piece.box_size / 2), physicsClientId=client
        )
        return shape, piece.X_PB
    shape = p.createCollisionShape(
        p.GEOM_MESH, vertices=piece.vertices.tolist(), physicsClientId=client
    )
    return shape, pin.SE3.Identity()


@dataclass
class EnvironmentBodies:
    """The environment's static bodies; `place` moves them all to a new ``X_WO``."""

    client: int
    part: Part
    bodies: list[int]
    offsets: list[pin.SE3]  # each piece body's frame in the part frame

    @classmethod
    def create(cls, part: Part, friction: float, client: int) -> "EnvironmentBodies":
        bodies, offsets = [], []
        for piece in part.pieces:
            shape, X_OP = piece_shape(piece, client)
            body = p.createMultiBody(0.0, shape, -1, physicsClientId=client)
            p.changeDynamics(
                body, -1, lateralFriction=friction, collisionMargin=0.0, physicsClientId=client
            )
            bodies.append(body)
            offsets.append(X_OP)
        return cls(client, part, bodies, offsets)

    def set_friction(self, friction: float) -> None:
        for body in self.bodies:
            p.changeDynamics(body, -1, lateralFriction=friction, physicsClientId=self.client)

    def forget_contacts(self) -> None:
        """Drop every contact the world remembers: with the environment far away, collision
        detection removes the broadphase pairs and their contact manifolds. restoreState
        leaves them, so what they held (warm-start impulses, we take it) carried one
        rollout's end into the next rollout of that world (4e-7 rad apart after a puzzle
        rollout that starts resting on a bar), and a seeded plan differed in-process and
        on Ray."""
        self.place(FAR)
        p.performCollisionDetection(physicsClientId=self.client)

    def place(self, X_WO: pin.SE3) -> None:
        for body, X_OP in zip(self.bodies, self.offsets, strict=True):
            X_WP = X_WO * X_OP
            p.resetBasePositionAndOrientation(
                body,
                X_WP.translation.tolist(),
                quat_xyzw(X_WP.rotation),
                physicsClientId=self.client,
            )

    def contact_points(
        self, body: int, link: int, distance: float
    ) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
        """(piece index, point on env [world], point on body [world], normal env→body) for
        every pair of points within ``distance`` [m] of the environment."""
        found = []
        for i, env_body in enumerate(self.bodies):
            for c in p.getClosestPoints(
                env_body, body, distance, linkIndexB=link, physicsClientId=self.client
            ):
                # c[5]: on A (env), c[6]: on B, c[7]: normal from B to A
                found.append((i, np.array(c[5]), np.array(c[6]), -np.array(c[7])))
        return found

    def touching(self, robot: int, part_link: int, distance: float) -> tuple[str, ...]:
        """The names of the pieces that a link of ``robot`` other than ``part_link`` (the arm,
        the hand, the fingers) comes within ``distance`` [m] of."""
        return tuple(
            piece.name
            for piece, env_body in zip(self.part.pieces, self.bodies, strict=True)
            if any(
                c[4] != part_link
                for c in p.getClosestPoints(env_body, robot, distance, physicsClientId=self.client)
            )
        )
