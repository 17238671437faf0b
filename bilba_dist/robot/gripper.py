"""The gripper as a part: the collision shapes of the Panda links rigid with the hand
(``panda_link7``, the hand, the two fingers), as convex pieces in the hand's frame.

They are the shapes the simulated arm collides with (PyBullet takes the convex hull of each
collision mesh and grows it by its 1 mm margin; the fingers locked where they close on the
part, ``finger_opening``), so the C-obs of the environment against this part says where the
gripper itself would be inside the environment: a part held too short for the depth of its
hole can never reach the goal, because the fingers meet the rim first (docs/task-files.md,
The gripper must fit too).
"""

import os
from functools import lru_cache
from typing import cast

import numpy as np
import pinocchio as pin
from scipy.optimize import linprog

from bilba_dist.geometry.piece import URDF_MESH_MARGIN_M, ConvexPiece, Part, convex_piece, inset
from bilba_dist.robot.panda import FINGER_JOINTS, HAND, panda_urdf

#: The links whose collision shapes move with the hand (the fingers locked).
GRIPPER_LINKS = ("panda_link7", HAND, "panda_leftfinger", "panda_rightfinger")


#: The Franka Hand's fingers: each opens to this from the centre [m] (80 mm between them).
FINGER_TRAVEL_M = 0.04
#: Where the fingers' collision shapes reach, along the hand's z [m] (pybullet_data's
#: finger mesh from the finger joints at 0.0584 m): the slab of the part they close on.
FINGER_REACH_M = (0.0584, 0.1122)


def finger_opening(part: Part, X_GM: pin.SE3) -> float:
    """How far each finger stands from the centre when the hand holds ``part`` at ``X_GM``
    [m]: ``grasp_reach``, up to FINGER_TRAVEL_M."""
    return min(grasp_reach(part, X_GM), FINGER_TRAVEL_M)


def grasp_reach(part: Part, X_GM: pin.SE3) -> float:
    """How far from the centre the part reaches along the hand's y (the fingers' axis)
    where the fingers are [m]: where the fingers close on it (the farther side: they move
    together); 0 where the part is not between them."""
    low, high = np.inf, -np.inf
    for piece in part.pieces:
        A = np.array([f.normal for f in piece.faces]) @ X_GM.rotation.T  # hand frame
        b = np.array([f.offset for f in piece.faces]) + A @ X_GM.translation
        for sign in (1.0, -1.0):  # the piece's extreme y within the fingers' slab
            found = linprog(
                [0.0, sign, 0.0],
                A_ub=A,
                b_ub=b,
                bounds=[(None, None), (None, None), FINGER_REACH_M],
            )
            if found.status == 0:
                low, high = min(low, found.x[1]), max(high, found.x[1])
    if low > high:
        return 0.0
    return float(max(abs(low), abs(high)))


def too_wide(part: Part, X_GM: pin.SE3) -> str | None:
    """A warning where the Franka Hand cannot open around the part as it is held, else
    None: the simulation then puts each finger at its 40 mm, inside the part."""
    reach = grasp_reach(part, X_GM)
    if reach <= FINGER_TRAVEL_M:
        return None
    opens = 2 * FINGER_TRAVEL_M * 1000
    return (
        f"the part is {2 * reach * 1000:.0f} mm across between the fingers (from the hand's "
        f"centre, the farther side doubled) where the Franka Hand opens {opens:.0f} mm; "
        "the simulation puts the fingers at their widest, inside the part: hold it by a "
        "narrower side (turn the grasp about the hand's z)"
    )


@lru_cache(maxsize=1)
def _gripper_model() -> tuple[
    pin.Model, pin.GeometryModel, tuple[tuple[int, str, np.ndarray], ...]
]:
    """The Panda's model, its collision model, and for each shape of GRIPPER_LINKS (its
    index, link, the corners of its mesh's convex hull grown by the margin, in its own
    frame): read once (~0.8 s)."""
    import trimesh  # ~0.8 s to import: only when a check needs the hulls

    urdf = panda_urdf()
    model, collision, _ = pin.buildModelsFromUrdf(urdf, os.path.dirname(urdf))
    shapes = []
    for i, shape in enumerate(collision.geometryObjects):
        link = model.frames[shape.parentFrame].name
        if link in GRIPPER_LINKS:
            mesh = cast(trimesh.Trimesh, trimesh.load(shape.meshPath, force="mesh", process=False))
            hull = convex_piece(link, mesh.convex_hull.vertices * np.asarray(shape.meshScale),
                                pin.SE3.Identity())  # fmt: skip
            # faces moved out by the margin: over the rounded shape at edges, by < 0.5 mm
            shapes.append((i, link, inset(hull, -URDF_MESH_MARGIN_M).vertices))
    return model, collision, tuple(shapes)


def gripper_hulls(opening: float = 0.0) -> tuple[tuple[str, np.ndarray], ...]:
    """(link name, the corners of its collision mesh's convex hull, grown by the margin, in
    the ``panda_hand`` frame [m]) for each of GRIPPER_LINKS, each finger ``opening`` from the
    centre (``finger_opening``), as the simulation holds them."""
    model, collision, shapes = _gripper_model()
    data, geometry = model.createData(), pin.GeometryData(collision)
    q = pin.neutral(model)
    for name in FINGER_JOINTS:
        q[model.joints[model.getJointId(name)].idx_q] = opening
    pin.framesForwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, collision, geometry, q)
    X_HW = data.oMf[model.getFrameId(HAND)].inverse()
    placed = [(link, X_HW * geometry.oMg[i]) for i, link, _ in shapes]
    return tuple(
        (link, corners @ X.rotation.T + X.translation)
        for (link, X), (_, _, corners) in zip(placed, shapes, strict=True)
    )


@lru_cache(maxsize=8)
def gripper_part(opening: float = 0.0) -> Part:
    """The gripper's pieces in the ``panda_hand`` frame (named by their links), each finger
    ``opening`` from the centre."""
    pieces: list[ConvexPiece] = [
        convex_piece(link, corners, pin.SE3.Identity()) for link, corners in gripper_hulls(opening)
    ]
    return Part("gripper", tuple(pieces))
