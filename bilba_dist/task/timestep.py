"""The physics step a task is planned at when its file does not set one
(``planner.sim_timestep_s``), and the step plans are verified at.

A rollout's cost is nearly all physics steps, and how fine a step must be depends on the
gaps the part has to find: the peg's 5.5 mm of play plans at 120 Hz as it does at 240 Hz
for 0.6x the cost a rollout, the puzzle's 0.5 mm gaps search much harder at 120 Hz
(docs/physics.md). So the step is read off the task's geometry: the goal contact's region
on the C-obstacle slice (at the nominal start rotation) is the set of positions in which
the part is home, and the diameter of the largest circle inside it is its free play there.
A play of at least ``COARSE_PLAY_M`` plans at ``COARSE_STEP_S``; anything else (less play,
or no region found) at ``FINE_STEP_S``. Every plan is verified at the fine step (or the
planning step, where a task sets a finer one), so a plan that only works at the coarse
step is not returned.
"""

import numpy as np
import pinocchio as pin
import shapely

from bilba_dist.cspace.slice import CObsSlice, plane_axes
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.piece import Part

FINE_STEP_S = 1 / 240
COARSE_STEP_S = 1 / 120
#: The goal's free play from which the coarse step is used: at the setpoint ramp's
#: 0.1 m/s the reference moves 0.8 mm a 120 Hz step, a sixth of it.
COARSE_PLAY_M = 0.005


def goal_play(environment: Part, manipuland: Part, goal: ContactPair, X_OM: pin.SE3) -> float:
    """The diameter [m] of the largest circle inside the goal contact's region on the
    C-obstacle slice at ``X_OM``'s rotation (0 when the slice has no such region)."""
    triangles, normals = CObsSlice.build(environment, manipuland, X_OM.rotation).mode_triangles(
        goal
    )
    play = 0.0
    for normal in np.unique(np.round(normals, 6), axis=0):
        on = np.all(np.isclose(normals, normal, atol=1e-6), axis=1)
        e1, e2 = plane_axes(normal[None])
        region = shapely.union_all(
            [shapely.Polygon(np.c_[t @ e1[0], t @ e2[0]]) for t in triangles[on]]
        )
        if region.is_empty or region.area <= 0:
            continue
        radius = shapely.maximum_inscribed_circle(region, tolerance=1e-6).length
        play = max(play, 2 * radius)
    return play


def auto_timestep(environment: Part, manipuland: Part, goal: ContactPair, X_OM: pin.SE3) -> float:
    """The step a task without ``planner.sim_timestep_s`` is planned at (module docstring)."""
    play = goal_play(environment, manipuland, goal, X_OM)
    return COARSE_STEP_S if play >= COARSE_PLAY_M else FINE_STEP_S


def verify_timestep(planning_step_s: float) -> float:
    """The step plans are verified at: the fine step, or the planning step if finer."""
    return min(planning_step_s, FINE_STEP_S)
