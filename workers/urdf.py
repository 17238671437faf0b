"""A Panda URDF that holds the manipuland rigidly: pybullet_data's arm and hand, the finger
joints made fixed, and the part as one more link fixed to the hand at ``X_GM``.

A link of the robot is rigid by construction (a fixed constraint drifts and slows physics by
1.7×). Box pieces are exact box shapes; other pieces are convex meshes, which PyBullet's URDF
loader gives a fixed collision margin of 1 mm (the shape collides as the hull grown by 1 mm,
and `changeDynamics` cannot change it on a link). So each mesh is written inset by that
margin: the hull grown back is the piece, exact on its faces, with edges and corners rounded
to 1 mm (as box shapes are).

The hand's rigid links (``panda_link8``, the hand, the locked fingers, the grasp target) are
merged into ``panda_link7`` (their collision shapes moved there, their inertias summed):
PyBullet's articulated-body step costs per link, fixed or not: 13 links → 8 ran the benchmark
motion 1.19× as fast, and cut a planning rollout's time to 0.87×, with PyBullet's mass matrix
and gravity unchanged (benchmarks/HISTORY.md, thirty-second session).
The part stays a link of its own, fixed to ``panda_link7`` where the hand holds it, so its
friction, mass and contacts are still its own. PyBullet's ``URDF_MERGE_FIXED_LINKS`` would
merge the part too.
"""

import re
import tempfile
import xml.etree.ElementTree as ET
from itertools import pairwise
from pathlib import Path

import numpy as np
import pinocchio as pin

from bilba_dist.errors import GeometryError
from bilba_dist.geometry.piece import URDF_MESH_MARGIN_M, ConvexPiece, Part, inset
from bilba_dist.robot.gripper import finger_opening
from bilba_dist.robot.panda import ARM_JOINTS, FINGER_JOINTS, panda_urdf

PART_LINK = "manipuland"
#: The arm's last moving link: the hand's fixed links are merged into it.
FLANGE_LINK = "panda_link7"


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


def part_collisions(part: Part, folder: Path) -> str:
    elements = []
    for piece in part.pieces:
        if piece.box_size is not None and piece.X_PB is not None:
            size = " ".join(f"{v:.17g}" for v in piece.box_size)
            geometry, origin = f'<box size="{size}"/>', _origin(piece.X_PB)
        else:
            obj = folder / f"{piece.name}.obj"  # the part name is free text: not in a path
            write_obj(inset(piece, URDF_MESH_MARGIN_M), obj)
            geometry, origin = f'<mesh filename="{obj}"/>', _origin(pin.SE3.Identity())
        elements.append(
            f'<collision name="{piece.name}">{origin}<geometry>{geometry}</geometry></collision>'
        )
    return "\n    ".join(elements)


def panda_with_part(
    part: Part,
    X_GM: pin.SE3,
    mass: float,
    folder: Path | None = None,
    merge_hand: bool = True,
    limits: tuple[np.ndarray, np.ndarray] | None = None,
) -> Path:
    """Write the URDF (and any meshes) into ``folder`` and return its path. ``merge_hand``:
    the hand's fixed links merged into the flange link (``merge_fixed_links``). ``limits``:
    the arm's joint limits (lower, upper) to write in place of the URDF's (pybullet_data's
    allow more: joint 5 to ±2.9671 rad where a Panda stops at ±2.8973) — the IK's,
    ``PandaModel.lower``/``upper``."""
    folder = Path(folder or tempfile.mkdtemp(prefix="bilba_urdf_"))
    folder.mkdir(parents=True, exist_ok=True)
    source = Path(panda_urdf())
    text = source.read_text()
    text = re.sub(r"<visual>.*?</visual>", "", text, flags=re.DOTALL)  # DIRECT: never drawn
    text = re.sub(r'filename="(package://)?meshes/', f'filename="{source.parent}/meshes/', text)
    text = _fingers_fixed(text, finger_opening(part, X_GM))
    if limits is not None:
        text = _with_joint_limits(text, *limits)
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
    if merge_hand:
        text = merge_fixed_links(text, FLANGE_LINK, keep=frozenset({PART_LINK}))
    path = folder / "panda_with_part.urdf"
    path.write_text(text)
    return path


def _fingers_fixed(text: str, opening: float) -> str:
    """``text`` with the finger joints made fixed and each finger's collision shape moved
    ``opening`` [m] along its joint's axis, where it closes on the part. Only the shapes
    move: the fingers' mass stays where the URDF puts it, so the arm's dynamics are those of
    every plan before the fingers opened (a 0.1 kg finger 15 mm aside changes rollouts)."""
    root = ET.fromstring(text)
    links = {link.get("name"): link for link in root.findall("link")}
    for joint in root.findall("joint"):
        if joint.get("name") not in FINGER_JOINTS:
            continue
        joint.set("type", "fixed")
        axis = np.array(_linked(joint, "axis", "xyz").split(), float)
        for collision in links[_linked(joint, "child")].findall("collision"):
            origin = collision.find("origin")
            if origin is None:
                origin = ET.SubElement(collision, "origin", {"rpy": "0 0 0", "xyz": "0 0 0"})
            xyz = np.array(origin.get("xyz", "0 0 0").split(), float) + opening * axis
            origin.set("xyz", " ".join(f"{v:.17g}" for v in xyz))
    return ET.tostring(root, encoding="unicode")


