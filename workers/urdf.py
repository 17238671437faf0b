"""A Panda URDF that holds the manipuland rigidly: pybullet_data's arm and hand, the finger
joints made fixed, and the part as one more link fixed to the hand at ``X_GM``.

A link of the robot is rigid by construction (a fixed constraint drifts and slows physics by
1.7×). Box pieces are exact box shapes; other pieces are convex meshes, which PyBullet's URDF
loader gives a fixed collision margin of 1 mm (the shape collides as the hull grown by 1 mm,
and `changeDynamics` cannot change it on a link). So each mesh is written inset by that
margin: the hull grown back is the piece, exact on its faces, with edges and corners rounded
to 1 mm (as box shapes are).
"""

import re
import tempfile
from itertools import pairwise
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.spatial import HalfspaceIntersection

from bilba_dist.errors import GeometryError
from bilba_dist.geometry.piece import ConvexPiece, Part, convex_piece
from bilba_dist.robot.panda import FINGER_JOINTS, panda_urdf

PART_LINK = "manipuland"
#: The collision margin PyBullet's URDF loader gives a convex mesh [m].
URDF_MESH_MARGIN_M = 0.001


def _origin(X: pin.SE3) -> str:
    xyz = " ".join(f"{v:.17g}" for v in X.translation)
    rpy = " ".join(f"{v:.17g}" for v in pin.rpy.matrixToRpy(X.rotation))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def write_obj(piece: ConvexPiece, path: Path) -> None:
    """The piece as a Wavefront OBJ in its part's frame: its vertices and every face as a
    fan of triangles. (An OBJ of vertices alone loads as an empty mesh: PyBullet warns
    "issue extracting mesh" and the link collides with nothing.)"""
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in piece.vertices]
    for face in piece.faces:
        a, *rest = (i + 1 for i in face.vertices)  # OBJ counts from 1, counter-clockwise
        lines += [f"f {a} {b} {c}" for b, c in pairwise(rest)]
    path.write_text("\n".join(lines) + "\n")


def inset(piece: ConvexPiece, depth: float) -> ConvexPiece:
    """``piece`` with every face moved ``depth`` [m] inwards (a piece thinner than twice
    that has nothing left: an error naming it)."""
    normals = np.array([f.normal for f in piece.faces])
    offsets = np.array([f.offset for f in piece.faces]) - depth
    centre = piece.vertices.mean(axis=0)
    if (normals @ centre - offsets).max() >= -1e-6:
        raise GeometryError(
            f"piece {piece.name!r} is too thin to simulate on the Panda model: its faces "
            f"must be more than {2 * depth * 1000:g} mm apart"
        )
    corners = HalfspaceIntersection(np.column_stack([normals, -offsets]), centre)
    return convex_piece(
        piece.name, np.unique(corners.intersections.round(12), axis=0), pin.SE3.Identity()
    )


def part_collisions(part: Part, folder: Path) -> str:
    elements = []
    for piece in part.pieces:
        if piece.box_size is not None and piece.X_PB is not None:
            size = " ".join(f"{v:.17g}" for v in piece.box_size)
            geometry, origin = f'<box size="{size}"/>', _origin(piece.X_PB)
        else:
            obj = folder / f"{part.name}_{piece.name}.obj"
            write_obj(inset(piece, URDF_MESH_MARGIN_M), obj)
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
    centre = part.centre()
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
