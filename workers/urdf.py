"""A Panda URDF that holds the manipuland rigidly: pybullet_data's arm and hand, the finger
joints made fixed, and the part as one more link fixed to the hand at ``X_GM``.

A link of the robot is rigid by construction (a fixed constraint drifts and slows physics by
1.7×: PHYSICS.md). Box pieces are exact box shapes; other pieces are convex meshes.
"""

import re
import tempfile
from pathlib import Path

import numpy as np
import pinocchio as pin

from bilba_dist.geometry.piece import Part
from bilba_dist.robot.panda import FINGER_JOINTS, panda_urdf

PART_LINK = "manipuland"


def _origin(X: pin.SE3) -> str:
    xyz = " ".join(f"{v:.17g}" for v in X.translation)
    rpy = " ".join(f"{v:.17g}" for v in pin.rpy.matrixToRpy(X.rotation))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def write_obj(vertices: np.ndarray, path: Path) -> None:
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in vertices]
    path.write_text("\n".join(lines) + "\n")  # pybullet takes the convex hull of the points


def part_collisions(part: Part, folder: Path) -> str:
    elements = []
    for piece in part.pieces:
        if piece.box_size is not None and piece.X_PB is not None:
            size = " ".join(f"{v:.17g}" for v in piece.box_size)
            geometry, origin = f'<box size="{size}"/>', _origin(piece.X_PB)
        else:
            obj = folder / f"{part.name}_{piece.name}.obj"
            write_obj(piece.vertices, obj)
            geometry, origin = f'<mesh filename="{obj}"/>', _origin(pin.SE3.Identity())
        elements.append(
            f'<collision name="{piece.name}">{origin}<geometry>{geometry}</geometry></collision>'
        )
    return "\n    ".join(elements)


def panda_with_part(part: Part, X_GM: pin.SE3, mass: float, folder: Path | None = None) -> Path:
    """Write the URDF (and any meshes) into ``folder`` and return its path."""
    folder = Path(folder or tempfile.mkdtemp(prefix="bilba_urdf_"))
    source = Path(panda_urdf())
    text = source.read_text()
    text = re.sub(r"<visual>.*?</visual>", "", text, flags=re.DOTALL)  # DIRECT: never drawn
    text = re.sub(r'filename="(package://)?meshes/', f'filename="{source.parent}/meshes/', text)
    for joint in FINGER_JOINTS:
        text = re.sub(rf'(<joint name="{joint}" type=)"prismatic"', r'\1"fixed"', text)
    centre = part_centre(part)
    link = f"""
  <link name="{PART_LINK}">
    <inertial><origin xyz="{" ".join(f"{v:.17g}" for v in centre)}"/><mass value="{mass}"/>
      <inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>
    {part_collisions(part, folder)}
  </link>
  <joint name="{PART_LINK}_joint" type="fixed">
    <parent link="panda_hand"/><child link="{PART_LINK}"/>{_origin(X_GM)}
  </joint>
</robot>"""
    text = text.replace("</robot>", link, 1)
    path = folder / "panda_with_part.urdf"
    path.write_text(text)
    return path


def part_centre(part: Part) -> np.ndarray:
    """Centre of the part's vertices [m, part frame]: where its mass is put."""
    points = np.concatenate([p.vertices for p in part.pieces])
    return (points.min(axis=0) + points.max(axis=0)) / 2
