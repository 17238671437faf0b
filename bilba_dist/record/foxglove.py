"""The belief as a 3-D scene in Foxglove's well-known JSON schemas.

One frame per particle and part: ``env_i`` (the environment at particle ``i``'s ``X_WO``),
``part_i`` (its manipuland at ``X_WM``) and, on the Panda model, ``panda_i/BODY`` for each of
the arm's collision bodies (from the particle's joint angles), all children of ``world`` by
``foxglove.FrameTransform`` on ``/tf``. ``/scene`` (``foxglove.SceneUpdate``) draws each as a
triangle list locked to its frame, so the transforms alone animate the scene. Foxglove
recognises a JSON channel by its schema *name*; the log carries the official schemas, and every
message is valid under them (tests/test_logs.py).
"""

import json
from collections.abc import Sequence
from importlib.resources import files
from typing import Any

import numpy as np
import pinocchio as pin

from bilba_dist.geometry.piece import Part
from bilba_dist.record.panda_scene import panda_bodies, panda_shapes
from bilba_dist.robot.gripper import finger_opening


def _official(name: str) -> dict[str, Any]:
    return json.loads(
        (files("bilba_dist.record") / "foxglove_schemas" / f"{name}.json").read_text()
    )


#: The official JSON schemas (foxglove-sdk's `@foxglove/schemas`, see the folder's README),
#: written into each log as the channel's schema.
SCHEMAS: dict[str, dict[str, Any]] = {
    "/scene": _official("SceneUpdate"),
    "/tf": _official("FrameTransform"),
}

#: SceneEntity's primitive lists: every one is required, empty or not.
PRIMITIVES = ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models")

WORLD = "world"
#: Manipuland colours, cycled over particles; the environment is grey.
PALETTE = [(0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.17, 0.63, 0.17), (0.84, 0.15, 0.16)]
ENV_COLOR = (0.6, 0.6, 0.6)
ROBOT_COLOR = (0.85, 0.85, 0.88)


def stamp(ns: int) -> dict[str, int]:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _xyz(v: np.ndarray) -> dict[str, float]:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _rgba(rgb: Sequence[float], a: float) -> dict[str, float]:
    return {"r": rgb[0], "g": rgb[1], "b": rgb[2], "a": a}


def triangles(part: Part) -> tuple[list[dict[str, float]], list[int]]:
    """A part's surface as points and triangle indices (each convex face fanned out)."""
    points: list[dict[str, float]] = []
    indices: list[int] = []
    for piece in part.pieces:
        base = len(points)
        points.extend(_xyz(v) for v in piece.vertices)
        for face in piece.faces:
            v = face.vertices
            for k in range(1, len(v) - 1):
                indices.extend((base + v[0], base + v[k], base + v[k + 1]))
    return points, indices


IDENTITY = {
    "position": {"x": 0.0, "y": 0.0, "z": 0.0},
    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
}


def entity(frame: str, ns: int, points: list[dict[str, float]], indices: list[int],
           color: dict[str, float]) -> dict[str, Any]:  # fmt: skip
    """A SceneEntity: one triangle list locked to ``frame`` (the entity's id too)."""
    return {
        "timestamp": stamp(ns),
        "frame_id": frame,
        "id": frame,
        "lifetime": stamp(0),
        "frame_locked": True,
        "metadata": [],
        **{kind: [] for kind in PRIMITIVES},
        "triangles": [
            {"pose": IDENTITY, "points": points, "color": color, "colors": [], "indices": indices}
        ],
    }


class SceneMessages:
    """Builds ``/scene`` and ``/tf`` messages for one task's two parts (and the Panda)."""

    def __init__(self, manipuland: Part, environment: Part, robot: bool = True) -> None:
        self._meshes = {"part": triangles(manipuland), "env": triangles(environment)}
        self._manipuland = manipuland
        self._openings: dict[bytes, float] = {}  # finger opening per grasp
        self._robot = (
            [
                (name, [_xyz(np.round(v, 4)) for v in vertices], [int(i) for i in faces.ravel()])
                for name, (vertices, faces) in zip(
                    panda_bodies().names, panda_shapes(), strict=True
                )
            ]
            if robot
            else []
        )

    def scene(self, n_particles: int, ns: int) -> dict[str, Any]:
        entities = []
        for i in range(n_particles):
            for kind, rgb, alpha in (
                ("env", ENV_COLOR, 0.35),
                ("part", PALETTE[i % len(PALETTE)], 0.8),
            ):
                points, indices = self._meshes[kind]
                entities.append(entity(f"{kind}_{i}", ns, points, indices, _rgba(rgb, alpha)))
            for name, points, indices in self._robot:
                entities.append(
                    entity(f"panda_{i}/{name}", ns, points, indices, _rgba(ROBOT_COLOR, 0.3))
                )
        return {"deletions": [], "entities": entities}

    def robot_transforms(
        self, i: int, q: np.ndarray, ns: int, X_GM: pin.SE3
    ) -> list[dict[str, Any]]:
        """Particle ``i``'s arm bodies at joint angles ``q``, its fingers where they close on
        the part held at ``X_GM`` (none without the robot)."""
        if not self._robot:
            return []
        key = X_GM.homogeneous.tobytes()
        if key not in self._openings:
            self._openings[key] = finger_opening(self._manipuland, X_GM)
        bodies = panda_bodies()
        return [
            self.transform(f"panda_{i}/{name}", X, ns)
            for name, X in zip(bodies.names, bodies.poses(q, self._openings[key]), strict=True)
        ]

    @staticmethod
    def transform(child: str, X: pin.SE3, ns: int) -> dict[str, Any]:
        q = pin.Quaternion(X.rotation)
        return {
            "timestamp": stamp(ns),
            "parent_frame_id": WORLD,
            "child_frame_id": child,
            "translation": _xyz(X.translation),
            "rotation": {"x": q.x, "y": q.y, "z": q.z, "w": q.w},
        }
