"""MakeContact's choice when no motion brings every particle in: laggards pushed past the
contact's environment face count against a motion (planning/laggards.py)."""

import numpy as np
import pinocchio as pin

from bilba_dist.belief.particles import initial_belief
from bilba_dist.belief.state import Belief
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.planning.evaluate import Candidate, Scored
from bilba_dist.planning.laggards import laggards_past, past_face, step_rank
from bilba_dist.rollout import Motion, ParticleState
from bilba_dist.task.loader import load_task, with_planner

TASK = load_task("peg-in-hole", ["grasp.x=2cm"])
INNER = ContactPair("wall_px/inner", "peg/+x")  # the +x wall's inner face at x = 32.75 mm
ACCEPT = frozenset({INNER})
PARTICLES = initial_belief(TASK)


def _at(x: float, z: float = 0.172) -> pin.SE3:
    """The upright peg (30 mm half-width) with its centre at (x, 0, z) in the hole's frame."""
    return pin.SE3(np.eye(3), np.array([x, 0.0, z]))


def _belief(poses: list[pin.SE3], in_contact: list[bool]) -> Belief:
    states = tuple(ParticleState(p.X_WO * X) for p, X in zip(PARTICLES, poses, strict=True))
    contacts = tuple(frozenset({INNER}) if c else frozenset() for c in in_contact)
    return Belief(PARTICLES, states, contacts)


def _scored(belief: Belief, score: float) -> Scored:
    motion = Motion(np.eye(6), pin.SE3.Identity())
    return Scored(Candidate(motion, 0), score, belief.count(ACCEPT), belief)


def test_a_peg_over_the_wall_is_past_its_inner_face_one_in_the_hole_is_not():
    assert past_face(TASK, INNER, _at(0.0123))  # on the chamfer, +x face at 42 mm
    assert not past_face(TASK, INNER, _at(-0.012))  # over the hole, 15 mm short of the face
    assert not past_face(TASK, INNER, _at(0.00275))  # touching the face
    tilted = pin.SE3(pin.rpy.rpyToMatrix(0, np.radians(10), 0), np.array([0.0, 0, 0.172]))
    assert past_face(TASK, INNER, tilted)  # a corner swings 13 mm past the plane


def test_only_laggards_are_counted_past_the_face():
    belief = _belief([_at(0.00275), _at(0.0123), _at(0.0123)], [True, False, True])
    assert laggards_past(TASK, belief, INNER, ACCEPT) == 1


def test_a_motion_that_leaves_a_laggard_past_the_face_ranks_below_one_that_does_not():
    """Both bring 2 of 3 in; the one with the better score left its laggard on the wall."""
    stranded = _scored(_belief([_at(0.00275)] * 2 + [_at(0.0123)], [True, True, False]), 2.5)
    fetchable = _scored(_belief([_at(0.00275)] * 2 + [_at(-0.012)], [True, True, False]), 2.1)
    one_in = _scored(_belief([_at(0.00275)] + [_at(-0.012)] * 2, [True, False, False]), 1.9)
    rank = step_rank(TASK, 0, INNER, ACCEPT)
    assert max([stranded, fetchable, one_in], key=rank) is fetchable
    # two in with one stranded counts as one in: the fetchable single wins the tie
    assert max([stranded, one_in], key=rank) is one_in
    # ... unless it lost a particle that was in before the motion
    assert max([stranded, one_in], key=step_rank(TASK, 2, INNER, ACCEPT)) is stranded


def test_the_peg_with_2_cm_grasp_offsets_plans_without_pruning_an_edge():
    """Seed 3, bilba-fixed, at 240 Hz (the step this case was found at): ranking by count
    alone (the previous code) took motions that left the third peg on the wall top and
    pruned 5 edges (2247 rollouts); now none (243)."""
    from bilba_dist.planning.bilba import plan
    from bilba_dist.workers.rollout_worker import RolloutWorker

    task = with_planner(TASK, sim_timestep_s=1 / 240)
    worker = RolloutWorker(task, "panda")
    result = plan(task, worker, "bilba-fixed", 3, 300)
    worker.close()
    assert result.success and result.pruned == []