def _with_joint_limits(text: str, lower: np.ndarray, upper: np.ndarray) -> str:
    """``text`` (the Panda URDF) with each arm joint's limits replaced."""
    for joint, low, high in zip(ARM_JOINTS, lower, upper, strict=True):
        text, n = re.subn(
            rf'(<joint name="{joint}".*?<limit [^>]*?)lower="[^"]*" upper="[^"]*"',
            rf'\g<1>lower="{low:.17g}" upper="{high:.17g}"',
            text,
            count=1,
            flags=re.DOTALL,
        )
        assert n == 1, joint  # pybullet_data's URDF as we know it
    return text


def _pose(origin: ET.Element | None) -> pin.SE3:
    if origin is None:
        return pin.SE3.Identity()
    xyz = [float(v) for v in origin.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in origin.get("rpy", "0 0 0").split()]
    return pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(xyz))


def _set_origin(element: ET.Element, X: pin.SE3) -> None:
    """Replace ``element``'s ``<origin>`` (first child) with ``X``."""
    old = element.find("origin")
    if old is not None:
        element.remove(old)
    element.insert(0, ET.fromstring(_origin(X)))


def _inertia(link: ET.Element) -> pin.Inertia:
    """The link's inertia about its frame's origin (zero without an ``<inertial>``)."""
    inertial = link.find("inertial")
    if inertial is None:
        return pin.Inertia.Zero()
    mass = float(_linked(inertial, "mass", "value"))
    t = inertial.find("inertia")
    xx, yy, zz, xy, xz, yz = (
        float(t.get(k, "0")) if t is not None else 0.0
        for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")
    )
    rotational = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    return _pose(inertial.find("origin")).act(pin.Inertia(mass, np.zeros(3), rotational))


def _linked(element: ET.Element, tag: str, attribute: str = "link") -> str:
    """``element``'s ``<tag attribute=…>`` (a joint's parent or child link, a mass)."""
    child = element.find(tag)
    if child is None or child.get(attribute) is None:
        raise GeometryError(f"the robot URDF has a <{element.tag}> without <{tag} {attribute}>")
    return str(child.get(attribute))


def merge_fixed_links(text: str, into: str, keep: frozenset[str] = frozenset()) -> str:
    """``text`` (a URDF) with every link hanging from ``into`` by fixed joints alone (but
    those in ``keep``, and what hangs from them) merged into ``into``: collision shapes moved
    there, inertias summed (as principal moments and axes: PyBullet reads the diagonal),
    joints to what stays re-attached to ``into``. A link's ``<contact>`` parameters are
    dropped with it (the fingers' soft contact: fingers touching the environment now do so
    as stiffly as the part)."""
    root = ET.fromstring(text)
    links = {link.get("name"): link for link in root.findall("link")}
    joints = root.findall("joint")
    parent_of = {_linked(j, "child"): j for j in joints}
    merged: dict[str, pin.SE3] = {}  # link -> its frame in ``into``'s
    frontier = [into]
    while frontier:
        name = frontier.pop()
        for j in joints:
            child = _linked(j, "child")
            if _linked(j, "parent") == name and j.get("type") == "fixed" and child not in keep:
                merged[child] = merged.get(name, pin.SE3.Identity()) * _pose(j.find("origin"))
                frontier.append(child)
    target = links[into]
    total = _inertia(target)
    for name, X in merged.items():
        total = total + X.act(_inertia(links[name]))
        for collision in links[name].findall("collision"):
            _set_origin(collision, X * _pose(collision.find("origin")))
            target.append(collision)
        root.remove(links[name])
        root.remove(parent_of[name])
    for j in root.findall("joint"):
        parent = _linked(j, "parent")
        if parent in merged:
            _set_origin(j, merged[parent] * _pose(j.find("origin")))
            j.find("parent").set("link", into)  # type: ignore[union-attr]
    moments, axes = np.linalg.eigh(total.inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1
    inertial = target.find("inertial")
    if inertial is not None:
        target.remove(inertial)
    xx, yy, zz = (f"{v:.17g}" for v in moments)
    target.insert(
        0,
        ET.fromstring(
            f"<inertial>{_origin(pin.SE3(axes, total.lever))}"
            f'<mass value="{total.mass:.17g}"/><inertia ixx="{xx}" ixy="0" ixz="0" '
            f'iyy="{yy}" iyz="0" izz="{zz}"/></inertial>'
        ),
    )
    return ET.tostring(root, encoding="unicode")
