"""The Panda in the log's scene: each collision body of pybullet_data's Panda as a small convex
triangle list, placed per particle from that particle's joint angles.

The shapes are the hulls of the URDF's collision meshes, cut down to at most
``MAX_VERTICES`` vertices each (farthest-point sampling, deterministic) so that a scene with
every particle's arm stays a few tens of kB; they show where the arm is, not its exact surface.
The fingers sit where they close on the part, where the rollout model fixes them
(``finger_opening``).
"""

import os
from functools import cache

import numpy as np
import pinocchio as pin
import trimesh

from bilba_dist.robot.panda import panda_urdf

#: Vertices kept of each body's hull.
MAX_VERTICES = 32


def _farthest_points(points: np.ndarray, k: int) -> np.ndarray:
    """``k`` of ``points``, each the farthest from those already chosen (starting from the
    farthest from the centroid): a spread-out subset, the same every time."""
    if len(points) <= k:
        return points
    chosen = [int(np.argmax(np.linalg.norm(points - points.mean(axis=0), axis=1)))]
    distance = np.linalg.norm(points - points[chosen[0]], axis=1)
    while len(chosen) < k:
        chosen.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return points[chosen]


class PandaBodies:
    """Forward kinematics of the Panda's collision bodies, and their shapes."""

    def __init__(self) -> None:
        urdf = panda_urdf()
        self.model = pin.buildModelFromUrdf(urdf)
        self.data = self.model.createData()
        self.geometry = pin.buildGeomFromUrdf(
            self.model, urdf, pin.GeometryType.COLLISION, package_dirs=[os.path.dirname(urdf)]
        )
        self.geometry_data = pin.GeometryData(self.geometry)
        #: Frame name (relative to the particle) of each body, e.g. ``link3``.
        self.names = [
            g.name.removeprefix("panda_").removesuffix("_0") for g in self.geometry.geometryObjects
        ]

    def shapes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Each body's (vertices [m], triangle indices), in the body's own frame."""
        shapes = []
        for g in self.geometry.geometryObjects:
            mesh: trimesh.Trimesh = trimesh.load(g.meshPath, force="mesh")  # type: ignore[assignment]
            hull_points = mesh.convex_hull.vertices * np.asarray(g.meshScale)
            hull = trimesh.convex.convex_hull(_farthest_points(hull_points, MAX_VERTICES))
            shapes.append((np.asarray(hull.vertices), np.asarray(hull.faces)))
        return shapes

    def poses(self, q_arm: np.ndarray, opening: float = 0.0) -> list[pin.SE3]:
        """Each body's pose in the world (the robot base) at the seven arm joint angles, each
        finger ``opening`` [m] from the centre."""
        q = pin.neutral(self.model)
        q[:7] = q_arm
        q[7:9] = opening  # the two finger joints
        pin.forwardKinematics(self.model, self.data, q)
        pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.geometry_data)
        return [pin.SE3(X) for X in self.geometry_data.oMg]


@cache
def panda_bodies() -> PandaBodies:
    return PandaBodies()


@cache
def panda_shapes() -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    return tuple(panda_bodies().shapes())
