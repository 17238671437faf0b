"""Convex pieces with named faces, and parts made of them.

Coordinates are in the part's own frame, in metres. A face is named ``piece/face``: box faces
``+x -x +y -y +z -z``, convex facets by the task's name map (face name → outward normal in the
piece frame) or ``f0, f1, …`` in a fixed order (by normal, descending x, then y, then z).
"""

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property

import networkx as nx
import numpy as np
import pinocchio as pin
from scipy.spatial import HalfspaceIntersection

from bilba_dist.errors import GeometryError, listed
from bilba_dist.geometry.hull import convex_hull, face_edges, planar_faces
from bilba_dist.geometry.pose import transform_points

BOX_FACES = {
    "+x": (1.0, 0.0, 0.0),
    "-x": (-1.0, 0.0, 0.0),
    "+y": (0.0, 1.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "+z": (0.0, 0.0, 1.0),
    "-z": (0.0, 0.0, -1.0),
}
#: A named normal matches a facet when within this angle [rad].
NAME_MATCH_ANGLE = np.deg2rad(1.0)
#: A listed vertex further than this inside the hull means the piece is not convex [m].
CONVEX_TOL = 1e-9
#: The name a facet gets when the task file names none for it (``f0``, ``f1``, …).
UNNAMED = re.compile(r"f\d+")
#: Unnamed facets of one piece that share an edge and whose normals differ by at most this
#: are one smooth surface (a meshed cylinder's sides, 11.25° apart at 32 sections): one
#: face name, so a contact anywhere on it is the same contact [rad]. A hexagon's or an
#: octagon's sides (60°, 45°) and a chamfer (45°) stay faces of their own. On the
#: environment it is also the most a surface's normals may differ (task/loader.py).
SMOOTH_ANGLE = np.deg2rad(25.0)


@dataclass(frozen=True)
class Face:
    """A planar face: ``normal · x = offset`` on it, ``<`` inside the piece (part frame)."""

    name: str  # "piece/face"
    normal: np.ndarray
    offset: float
    vertices: tuple[int, ...]  # indices into the piece's vertices, counter-clockwise


@dataclass(frozen=True)
class ConvexPiece:
    """A convex polyhedron in its part's frame."""

    name: str
    vertices: np.ndarray  # (N, 3) hull vertices only [m]
    faces: tuple[Face, ...]
    edges: np.ndarray  # (E, 2) vertex index pairs
    box_size: np.ndarray | None = None  # for boxes: full size [m], centred at X_PB
    X_PB: pin.SE3 | None = None  # for boxes: the box centre frame in the part frame

    @cached_property
    def face_vertex_sets(self) -> tuple[tuple[str, frozenset[int]], ...]:
        """Each face's name and the indices of its vertices (a hashable key for caches)."""
        return tuple((f.name, frozenset(f.vertices)) for f in self.faces)

    def face(self, name: str) -> Face:
        for face in self.faces:
            if face.name == name:
                return face
        raise GeometryError(f"piece {self.name!r} has no face {name!r}; its faces: {self._known()}")

    def _known(self) -> str:
        """The faces a user named first (a mesh has dozens of facets ``f0``, ``f1``, … in
        order of their normals, and a typo's message should show the name it missed)."""
        unnamed = [f.name for f in self.faces if UNNAMED.fullmatch(f.name.rpartition("/")[2])]
        named = [f.name for f in self.faces if f.name not in unnamed]
        if not unnamed:
            return listed(named)
        return (
            f"{listed(named) + ' and ' if named else ''}{len(unnamed)} unnamed facets "
            f"{self.name}/f0 … f{len(self.faces) - 1} (name one by its outward normal under "
            "'faces:')"
        )

    def faces_at(self, point: np.ndarray, tol: float = 1e-6) -> list[int]:
        """Indices of the faces whose plane holds ``point`` (part frame), if the point is on
        the piece: 1 inside a face, 2 on an edge, 3 or more at a corner; [] off the piece."""
        normals = np.array([f.normal for f in self.faces])
        offsets = np.array([f.offset for f in self.faces])
        slack = normals @ point - offsets
        if slack.max() > tol:
            return []
        return [int(i) for i in np.flatnonzero(np.abs(slack) <= tol)]


def box_piece(name: str, size: Sequence[float], X_PB: pin.SE3) -> ConvexPiece:
    """A box of ``size`` [m] whose centre frame is at ``X_PB`` in the part frame."""
    half = np.asarray(size, dtype=float) / 2.0
    if half.shape != (3,) or np.any(half <= 0):
        raise GeometryError(f"piece {name!r}: box size must be three positive lengths, got {size}")
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    piece = convex_piece(name, corners * half, X_PB, BOX_FACES)
    return replace(piece, box_size=2 * half, X_PB=X_PB.copy())


def convex_piece(
    name: str,
    vertices: Sequence[Sequence[float]] | np.ndarray,
    X_PC: pin.SE3,
    face_names: Mapping[str, Sequence[float]] | None = None,
) -> ConvexPiece:
    """The convex piece spanned by ``vertices`` (piece frame), placed at ``X_PC``.

    Every listed vertex must be a corner of the hull: a vertex inside it means the user
    described a non-convex shape, which is an error, not something to silently fill in.
    """
    points = np.asarray(vertices, dtype=float)
    hull = convex_hull(points, f"piece {name!r}")
    _check_convex(name, points, hull)
    faces = planar_faces(points, hull)
    names = _name_faces(name, faces, face_names or {})
    keep = np.array(sorted(hull.vertices))
    remap = {int(old): new for new, old in enumerate(keep)}
    R = X_PC.rotation
    placed = tuple(
        Face(
            name=f"{name}/{label}",
            normal=R @ face.normal,
            offset=float(face.offset + (R @ face.normal) @ X_PC.translation),
            vertices=tuple(remap[i] for i in face.vertices),
        )
        for label, face in zip(names, faces, strict=True)
    )
    return ConvexPiece(
        name=name,
        vertices=transform_points(X_PC, points[keep]),
        faces=placed,
        edges=face_edges(f.vertices for f in placed),
    )


def _check_convex(name: str, points: np.ndarray, hull: object) -> None:
    equations = hull.equations  # type: ignore[attr-defined]
    corners = set(int(i) for i in hull.vertices)  # type: ignore[attr-defined]
    for i, p in enumerate(points):
        if i in corners:
            continue
        depth = float((equations[:, :3] @ p + equations[:, 3]).max())
        if depth < -CONVEX_TOL:
            raise GeometryError(
                f"piece {name!r} is not convex: vertex {i} {p.tolist()} lies "
                f"{-depth * 1000:.3g} mm inside the hull of the others; split it into convex pieces"
            )


def _name_faces(
    piece: str, faces: list[Face] | list, face_names: Mapping[str, Sequence[float]]
) -> list[str]:
    order = sorted(range(len(faces)), key=lambda i: tuple(-np.round(faces[i].normal, 9)))
    names = [""] * len(faces)
    for k, i in enumerate(order):
        names[i] = f"f{k}"
    named: dict[int, str] = {}
    for label, direction in face_names.items():
        d = np.asarray(direction, dtype=float)
        if d.shape != (3,) or not np.isfinite(d).all() or not np.abs(d).max() > 0:
            raise GeometryError(f"piece {piece!r}: face {label!r} needs a nonzero 3-vector normal")
        d = d / np.abs(d).max()  # first to the unit box: [1e308, 1e308, 0] has no finite norm
        d = d / np.linalg.norm(d)
        angles = [np.arccos(np.clip(f.normal @ d, -1, 1)) for f in faces]
        best = int(np.argmin(angles))
        if angles[best] > NAME_MATCH_ANGLE:
            raise GeometryError(
                f"piece {piece!r}: no facet has the normal {d.round(4).tolist()} given for "
                f"face {label!r}"
            )
        if best in named:
            raise GeometryError(
                f"piece {piece!r}: faces {named[best]!r} and {label!r} name the same facet"
            )
        named[best] = label
        names[best] = label
    if len(set(names)) != len(names):
        raise GeometryError(f"piece {piece!r}: two faces share a name in {sorted(names)}")
    return names


def smooth_surfaces(
    piece: ConvexPiece, spread: float | None = None, keep: frozenset[str] = frozenset()
) -> ConvexPiece:
    """``piece`` with each smooth surface's unnamed facets (joined by edges, normals within
    ``SMOOTH_ANGLE``) renamed to its first facet's name (the lowest ``f`` number). With
    ``spread``, a surface is cut into patches whose normals all lie within it of each other
    (each facet, in order, joins the first patch it touches and fits). Faces the task file
    named, and those in ``keep`` (a goal given as ``piece/f7``), join nothing."""
    faces = piece.faces
    labels = [f.name.rpartition("/")[2] for f in faces]
    unnamed = [
        i
        for i, label in enumerate(labels)
        if UNNAMED.fullmatch(label) and faces[i].name not in keep
    ]
    graph = nx.Graph()
    graph.add_nodes_from(unnamed)
    cos = np.cos(SMOOTH_ANGLE)
    by_edge: dict[tuple[int, int], list[int]] = {}  # each hull edge: the two faces along it
    for i in unnamed:
        ring = faces[i].vertices
        for u, v in zip(ring, ring[1:] + ring[:1], strict=True):
            by_edge.setdefault((min(u, v), max(u, v)), []).append(i)
    for pair in by_edge.values():
        if len(pair) == 2 and faces[pair[0]].normal @ faces[pair[1]].normal >= cos:
            graph.add_edge(*pair)
    names = [f.name for f in faces]
    surfaces: list[set[int]] = list(nx.connected_components(graph))
    if spread is not None:
        surfaces = [patch for s in surfaces for patch in _patches(faces, sorted(s), graph, spread)]
    for surface in surfaces:
        first = min(surface, key=lambda i: int(labels[i][1:]))
        for i in surface:
            names[i] = faces[first].name
    return replace(
        piece, faces=tuple(replace(f, name=n) for f, n in zip(faces, names, strict=True))
    )


def _patches(
    faces: Sequence[Face], members: list[int], graph: nx.Graph, spread: float
) -> list[set[int]]:
    """``members`` (one smooth surface, in order) as patches: a facet joins the first patch
    it shares an edge with whose every normal lies within ``spread`` of its own."""
    patches: list[set[int]] = []
    patch_of: dict[int, int] = {}
    cos = np.cos(spread)
    for i in members:
        touching = sorted({patch_of[j] for j in graph.neighbors(i) if j in patch_of})
        for k in touching:
            if all(faces[i].normal @ faces[j].normal >= cos for j in patches[k]):
                patches[k].add(i)
                patch_of[i] = k
                break
        else:
            patch_of[i] = len(patches)
            patches.append({i})
    return patches


@dataclass(frozen=True)
class Part:
    """A rigid part: a union of convex pieces in one frame."""

    name: str
    pieces: tuple[ConvexPiece, ...]

    def __post_init__(self) -> None:
        names = [p.name for p in self.pieces]
        if len(set(names)) != len(names):
            twice = sorted({n for n in names if names.count(n) > 1})
            raise GeometryError(f"part {self.name!r}: piece names must be unique: {listed(twice)}")
        if not self.pieces:
            raise GeometryError(f"part {self.name!r} has no pieces")

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The corners (min, max) of the part's vertices' bounding box [m, part frame]."""
        points = np.concatenate([p.vertices for p in self.pieces])
        return points.min(axis=0), points.max(axis=0)

    def centre(self) -> np.ndarray:
        """Centre of the bounding box: where the simulator puts the part's mass (and the
        plan file its payload's centre of mass)."""
        low, high = self.bounds()
        return (low + high) / 2

    @property
    def face_names(self) -> list[str]:
        return [f.name for p in self.pieces for f in p.faces]

    def face(self, name: str) -> Face:
        return self.piece(name).face(name)

    def piece(self, face_name: str) -> ConvexPiece:
        """The piece that holds the face ``face_name`` ("piece/face")."""
        piece_name = face_name.split("/", 1)[0]
        for piece in self.pieces:
            if piece.name == piece_name:
                return piece
        known = listed(p.name for p in self.pieces)
        raise GeometryError(
            f"part {self.name!r} has no piece {piece_name!r} (faces are PIECE/FACE); "
            f"pieces: {known}"
        )


#: The collision margin PyBullet's URDF loader gives a convex mesh [m]: the shape collides
#: as its hull grown by this much (rounded at edges and corners).
URDF_MESH_MARGIN_M = 0.001


def inset(piece: ConvexPiece, depth: float) -> ConvexPiece:
    """``piece`` with every face moved ``depth`` [m] inwards (outwards where negative; a
    piece thinner than twice that has nothing left: an error naming it)."""
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
