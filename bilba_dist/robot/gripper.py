"""The gripper as a part: the collision shapes of the Panda links rigid with the hand
(``panda_link7``, the hand, the two fingers), as convex pieces in the hand's frame.

They are the shapes the simulated arm collides with (PyBullet takes the convex hull of each
collision mesh and grows it by its 1 mm margin; the fingers locked closed, where the
simulation locks them), so the C-obs
of the environment against this part says where the gripper itself would be inside the
environment: a part held too short for the depth of its hole can never reach the goal,
because the fingers meet the rim first (docs/task-files.md, The gripper must fit too).
"""

import os
from functools import lru_cache
from typing import cast

import numpy as np
import pinocchio as pin
import trimesh

from bilba_dist.geometry.piece import URDF_MESH_MARGIN_M, ConvexPiece, Part, convex_piece, inset
from bilba_dist.robot.panda import HAND, panda_urdf

#: The links whose collision shapes move with the hand (the fingers locked).
GRIPPER_LINKS = ("panda_link7", HAND, "panda_leftfinger", "panda_rightfinger")


@lru_cache(maxsize=1)
def gripper_hulls() -> tuple[tuple[str, np.ndarray], ...]:
    """(link name, the corners of its collision mesh's convex hull, grown by the margin, in
    the ``panda_hand`` frame [m]) for each of GRIPPER_LINKS, the finger joints at 0 as the
    simulation holds them."""
    urdf = panda_urdf()
    model, collision, _ = pin.buildModelsFromUrdf(urdf, os.path.dirname(urdf))
    data, geometry = model.createData(), pin.GeometryData(collision)
    q = pin.neutral(model)
    pin.framesForwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, collision, geometry, q)
    X_WH = data.oMf[model.getFrameId(HAND)]
    hulls = []
    for i, shape in enumerate(collision.geometryObjects):
        link = model.frames[shape.parentFrame].name
        if link not in GRIPPER_LINKS:
            continue
        mesh = cast(trimesh.Trimesh, trimesh.load(shape.meshPath, force="mesh", process=False))
        corners = mesh.convex_hull.vertices * np.asarray(shape.meshScale)
        hull = convex_piece(link, corners, X_WH.inverse() * geometry.oMg[i])
        # faces moved out by the margin: over the rounded shape at edges, by < 0.5 mm
        hulls.append((link, inset(hull, -URDF_MESH_MARGIN_M).vertices))
    return tuple(hulls)


@lru_cache(maxsize=1)
def gripper_part() -> Part:
    """The gripper's pieces in the ``panda_hand`` frame (named by their links)."""
    pieces: list[ConvexPiece] = [
        convex_piece(link, corners, pin.SE3.Identity()) for link, corners in gripper_hulls()
    ]
    return Part("gripper", tuple(pieces))
