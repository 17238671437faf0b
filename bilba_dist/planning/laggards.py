"""Which motion MakeContact takes when none brings every particle into the contact.

It takes the one that brought most particles in, unless that one pushed a laggard (a
particle not yet in the contact) past the plane of the contact's environment face: a peg
resting on top of the wall whose inner face is the contact, say. Such a particle reaches
the face only by moving back over the edge first, and the motion that would do it pulls
the particles already in the contact away from the face, so the next motion almost never
adds it and the contact fails. A motion is ranked by the particles it brought in less the
laggards it left past the face (then fewer of those, the check particles it brought in,
and its score); none that lost a particle already in is preferred to one that kept them.
"""

from collections.abc import Callable

import numpy as np
import pinocchio as pin

from bilba_dist.belief.state import Accept, Belief
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.piece import Face
from bilba_dist.planning.evaluate import Scored
from bilba_dist.task.loader import Task

#: A particle is past the face when its part crosses the face's plane by more than this [m].
PAST_M = 1e-3

Rank = tuple[bool, int, int, int, float]


def past_face(task: Task, mode: ContactPair, X_OM: pin.SE3) -> bool:
    """Whether the manipuland piece of ``mode``, at ``X_OM``, lies past the plane of the
    mode's environment face: the face's C-obs facet ``n·p = offset + max_m −n·(R m)``
    (the piece's vertices ``m`` at rotation ``R``) has the part on its inner side."""
    return _past(*_face_and_piece(task, mode), X_OM)


def laggards_past(task: Task, belief: Belief, mode: ContactPair, accept: Accept) -> int:
    """Particles of ``belief`` not in ``accept`` that lie past ``mode``'s environment face."""
    return _laggards_past(_face_and_piece(task, mode), belief, accept)


def step_rank(
    task: Task, before: int, mode: ContactPair, accept: Accept
) -> Callable[[Scored], Rank]:
    """The key MakeContact ranks scored motions by when none won; ``before``: particles in
    ``accept`` before the motion. Each motion is ranked once (the GP rounds rank the
    sampled ones again)."""
    plane, ranks = _face_and_piece(task, mode), dict[int, Rank]()

    def rank(s: Scored) -> Rank:
        if id(s) not in ranks:
            assert s.posterior is not None
            past = _laggards_past(plane, s.posterior, accept)
            ranks[id(s)] = (s.count >= before, s.count - past, -past, s.checked, s.score)
        return ranks[id(s)]

    return rank


def _face_and_piece(task: Task, mode: ContactPair) -> tuple[Face, np.ndarray]:
    """``mode``'s environment face and its manipuland piece's vertices (part frames)."""
    return task.environment.face(mode.env), task.manipuland.piece(mode.manip).vertices


def _past(face: Face, vertices: np.ndarray, X_OM: pin.SE3) -> bool:
    reach = float(np.max(-(vertices @ X_OM.rotation.T) @ face.normal))
    return float(face.normal @ X_OM.translation) - face.offset - reach < -PAST_M


def _laggards_past(plane: tuple[Face, np.ndarray], belief: Belief, accept: Accept) -> int:
    return sum(
        _past(*plane, belief.X_OM(i))
        for i, contacts in enumerate(belief.contacts)
        if not contacts & accept
    )
