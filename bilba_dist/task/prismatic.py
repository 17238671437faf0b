"""Task files for a prismatic peg of any convex cross-section (or a union of convex ones)
and a chamfered hole that fits it: the family the defaults are measured on.

The hole is the peg's outline grown by half the clearance (Shapely's mitred buffer), so the
gap is the same on every side; each side of the hole is one convex wall piece running from
the hole's outline to an outer outline 30 mm further out, cut by the mitre planes through
the corners (so no seam lies where the peg slides) and chamfered at the top. A floor piece
fills the hole's outline: its top face ``floor/top`` is the goal and exists only inside.

Everything returned is plain data in the task-file format (metres, radians), ready for
``yaml.safe_dump``; nothing here loads or plans.
"""

from collections.abc import Sequence
from typing import Any

import numpy as np
from shapely.geometry import Polygon
from shapely.geometry.polygon import orient

#: Wall thickness beyond the chamfer [m], wall height [m], floor thickness [m].
WALL_M, WALL_HEIGHT_M, FLOOR_M = 0.03, 0.10, 0.04
#: Peg length [m]; the gripper holds it this far above its centre [m].
PEG_LENGTH_M, GRASP_M = 0.15, 0.155

Outline = Sequence[tuple[float, float]] | np.ndarray


def regular_polygon(sides: int, width_m: float, turn: float = 0.0) -> list[tuple[float, float]]:
    """A regular polygon of ``sides`` whose inscribed circle is ``width_m`` across [m]."""
    inradius = width_m / 2
    radius = inradius / np.cos(np.pi / sides)
    angles = turn + np.pi / sides + 2 * np.pi * np.arange(sides) / sides
    return [(float(radius * np.cos(a)), float(radius * np.sin(a))) for a in angles]


def rectangle(x_m: float, y_m: float, centre: tuple[float, float] = (0.0, 0.0)) -> Outline:
    cx, cy = centre
    return [(cx - x_m / 2, cy - y_m / 2), (cx + x_m / 2, cy - y_m / 2),
            (cx + x_m / 2, cy + y_m / 2), (cx - x_m / 2, cy + y_m / 2)]  # fmt: skip


def prism(outline: Outline, z0: float, z1: float) -> list[list[float]]:
    """The vertices of ``outline`` extruded from ``z0`` to ``z1`` [m]."""
    return [[float(x), float(y), z] for z in (z0, z1) for x, y in outline]


def _ring(polygon: Polygon) -> np.ndarray:
    """A polygon's corners, counter-clockwise, without the closing repeat or collinear
    points."""
    return np.array(orient(polygon.simplify(0), 1.0).exterior.coords)[:-1]


def _grown(outline: np.ndarray, distance: float) -> np.ndarray:
    """``outline`` grown by ``distance`` [m] with mitred corners, corner for corner."""
    grown = _ring(Polygon(outline).buffer(distance, join_style="mitre", mitre_limit=100.0))
    start = int(np.argmin(np.linalg.norm(grown - outline[0], axis=1)))
    grown = np.roll(grown, -start, axis=0)
    if len(grown) != len(outline):
        raise ValueError("the hole outline must be a convex polygon")
    return grown


def wall_pieces(hole: np.ndarray, chamfer_m: float) -> list[dict[str, Any]]:
    """One convex wall piece per side of the (convex, counter-clockwise) ``hole`` outline."""
    chamfered = _grown(hole, chamfer_m) if chamfer_m > 0 else hole
    outer = _grown(hole, chamfer_m + WALL_M)
    top, low = WALL_HEIGHT_M, WALL_HEIGHT_M - chamfer_m
    pieces = []
    for i in range(len(hole)):
        j = (i + 1) % len(hole)
        vertices = [
            *([float(v) for v in (*hole[k], z)] for k in (i, j) for z in (0.0, low)),
            *([float(v) for v in (*outer[k], z)] for k in (i, j) for z in (0.0, top)),
        ]
        if chamfer_m > 0:
            vertices += [[float(chamfered[k][0]), float(chamfered[k][1]), top] for k in (i, j)]
        edge = hole[j] - hole[i]
        inward = [float(-edge[1]), float(edge[0]), 0.0]  # toward the hole (ccw outline)
        faces = {"inner": inward, "top": [0.0, 0.0, 1.0], "bottom": [0.0, 0.0, -1.0]}
        if chamfer_m > 0:
            faces["chamfer"] = [inward[0], inward[1], float(np.hypot(*edge))]
        pieces.append({"name": f"wall{i}", "convex": {"vertices": vertices, "faces": faces}})
    return pieces


def peg_in_hole_task(
    name: str,
    peg: Sequence[Outline],
    clearance_m: float,
    chamfer_m: float,
    uncertainty: dict[str, str] | None = None,
) -> dict[str, Any]:
    """A task file's data: a peg made of the convex ``peg`` outlines (their union must be
    convex for the hole to be; an L-shaped peg's hole is the hull of its outlines), a hole
    ``clearance_m`` wider in total, chamfered by ``chamfer_m``, goal floor/top on the
    peg's bottom face."""
    hull = Polygon(np.concatenate([np.asarray(o, dtype=float) for o in peg])).convex_hull
    hole = _grown(_ring(hull), clearance_m / 2)
    half = PEG_LENGTH_M / 2
    pieces = [
        {
            "name": f"peg{k}" if len(peg) > 1 else "peg",
            "convex": {"vertices": prism(outline, -half, half), "faces": {"bottom": [0, 0, -1]}},
        }
        for k, outline in enumerate(peg)
    ]
    floor = {
        "name": "floor",
        "convex": {"vertices": prism(hole, 0.0, FLOOR_M), "faces": {"top": [0, 0, 1]}},
    }
    start_z = WALL_HEIGHT_M + 0.03 + half + GRASP_M  # the peg's bottom 3 cm above the walls
    return {
        "name": name,
        "description": f"prismatic peg, {clearance_m * 1000:g} mm clearance, "
        f"{chamfer_m * 1000:g} mm chamfer (bilba_dist.task.prismatic)",
        "manipuland": {"name": "peg", "pieces": pieces},
        "environment": {"name": "hole", "pieces": [floor, *wall_pieces(hole, chamfer_m)]},
        "grasp": {"xyz": [0, 0, GRASP_M], "rpy": [float(np.pi), 0, 0]},
        "environment_pose": {"xyz": [0.5, 0, 0]},
        "robot_start": {"gripper": {"xyz": [0.5, 0, start_z], "rpy": [float(np.pi), 0, 0]}},
        "goal": {"env": "floor/top", "manip": f"{pieces[0]['name']}/bottom"},
        "friction": 0.45,
        "uncertainty": dict(uncertainty or {"grasp.pitch": "2deg"}),
    }
