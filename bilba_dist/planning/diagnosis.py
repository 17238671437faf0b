"""Why no plan was found, in terms a user can act on: which contact blocked the search, and
why it could not be made — no region at the particles' rotations, the best single motion
bringing only k of n particles in (or all n, but not all the check particles of robust
acceptance), the belief spread wider than the contact's region."""

from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial.distance import pdist

from bilba_dist.belief.state import Belief
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.pose import transform_points
from bilba_dist.modes.schedule import SliceCache
from bilba_dist.planning.setpoints import start_rotation

if TYPE_CHECKING:
    from bilba_dist.task.loader import Task

#: The share of a blocked contact's rollouts that must end with the arm or hand touching the
#: environment for the diagnosis to name it.
ARM_SHARE = 0.25


@dataclass(frozen=True)
class Blocked:
    """One failed attempt to make ``contact`` from a belief of ``n`` particles."""

    contact: ContactPair
    reached: int  # particles in the contact (or past it) after the best motions
    n: int
    no_region: int  # particles at whose rotation (and start rotation) the contact has no region
    spread_m: float  # largest distance between two particles' part positions (env frame)
    region_m: float  # the contact region's largest extent (first particle that has one)
    checked: int = 0  # check particles (robust acceptance) in the contact
    n_check: int = 0  # check particles in all (0: robust acceptance off)
    rollouts: int = 0  # rollouts the attempt took
    arm_touching: int = 0  # ... of which ended with the arm or hand touching the environment
    arm_piece: str = ""  # the piece it touched most


def _diameter(points: np.ndarray) -> float:
    return float(pdist(points).max()) if len(points) > 1 else 0.0


def blocked(
    cache: SliceCache,
    belief: Belief,
    contact: ContactPair,
    reached: int,
    checked: int = 0,
    arm: tuple[int, int, str] = (0, 0, ""),
) -> Blocked:
    """What stood in the way of ``contact`` from ``belief`` (no random draws: the planner's
    generator is untouched); ``arm``: the attempt's rollouts, how many ended with the arm or
    hand touching the environment, and the piece it touched most."""
    positions, no_region = [], 0
    region_m = 0.0
    for i, particle in enumerate(belief.particles):
        X_OM = belief.X_OM(i)
        positions.append(X_OM.translation)
        triangles = cache.get(X_OM.rotation).mode_triangles(contact)[0]
        if not len(triangles):  # as the sampler does: try the start rotation (then it
            # samples at the nominal part's, turning this part: not a region of its own)
            start = start_rotation(particle, cache.task.X_WG0)
            triangles = cache.get(start).mode_triangles(contact)[0]
        if not len(triangles):
            no_region += 1
        elif region_m == 0.0:
            region_m = _diameter(np.unique(triangles.reshape(-1, 3), axis=0))
    n_check = len(belief.check) if belief.check is not None else 0
    spread_m = _diameter(np.array(positions))
    return Blocked(
        contact, reached, len(belief), no_region, spread_m, region_m, checked, n_check, *arm
    )


def explain(failures: list[Blocked]) -> str:
    """One sentence on the contact that blocked most attempts (ties: the latest)."""
    if not failures:
        return ""
    counts = Counter(f.contact for f in failures)
    worst = max(counts.values())
    last = next(f for f in reversed(failures) if counts[f.contact] == worst)
    same = [f for f in failures if f.contact == last.contact]
    text = f"blocked by {last.contact} ({worst} of {len(failures)} failed attempts): "
    if last.no_region == last.n:
        return text + (
            "it has no region at the particles' rotations, so the parts cannot touch that way "
            "there (a goal face that meets the other part only when tilted?)"
        )
    best = max(f.reached for f in same)
    if best == last.n and last.n_check:
        checked = max(f.checked for f in same if f.reached == last.n)
        text += (
            f"motions brought all {last.n} particles into it, but no more than {checked} of "
            f"its {last.n_check} check particles (the same parts at other frictions: "
            "planner.check_friction)"
        )
    else:
        text += f"no motion brought more than {best} of {last.n} particles into it"
    if last.no_region:
        text += f"; it has no region at the rotations of {last.no_region} of {last.n} particles"
    rollouts, touching = sum(f.rollouts for f in same), sum(f.arm_touching for f in same)
    if touching and touching >= ARM_SHARE * rollouts:
        piece = Counter(f.arm_piece for f in same if f.arm_piece).most_common(1)[0][0]
        text += (
            f"; {touching} of its {rollouts} rollouts ended with the arm or hand touching the "
            f"environment ({piece} most): the gripper in the way (docs/task-files.md, The "
            "gripper must fit too)"
        )
    elif last.spread_m > last.region_m > 0:  # (the spread is beside the point then)
        text += (
            f"; the particles spread {last.spread_m * 1000:.1f} mm across, wider than its "
            f"region ({last.region_m * 1000:.1f} mm): less uncertainty, or a contact before "
            "it that funnels them (a chamfer), would help"
        )
    return text


