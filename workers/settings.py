"""Numbers of the simulated controllers, with their units. Defaults follow
docs/reference-values.md and the measurements in docs/physics.md."""

from dataclasses import dataclass, replace


@dataclass(frozen=True)
class SimSettings:
    timestep_s: float = 1 / 240  # the worker sets these two from the task's planner
    contact_distance_m: float = 2e-4  # parameters: a pair closer than this is in contact
    spring_limit: float = 20.0  # norm clip of the 6-D spring wrench [N, N·m]
    ramp_speed_m_s: float = 0.1  # setpoint ramp: translation speed ...
    ramp_speed_rad_s: float = 0.5  # ... and rotation speed; the slower one sets the time
    min_ramp_s: float = 0.2
    ramp_blend_s: float = 0.0  # ease the ramp's speed in and out over this long (libfranka)
    cartesian_ramp: bool = False  # Panda: reference through IK waypoints on the hand's
    ramp_waypoint_steps: int = 8  # straight line (SE(3) geodesic), one every N steps
    settle_window_s: float = 0.25  # stop once still this long after the ramp ends
    settle_joint_speed: float = 2e-3  # "still" for the Panda: every |dq| below [rad/s]
    settle_speed_m_s: float = 1e-3  # "still" for the floating part [m/s] ...
    settle_speed_rad_s: float = 1e-2  # ... and [rad/s]
    early_stop: bool = True
    null_stiffness: float = 10.0  # posture spring in the null space [N·m/rad]
    null_damping: float = 1.0  # [N·m·s/rad]
    virtual_mass_kg: float = 8.0  # floating model: the Panda hand's effective inertia
    # (task-space Λ at the peg start: 6–10 kg, 0.6–1.2 kg·m²); too little is unstable
    virtual_inertia_kg_m2: float = 0.8
    gui: bool = False  # open the PyBullet viewer (`bilba execute --gui`; one world per process)


def driver_settings(settings: SimSettings, driver: str) -> SimSettings:
    """``settings`` as a Franka driver runs a motion: every exported script ramps the EE
    setpoint along a straight line, and only franky can bound the spring's wrench."""
    from bilba_dist.robot.drivers import DRIVERS

    settings = replace(settings, cartesian_ramp=True, ramp_blend_s=DRIVERS[driver].ramp_blend_s)
    if not DRIVERS[driver].wrench_clip:
        settings = replace(settings, spring_limit=float("inf"))
    return settings
