"""The belief as a 3-D scene in Foxglove's well-known JSON schemas.

One frame per particle and part: ``env_i`` (the environment at particle ``i``'s ``X_WO``) and
``part_i`` (its manipuland at ``X_WM``), both children of ``world`` by ``foxglove.FrameTransform``
on ``/tf``. ``/scene`` (``foxglove.SceneUpdate``) draws each part as a triangle list locked to
its frame, so the transforms alone animate the scene. Foxglove recognises a JSON channel by
its schema *name*; the schemas below are the subset of the official ones we fill (same field
names and types, so a message valid here is valid there).
"""

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from bilba_dist.geometry.piece import Part


def _numbers(keys: str) -> dict[str, Any]:
    """An object of required numbers, one per letter of ``keys`` (vector, quaternion, colour)."""
    return {
        "type": "object",
        "properties": {k: {"type": "number"} for k in keys},
        "required": list(keys),
    }


_VEC3 = _numbers("xyz")
_QUAT = _numbers("xyzw")
_TIME = {
    "type": "object",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
    "required": ["sec", "nsec"],
}
_COLOR = _numbers("rgba")
_POSE = {
    "type": "object",
    "properties": {"position": _VEC3, "orientation": _QUAT},
    "required": ["position", "orientation"],
}
_TRIANGLES = {
    "type": "object",
    "properties": {
        "pose": _POSE,
        "points": {"type": "array", "items": _VEC3},
        "color": _COLOR,
        "colors": {"type": "array", "items": _COLOR},
        "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}},
    },
    "required": ["pose", "points", "color", "colors", "indices"],
}
_ENTITY = {
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "id": {"type": "string"},
        "lifetime": _TIME,
        "frame_locked": {"type": "boolean"},
        "metadata": {"type": "array"},
        "triangles": {"type": "array", "items": _TRIANGLES},
    },
    "required": ["timestamp", "frame_id", "id", "lifetime", "frame_locked", "triangles"],
}

SCHEMAS: dict[str, dict[str, Any]] = {
    "/scene": {
        "title": "foxglove.SceneUpdate",
        "type": "object",
        "properties": {
            "deletions": {"type": "array"},
            "entities": {"type": "array", "items": _ENTITY},
        },
        "required": ["deletions", "entities"],
    },
    "/tf": {
        "title": "foxglove.FrameTransform",
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "parent_frame_id": {"type": "string"},
            "child_frame_id": {"type": "string"},
            "translation": _VEC3,
            "rotation": _QUAT,
        },
        "required": ["timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"],
    },
}

WORLD = "world"
#: Manipuland colours, cycled over particles; the environment is grey.
PALETTE = [(0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.17, 0.63, 0.17), (0.84, 0.15, 0.16)]
ENV_COLOR = (0.6, 0.6, 0.6)


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


class SceneMessages:
    """Builds ``/scene`` and ``/tf`` messages for one task's two parts."""

    def __init__(self, manipuland: Part, environment: Part) -> None:
        self._meshes = {"part": triangles(manipuland), "env": triangles(environment)}

    def scene(self, n_particles: int, ns: int) -> dict[str, Any]:
        entities = []
        for i in range(n_particles):
            for kind, rgb, alpha in (
                ("env", ENV_COLOR, 0.35),
                ("part", PALETTE[i % len(PALETTE)], 0.8),
            ):
                points, indices = self._meshes[kind]
                entities.append(
                    {
                        "timestamp": stamp(ns),
                        "frame_id": f"{kind}_{i}",
                        "id": f"{kind}/{i}",
                        "lifetime": stamp(0),
                        "frame_locked": True,
                        "metadata": [],
                        "triangles": [
                            {
                                "pose": IDENTITY,
                                "points": points,
                                "color": _rgba(rgb, alpha),
                                "colors": [],
                                "indices": indices,
                            }
                        ],
                    }
                )
        return {"deletions": [], "entities": entities}

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