def goal_edge_warning(goal: ContactPair, belief: Belief) -> str | None:
    """A warning when a plan's final particles touch the goal's part face with another face
    of the goal's environment piece too — the goal face met at its edge. The built-ins'
    floors fill their holes exactly, and none of 89 of their plans (and of our meshed
    tasks) ends so; a floor as wide as the plate did, the peg hanging on its outer edge."""
    piece = goal.env.split("/")[0]
    edges = {
        i: sorted(
            c
            for c in contacts
            if c.manip == goal.manip and c.env != goal.env and c.env.split("/")[0] == piece
        )
        for i, contacts in enumerate(belief.contacts)
        if goal in contacts
    }
    edges = {i: found for i, found in edges.items() if found}
    if not edges:
        return None
    pairs = sorted({str(c) for found in edges.values() for c in found})
    return (
        f"particles {', '.join(map(str, edges))} end in the goal touching also "
        f"{', '.join(pairs)}: the goal face met at its edge — is {goal.env} exposed outside "
        "the assembly? (docs/task-files.md: a goal face must exist only where the part is home)"
    )


#: A particle that ends touching its goal with less than this share of its part's goal face
#: on the environment's goal face is at the face's edge, not home.
GOAL_OVERLAP_MIN = 0.25


def goal_overlap(task: "Task", belief: Belief, i: int) -> float:
    """The share of the part's goal face (its area) that lies on the environment's goal face,
    for particle ``i`` of ``belief``, both faces projected on the environment face's plane."""
    from shapely.geometry import MultiPoint

    from bilba_dist.planning.stiffness import frame_with_z

    env, manip = task.goal
    env_face, part_face = task.environment.face(env), task.manipuland.face(manip)
    env_piece, part_piece = task.environment.piece(env), task.manipuland.piece(manip)
    X_WO, X_WM = belief.particles[i].X_WO, belief.states[i].X_WM
    R = X_WO.rotation @ frame_with_z(env_face.normal)  # the plane's axes in the world

    def outline(points: np.ndarray) -> Any:
        return MultiPoint((points @ R)[:, :2]).convex_hull

    on_env = outline(transform_points(X_WO, env_piece.vertices[list(env_face.vertices)]))
    part = outline(transform_points(X_WM, part_piece.vertices[list(part_face.vertices)]))
    return float(part.intersection(on_env).area / part.area) if part.area > 0 else 1.0


def goal_overlap_warning(task: "Task", belief: Belief) -> str | None:
    """A warning when a plan's final particles touch the goal with only a sliver of the part's
    goal face on the environment's: a card slid out of an open-ended slot until the fingers
    cleared its walls, its bottom on the floor's last 4 mm (7 %). The built-ins' goals end
    with 90 % or more."""
    shares = {
        i: goal_overlap(task, belief, i)
        for i, contacts in enumerate(belief.contacts)
        if task.goal in contacts
    }
    low = {i: share for i, share in shares.items() if share < GOAL_OVERLAP_MIN}
    if not low:
        return None
    env, manip = task.goal
    return (
        f"particles {', '.join(map(str, low))} end with only "
        f"{min(low.values()):.0%}–{max(low.values()):.0%} of {manip} on {env}: the goal met at "
        "the edge of its face, not home — is the goal face exposed beyond where the part "
        "belongs, or is the gripper in the way there? (docs/task-files.md)"
    )
