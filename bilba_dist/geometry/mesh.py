"""Convex pieces from mesh files, read with trimesh (STL, OBJ, PLY, OFF, GLB, …).

A mesh piece must be one closed, convex surface with volume: a closed surface because a
convex hull of an open or self-intersecting scan is not the part, convex because a piece
is. A non-convex part is refused with how to split it: CoACD (``pip install coacd``) writes
one convex part per piece, and each becomes a ``mesh`` piece of its own.
"""

from pathlib import Path

import numpy as np

from bilba_dist.errors import GeometryError, first_line
from bilba_dist.task.units import WORKSPACE_M

#: A mesh is convex when its volume is within this fraction of its convex hull's.
CONVEX_VOLUME_TOL = 1e-3
#: Files beyond this size are refused before parsing [bytes].
MAX_MESH_BYTES = 50 * 2**20


@np.errstate(all="ignore")  # a file's overflows are checked below, not printed as warnings
def mesh_vertices(path: Path, scale: float) -> np.ndarray:
    """The corners of the convex hull of the closed, convex mesh in ``path``, times
    ``scale`` [m]; any problem is one GeometryError naming the file."""
    import trimesh  # ~0.3 s to import: only for tasks with meshes

    try:
        size = path.stat().st_size
    except OSError as exc:
        raise GeometryError(f"mesh {path}: cannot read it: {exc.strerror or exc}") from None
    if size > MAX_MESH_BYTES:
        raise GeometryError(f"mesh {path}: {size / 2**20:.0f} MiB, over the 50 MiB limit")
    try:
        mesh = trimesh.load_mesh(path, process=True)
    except Exception as exc:  # trimesh raises many kinds for a corrupt file
        reason = first_line(exc, type(exc).__name__)
        raise GeometryError(f"mesh {path}: cannot load it: {reason}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise GeometryError(f"mesh {path}: holds no triangles (one closed surface expected)")
    if not np.isfinite(mesh.vertices).all():
        raise GeometryError(f"mesh {path}: has vertices that are not finite numbers")
    reach = float(np.abs(mesh.vertices).max() * scale)
    if not reach <= WORKSPACE_M:
        shown = f"{reach:g} m" if np.isfinite(reach) else "far"
        raise GeometryError(
            f"mesh {path}: times scale {scale:g} its points reach {shown} from the piece's "
            f"frame, beyond the ±{WORKSPACE_M:g} m of a task; is the scale right (0.001 for "
            "a file in millimetres)?"
        )
    if not mesh.is_watertight:
        raise GeometryError(
            f"mesh {path}: not a closed (watertight, manifold) surface; repair it, e.g. "
            "with trimesh.repair or MeshLab"
        )
    hull = mesh.convex_hull  # once, in file units: its corners are what is returned
    # Volumes in metres: cubes of file units can overflow.
    metres, hull_metres = mesh.copy(), hull.copy()
    metres.apply_scale(scale)
    hull_metres.apply_scale(scale)
    volume, hull_volume = abs(metres.volume), float(hull_metres.volume)
    if volume <= 1e-12 * float(np.ptp(metres.vertices, axis=0).max()) ** 3:
        raise GeometryError(f"mesh {path}: encloses no volume")
    if volume < (1 - CONVEX_VOLUME_TOL) * hull_volume:
        share = 100 * (1 - volume / hull_volume)
        raise GeometryError(
            f"mesh {path}: not convex (its hull is {share:.1f} % empty); split it into convex "
            "parts, e.g. `coacd -i PART -o parts.obj`, and give each its own mesh piece"
        )
    return np.asarray(hull.vertices, dtype=float) * scale
