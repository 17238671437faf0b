"""Contact sets from contact points: the rule both the simulator and tests use.

On each side, a point names the faces it lies on that face the other part: those whose
outward normal is within 3° of the contact normal. If none does, the point is on an edge or
a corner of that side, and every face through it counts (2 on an edge, 3 at a corner).
So a peg lying flat on a floor names (floor, peg bottom) even at its corners, while a tilted
peg touching by its corner names the three faces there — the same labels the C-obs facets
carry (face–face, face–corner), so geometry and physics agree.
"""

from collections.abc import Sequence

import numpy as np

from bilba_dist.geometry.contact import ContactPair, ContactSet
from bilba_dist.geometry.piece import ConvexPiece, Part

#: A point within this of a face's plane lies on it [m]. Generous because PyBullet rounds a
#: box's edges by its ~1 mm collision margin against convex meshes (the manipuland is a robot
#: link, whose margin cannot be zeroed): an edge contact lands ~0.3 mm off both faces. Face
#: contacts are unaffected: their normal picks the one face.
ON_FACE_TOL = 1.5e-3
#: On either side, faces within this angle of the contact normal are "the" face [rad].
NORMAL_ANGLE = np.deg2rad(3.0)


def named_faces(pieces: Sequence[ConvexPiece], point: np.ndarray, normal: np.ndarray) -> list[str]:
    """The faces of ``pieces`` a contact at ``point`` names; ``normal`` is the outward
    normal the contact has on this side (both in the pieces' frame)."""
    through = [(piece, i) for piece in pieces for i in piece.faces_at(point, ON_FACE_TOL)]
    aligned = [
        (piece, i) for piece, i in through if piece.faces[i].normal @ normal >= np.cos(NORMAL_ANGLE)
    ]
    return sorted({piece.faces[i].name for piece, i in (aligned or through)})


def label_points(
    env_piece: ConvexPiece,
    manipuland: Part,
    points_O: np.ndarray,
    normals_O: np.ndarray,
    points_M: np.ndarray,
    R_OM: np.ndarray,
) -> ContactSet:
    """The contact set of contact points between one environment piece and the manipuland:
    ``points_O`` on the environment (its frame), ``points_M`` the matching points on the
    manipuland (its frame), ``normals_O`` from the environment towards the manipuland, and
    ``R_OM`` the manipuland's rotation in the environment frame."""
    pairs: set[ContactPair] = set()
    for p_O, n_O, p_M in zip(points_O, normals_O, points_M, strict=True):
        n_M = -(R_OM.T @ n_O)  # the manipuland's outward normal there, in its frame
        for e in named_faces([env_piece], p_O, n_O):
            for m in named_faces(manipuland.pieces, p_M, n_M):
                pairs.add(ContactPair(e, m))
    return frozenset(pairs)
