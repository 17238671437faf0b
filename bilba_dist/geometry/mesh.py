"""Convex pieces from mesh files, read with trimesh (STL, OBJ, PLY, OFF, GLB, …).

A mesh piece must be one closed, convex surface with volume: a closed surface because a
convex hull of an open or self-intersecting scan is not the part, convex because a piece
is. A non-convex part is refused with how to split it: CoACD (``pip install coacd``) writes
its convex parts as the objects of one OBJ file, and a file of several objects (or glTF
nodes) is several bodies, each a piece of its own.
"""

import re
from pathlib import Path
from typing import Any

import numpy as np

from bilba_dist.errors import GeometryError, first_line
from bilba_dist.task.units import WORKSPACE_M

#: A mesh is convex when its volume is within this fraction of its convex hull's.
CONVEX_VOLUME_TOL = 1e-3
#: Files beyond this size are refused before parsing [bytes].
MAX_MESH_BYTES = 50 * 2**20
#: Bodies one file may hold (a CoACD decomposition of a part has tens).
MAX_BODIES = 200


def _natural(name: str) -> list:
    """Sort key: ``geometry_2`` before ``geometry_10``."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name)]


@np.errstate(all="ignore")  # a file's overflows are checked below, not printed as warnings
def mesh_bodies(path: Path, scale: float) -> list[np.ndarray]:
    """The corners of each body's convex hull, times ``scale`` [m]: one body for a file of
    one surface, one per object for a file of several (an OBJ's ``o`` objects, as CoACD
    writes them; glTF nodes), in the natural order of their names. Each must be a closed,
    convex surface; any problem is one GeometryError naming the file (and the body)."""
    import trimesh  # ~0.3 s to import: only for tasks with meshes

    try:
        size = path.stat().st_size
    except OSError as exc:
        raise GeometryError(f"mesh {path}: cannot read it: {exc.strerror or exc}") from None
    if size > MAX_MESH_BYTES:
        raise GeometryError(f"mesh {path}: {size / 2**20:.0f} MiB, over the 50 MiB limit")
    try:
        scene: Any = trimesh.load(
            path, force="scene", process=True, split_objects=True, group_material=False
        )
        nodes = sorted(scene.graph.nodes_geometry, key=_natural)
        meshes = []
        for node in nodes[: MAX_BODIES + 1]:
            transform, name = scene.graph[node]
            meshes.append((node, scene.geometry[name].copy().apply_transform(transform)))
    except Exception as exc:  # trimesh raises many kinds for a corrupt file
        reason = first_line(exc, type(exc).__name__)
        raise GeometryError(f"mesh {path}: cannot load it: {reason}") from None
    if len(meshes) > MAX_BODIES:
        raise GeometryError(f"mesh {path}: over {MAX_BODIES} objects; merge some")
    if not meshes:
        raise GeometryError(f"mesh {path}: holds no triangles (one closed surface expected)")
    bodies = []
    for node, mesh in meshes:
        where = f"mesh {path}" if len(meshes) == 1 else f"mesh {path}, object {node!r}"
        bodies.append(_hull_corners(mesh, scale, where))
    return bodies


def _hull_corners(mesh: Any, scale: float, where: str) -> np.ndarray:
    """The corners of the convex hull of the closed, convex ``mesh``, times ``scale``."""
    import trimesh

    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise GeometryError(f"{where}: holds no triangles (one closed surface expected)")
    if not np.isfinite(mesh.vertices).all():
        raise GeometryError(f"{where}: has vertices that are not finite numbers")
    reach = float(np.abs(mesh.vertices).max() * scale)
    if not reach <= WORKSPACE_M:
        shown = f"{reach:g} m" if np.isfinite(reach) else "far"
        raise GeometryError(
            f"{where}: times scale {scale:g} its points reach {shown} from the piece's "
            f"frame, beyond the ±{WORKSPACE_M:g} m of a task; is the scale right (0.001 for "
            "a file in millimetres)?"
        )
    if not mesh.is_watertight:
        raise GeometryError(
            f"{where}: not a closed (watertight, manifold) surface; repair it, e.g. with "
            "trimesh.repair or MeshLab (convex parts in one file: write each as an object "
            "of an OBJ file, as CoACD does)"
        )
    hull = mesh.convex_hull  # once, in file units: its corners are what is returned
    # Volumes in metres: cubes of file units can overflow.
    metres, hull_metres = mesh.copy(), hull.copy()
    metres.apply_scale(scale)
    hull_metres.apply_scale(scale)
    volume, hull_volume = abs(metres.volume), float(hull_metres.volume)
    if volume <= 1e-12 * float(np.ptp(metres.vertices, axis=0).max()) ** 3:
        raise GeometryError(f"{where}: encloses no volume")
    if volume < (1 - CONVEX_VOLUME_TOL) * hull_volume:
        share = 100 * (1 - volume / hull_volume)
        raise GeometryError(
            f"{where}: not convex (its hull is {share:.1f} % empty); split it into convex "
            "parts, e.g. `coacd -i PART -o parts.obj`, and give that file as the mesh: "
            "each of its objects becomes a piece"
        )
    return np.asarray(hull.vertices, dtype=float) * scale
