"""The task file, as typed models. Unknown keys and wrong types are errors.

Lengths accept ``m cm mm`` and angles ``deg rad`` (bare numbers are metres and radians).
Planner parameters default to the values of the authors' implementation
(docs/reference-values.md).
"""

import math
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    ValidationInfo,
    field_validator,
    model_validator,
)

from bilba_dist.task.units import (
    Angle,
    JointAngle,
    Length,
    parse_angle,
    parse_fraction,
    parse_length,
    within,
)

AXES = ("x", "y", "z", "roll", "pitch", "yaw")
ANGULAR_AXES = ("roll", "pitch", "yaw")
#: Physical parameters as uncertainty axes: a relative spread of the task's friction
#: coefficient and of the manipuland's mass (``friction: 50%`` is μ from 0.5 μ to 1.5 μ).
PHYSICAL_AXES = ("friction", "mass")
#: The largest relative spread of a physical axis (at 100 % the friction or mass reaches 0).
MAX_PHYSICAL_SPREAD = 0.9


#: Uncertainty bounds and particle offsets: positions within 10 cm, angles within 45° (more
#: than the parts' own size or a quarter turn is no belief a compliant motion can funnel).
MAX_OFFSET_M = 0.1
MAX_OFFSET_RAD = math.pi / 4
#: Particles in a belief: each costs a rollout per candidate motion.
MAX_PARTICLES = 256
#: The longest one compliant motion may run [s] (task files and plan files).
MAX_MOTION_TIMEOUT_S = 60.0
#: The physics time steps a task (or `bilba validate --timestep`) may ask for [s].
TIMESTEP_RANGE_S = (1e-4, 0.02)


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class PoseSpec(Strict):
    """A pose: translation [m] and roll-pitch-yaw [rad] (Z·Y·X order)."""

    xyz: tuple[Length, Length, Length] = (0.0, 0.0, 0.0)
    rpy: tuple[Angle, Angle, Angle] = (0.0, 0.0, 0.0)


class BoxSpec(Strict):
    size: tuple[Length, Length, Length]


class ConvexSpec(Strict):
    vertices: list[tuple[Length, Length, Length]] = Field(min_length=4, max_length=100_000)
    faces: dict[str, tuple[float, float, float]] = Field(
        default_factory=dict, description="face name -> outward normal in the piece frame"
    )


class MeshSpec(Strict):
    """A convex part from a mesh file (STL, OBJ, PLY, …; a path relative to the task file),
    its coordinates multiplied by ``scale`` to get metres. Loading replaces it by the
    ``convex`` piece it describes, so a loaded task carries the vertices, not the path."""

    file: str = Field(min_length=1)
    scale: float = Field(default=1.0, gt=0)
    faces: dict[str, tuple[float, float, float]] = Field(
        default_factory=dict, description="face name -> outward normal in the piece frame"
    )


SHAPES = ("box", "convex", "mesh")
#: Pieces a part may have (a mesh file's objects each count as one).
MAX_PIECES = 500
#: Environment pieces × manipuland pieces: the C-obstacles of a slice. The time to build
#: one grows faster than their number: 63 took 24 s, 126 84 s (a plate split by CoACD
#: against a one- and a two-piece peg), so 256 is minutes and 1 400 hours.
MAX_PIECE_PAIRS = 256


def piece_pairs_problem(env: int, manip: int) -> str:
    """Why ``env`` environment pieces against ``manip`` manipuland pieces are too many
    (the C-obstacles of a slice); empty when they are not."""
    if env * manip <= MAX_PIECE_PAIRS:
        return ""
    return (
        f"{env} environment pieces × {manip} manipuland pieces = {env * manip} C-obstacles, "
        f"over {MAX_PIECE_PAIRS}: a C-obs slice takes minutes at ~100 and grows faster than "
        "their number; merge pieces (a coarser CoACD threshold, fewer objects)"
    )


class PieceSpec(Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9_\-]+$")
    box: BoxSpec | None = None
    convex: ConvexSpec | None = None
    mesh: MeshSpec | None = None
    pose: PoseSpec = PoseSpec()

    @model_validator(mode="after")
    def _one_shape(self) -> "PieceSpec":
        if sum(getattr(self, shape) is not None for shape in SHAPES) != 1:
            raise ValueError(f"piece {self.name!r} needs exactly one of 'box', 'convex', 'mesh'")
        return self


class PartSpec(Strict):
    name: str
    pieces: list[PieceSpec] = Field(min_length=1, max_length=MAX_PIECES)
    mass: float = Field(
        default=0.5, gt=0, le=3.0, description="[kg]; used for the manipuland (Panda payload ≤ 3)"
    )


class RobotStartSpec(Strict):
    """Where the robot starts: the gripper pose ``X_WG``, or Panda joint angles [rad] (then
    the gripper pose is their forward kinematics). Given both, the joints seed the IK."""

    gripper: PoseSpec | None = None
    joints: (
        tuple[JointAngle, JointAngle, JointAngle, JointAngle, JointAngle, JointAngle, JointAngle]
        | None
    ) = None

    @model_validator(mode="after")
    def _one_given(self) -> "RobotStartSpec":
        if self.gripper is None and self.joints is None:
            raise ValueError("give the start as 'gripper' (a pose) or 'joints' (7 angles)")
        return self


class GoalSpec(Strict):
    env: str = Field(description="environment face, 'piece/face'")
    manip: str = Field(description="manipuland face, 'piece/face'")


class AxisBelief(Strict):
    generator: Literal["axis"] = "axis"
    points: int = Field(
        default=3,
        ge=3,
        le=51,
        description="particles along each bounded axis, the nominal one included: 3 is −n, 0, "
        "+n (the paper's); 5 adds ±n/2, and so on, evenly spaced",
    )

    @field_validator("points")
    @classmethod
    def _odd(cls, points: int) -> int:
        if points % 2 == 0:
            raise ValueError(f"must be odd (the nominal particle and ± pairs), got {points}")
        return points


class ExtremalRandomBelief(Strict):
    generator: Literal["extremal+random"]
    random: int = Field(default=8, ge=0, le=MAX_PARTICLES)
    seed: int = Field(default=0, ge=0, lt=2**32)


class ParticleOffset(Strict):
    """One particle as offsets from the nominal grasp and environment pose, per axis."""

    grasp: dict[str, float] = Field(default_factory=dict)
    env: dict[str, float] = Field(default_factory=dict)

    @field_validator("grasp", "env", mode="before")
    @classmethod
    def _axis_values(cls, offsets: object, info: ValidationInfo) -> dict[str, float]:
        return parse_axis_values(offsets, prefix=f"{info.field_name}.")


class ExplicitBelief(Strict):
    generator: Literal["explicit"]
    particles: list[ParticleOffset] = Field(min_length=1, max_length=MAX_PARTICLES)


def _generator(belief: object) -> object:
    """The belief's generator; ``axis`` when a mapping leaves it out (``belief: {points:
    5}``, as the verification warning advises)."""
    if isinstance(belief, dict):
        return belief.get("generator", "axis")
    return getattr(belief, "generator", None)


BeliefSpec = Annotated[
    Annotated[AxisBelief, Tag("axis")]
    | Annotated[ExtremalRandomBelief, Tag("extremal+random")]
    | Annotated[ExplicitBelief, Tag("explicit")],
    Discriminator(
        _generator,
        custom_error_type="belief_generator",
        custom_error_message="write a mapping whose generator is axis (the default), "
        "extremal+random or explicit",
    ),
]


#: The authors' settings where ours differ (docs/reference-values.md): ``planner: {preset:
#: paper}`` in a task file, or ``bilba plan --preset paper``, to reproduce the paper. Keys a
#: task file also gives win over the preset.
PAPER_PLANNER: dict[str, Any] = {
    "sample_patience": 0,  # score every sampled setpoint
    "race_contacts": 0,  # follow Dijkstra's schedule alone
    "prune_rounds": 1,  # stop when pruning leaves no schedule
    "keep_reached": False,  # start over from the initial belief after every pruned edge
    "n_attempts": 50,
    "gp_patience": 3,  # always run the 3 GP rounds
    "near_edge_m": 0.0,  # modes joined only where they share a vertex
    "fail_cost": 0.0,  # a failed contact costs no more (its failed edge alone is pruned)
    "setpoint_press_m": 0.003,  # "slightly inside" (the paper gives no figure)
    "check_friction": 0.0,  # plan at the task's friction, no check particles
    "verify_particles": 0,  # return the first plan found
}

PRESETS: dict[str, dict[str, Any]] = {"default": {}, "paper": PAPER_PLANNER}


class PlannerParams(Strict):
    """The planner's parameters. The defaults are ours, chosen on generated tasks nobody tuned
    (benchmarks/generality.py; benchmarks/README.md); ``preset: paper`` gives the authors'
    (docs/reference-values.md), which the fields' comments name where they differ."""

    preset: Literal["default", "paper"] = "default"

    @model_validator(mode="before")
    @classmethod
    def _apply_preset(cls, data: Any) -> Any:
        preset = data.get("preset") if isinstance(data, dict) else None
        # `preset in PRESETS` on a list raises TypeError, which pydantic passes through
        if isinstance(preset, str) and preset in PRESETS:
            return {**PRESETS[preset], **data}
        return data

    n_free: int = Field(default=3, ge=1, le=100)
    delta_proj: float = Field(default=1e-4, ge=0, le=1)
    min_mode_vertices: int = Field(default=4, ge=1, le=1000)
    # Also join two modes whose C-obs regions come within this distance [m]: the short
    # free-space move between them (a part sliding off a bar's top into a slot just beside
    # it), which vertex sharing alone misses (ours; the authors' graph: 0). 0.6 mm, just over
    # the puzzle's 0.5 mm side clearances, also took the generated family from 60 to 62 of
    # 63 plans (benchmarks/README.md, Tasks nobody tuned; docs/design.md).
    near_edge_m: float = Field(default=0.0006, ge=0, le=0.05)
    # Entering a mode costs this much more (a hop costs about 1) for each edge into it pruned
    # so far, up to 3 (ours; the authors: 0): of schedules as short, those that avoid
    # contacts that failed come first. The puzzle's slot contacts failed from one bar top
    # after another, up to 13 times a run; at 0.1 its grasp.x ±1 cm took 0.75x the
    # rollouts, generated tasks 0.89x, the peg's ±2 cm cells 1.2x (docs/planner.md).
    fail_cost: float = Field(default=0.1, ge=0, le=10)
    # Schedule attempts (each ends with a pruned edge or a plan); 0, the default, is no limit
    # but the timeout (ours; the authors stop after 50).
    n_attempts: int = Field(default=0, ge=0, le=100_000)
    # When pruning has left no schedule from free, put the pruned edges back and go on, up
    # to this many rounds in all; 0, the default, until the timeout (ours; the authors stop
    # there: 1). MakeContact samples: an edge it failed once may work from a later belief or
    # draw, so a search that ran out of schedules after 40 s of a 900 s budget goes on.
    prune_rounds: int = Field(default=0, ge=0, le=100)
    # After a pruned edge, go on from the contact the belief had reached, on the next
    # schedule from there, while one is left; else start over from the initial belief (ours;
    # the authors always start over: false). The puzzle's grasp.pitch ±2° reaches the frame's
    # neck contacts with every particle and then fails the last one: starting over, no run of
    # 6 planned within 300 s; going on, 3 did, at 1.1-1.5x the rollouts on cells that
    # already planned (benchmarks/HISTORY.md).
    keep_reached: bool = True
    timeout_s: float = Field(default=900.0, gt=0, le=7 * 86400)
    setpoints_per_particle: int = Field(default=32, ge=1, le=4096)
    noisy_setpoints: int = Field(default=32, ge=0, le=4096)
    setpoint_noise_m: float = Field(default=0.01, ge=0, le=0.1)
    # Surface samples are pushed inside the C-obs by a depth uniform up to this [m] (the
    # paper's "slightly inside", no figure given). Deeper presses push harder along the
    # contact's normal, which a slide that must beat friction needs: 2 cm (ours) is what the
    # puzzle needed and what the generated family did best with (benchmarks/HISTORY.md).
    setpoint_press_m: float = Field(default=0.02, ge=0, le=0.05)
    # Stop scoring sampled setpoints once this many in a row bring no better score, and go
    # on to the GP rounds (ours; 0 scores every sample, as the authors do). On the peg 3-4x
    # fewer rollouts, every run successful; the puzzle ~2.5x faster (benchmarks/HISTORY.md).
    sample_patience: int = Field(default=16, ge=0, le=100_000)
    # Before the full MakeContact, race the next contacts of up to this many schedules as
    # short as Dijkstra's (whose tie-break picks among them): race_chunks chunks of sampled
    # setpoints each, in turn, no GP; follow the first motion that brings every particle in
    # (ours; 0 or 1 follows Dijkstra's schedule alone, as the authors do).
    race_contacts: int = Field(default=3, ge=0, le=100)
    race_chunks: int = Field(default=2, ge=1, le=100)
    gp_test_points: int = Field(default=1000, ge=1, le=100_000)
    gp_noise: float = Field(default=0.02, ge=0, le=1)
    gp_simulated: int = Field(default=31, ge=1, le=4096)
    gp_rounds: int = Field(default=3, ge=0, le=100)
    # Stop the GP rounds after this many in a row that bring no better score (ours; the
    # authors always run gp_rounds: set gp_patience = gp_rounds for their behaviour).
    gp_patience: int = Field(default=1, ge=1, le=100)
    gp_restarts: int = Field(default=9, ge=0, le=100)
    motion_timeout_s: float = Field(default=5.0, gt=0, le=MAX_MOTION_TIMEOUT_S)
    # The physics step [s]. Unset (the default), it is read off the parts when the task is
    # loaded: 1/120 s where the goal leaves the part 5 mm of play or more (the peg), 1/240 s
    # otherwise (the puzzle, the hex peg); plans are verified at 1/240 s either way
    # (bilba_dist/task/timestep.py, docs/physics.md). The authors used 0.005 s in Drake.
    sim_timestep_s: float | None = Field(
        default=None, ge=TIMESTEP_RANGE_S[0], le=TIMESTEP_RANGE_S[1]
    )
    # Panda: move the joint reference through IK waypoints on the hand's straight line
    # (ours; off = a straight line in joint space, which bows the hand ~2 mm on an 8 cm
    # move). docs/physics.md.
    cartesian_ramp: bool = False
    # In contact when closer than this. The authors used 1 mm in Drake; in PyBullet a resting
    # contact sits at about -0.01 mm, and a 1 mm threshold flips on pegs resting 0.99 mm
    # from a wall (measured: early-stopped vs full-length rollouts disagreed on 1 in 50).
    contact_distance_m: float = Field(default=2e-4, ge=0, le=0.01)
    # Robust acceptance, margin f (ours; the authors: 0, off). The planning particles are
    # simulated at friction x(1 + f), where compliant motions jam, and a motion wins only if
    # it also brings their twins at x1 and x(1 - f) (check particles, simulated from their own
    # states through the plan) into the contact. The peg's seed-0 plans then hold 14 of 14
    # held-out particles at 0.5, 1 and 1.5 times the task's friction (without: 8 of 16 plans
    # lose some at 1.5), at about 2x the planning time (docs/planner.md, Robust acceptance).
    # Off when the uncertainty has a friction axis: its particles span the friction given.
    check_friction: float = Field(default=0.5, ge=0, le=0.9)
    # ... and on this many more check particles drawn inside the pose bounds (a fixed draw),
    # each at friction x(1 - f), x1 and x(1 + f) (0: the planning particles' twins only).
    check_random: int = Field(default=0, ge=0, le=64)
    # Verify a plan before returning it (ours; the authors: 0, off): replay it on this many
    # offsets spread evenly inside the bounds (a fixed, stratified draw), each at friction
    # x(1 - f), x1 and x(1 + f); one that brings fewer than verify_min of them to the goal
    # at some friction is not returned, two of the particles it lost become check particles,
    # and the search goes on from the last contact of that plan they made too (else from the
    # start). The replay spends at most verify_share of the search's rollouts so far (at
    # least one offset). Every verified plan of the puzzle's hard cells (seeds 5-7) then held
    # >= 0.929 of 14 held-out particles at 0.5, 1 and 1.5 μ (docs/planner.md, Verification).
    verify_particles: int = Field(default=14, ge=0, le=256)
    verify_min: float = Field(default=1.0, ge=0, le=1)
    verify_share: float = Field(default=0.2, gt=0, le=100)
    # ... and a search whose plans keep failing verification stops at this many times the
    # time of its first plan (or the timeout, if sooner), returning the one that held best
    # (else the puzzle's env.y ±1 cm, whose plans rarely pass, ran every search to its
    # timeout). 5, not 3: every verified puzzle plan held out held, half the others did not;
    # at 5 the grasp.x ±1 cm cell verified 8 of 10 (6 at 3) for +10 / +21 % median time
    # (benchmarks/HISTORY.md, twenty-ninth session).
    verify_effort: float = Field(default=5.0, ge=1, le=1000)
    # Plan within one Franka driver's form of stiffness and its limits (docs/drivers.md):
    # every candidate K is made what that driver can hold before it is simulated, so the plan
    # exports without approximation. "none": any symmetric PSD K (what franky takes).
    driver: Literal["none", "franky", "panda-py", "libfranka", "franka-ros"] = "none"
    # The driver's EE (Desk's TCP) origin in the panda_hand frame [m]: the Franka Hand's
    # default is 0.1034 m along z. Used with `driver`, and by `bilba export`.
    ee_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.1034)

    @field_validator("ee_offset_m")
    @classmethod
    def _offset_range(cls, value: tuple[float, float, float]) -> tuple[float, float, float]:
        if max(abs(v) for v in value) > 0.5:
            raise ValueError("the EE offset must be within 0.5 m of panda_hand on each axis")
        return value


class TaskSpec(Strict):
    name: str
    description: str = ""
    manipuland: PartSpec
    environment: PartSpec
    grasp: PoseSpec = Field(description="nominal X_GM")
    environment_pose: PoseSpec = Field(description="nominal X_WO")
    robot_start: RobotStartSpec
    goal: GoalSpec
    friction: float = Field(gt=0, le=2.0, description="Coulomb μ, in (0, 2]")
    uncertainty: dict[str, float] = Field(default_factory=dict)
    belief: BeliefSpec = AxisBelief()
    planner: PlannerParams = PlannerParams()

    @field_validator("uncertainty", mode="before")
    @classmethod
    def _bounds(cls, bounds: object) -> dict[str, float]:
        values = parse_axis_values(bounds, prefix="")
        negative = [k for k, v in values.items() if v < 0]
        if negative:
            raise ValueError(f"uncertainty bounds must be >= 0: {', '.join(negative)}")
        return values

    @property
    def bounds(self) -> dict[str, float]:
        """The uncertain axes and their bounds: the uncertainty's axes with a bound above 0,
        in the task file's order (an axis overridden to 0 is certain)."""
        return {k: v for k, v in self.uncertainty.items() if v > 0}

    @model_validator(mode="after")
    def _piece_pairs(self) -> "TaskSpec":
        # as listed: a mesh piece may hold several objects, counted again once loaded
        problem = piece_pairs_problem(len(self.environment.pieces), len(self.manipuland.pieces))
        if problem:
            raise ValueError(problem)
        return self

    @model_validator(mode="after")
    def _particle_count(self) -> "TaskSpec":
        n = particle_count(self.belief, len(self.bounds))
        if n > MAX_PARTICLES:
            raise ValueError(
                f"belief: {n} particles, over the limit of {MAX_PARTICLES} (each costs a "
                "rollout per candidate motion); fewer points or axes"
            )
        return self


def particle_count(belief: "AxisBelief | ExtremalRandomBelief | ExplicitBelief", axes: int) -> int:
    """How many particles a belief generator makes over ``axes`` bounded axes."""
    if isinstance(belief, ExplicitBelief):
        return len(belief.particles)
    if isinstance(belief, ExtremalRandomBelief):
        return 2 * axes + belief.random
    return 1 + (belief.points - 1) * axes


def axis_unit(axis: str) -> tuple[str, float]:
    """The unit an offset on ``axis`` is shown in, and how many of it make one SI unit:
    ("mm", 1000), ("deg", 180/π) or ("%", 100)."""
    frame, name = check_axis_key(axis)
    if frame == "physical":
        return "%", 100.0
    return ("deg", 180 / math.pi) if name in ANGULAR_AXES else ("mm", 1000.0)


def parse_axis_values(values: object, prefix: str) -> dict[str, float]:
    """Read ``{axis: quantity}`` with the unit kind each axis needs (length or angle)."""
    if values is None:
        return {}
    if not isinstance(values, dict):
        raise ValueError(f"expected a mapping of axis to value, got {values!r}")
    parsed = {}
    for key, value in values.items():
        frame, axis = check_axis_key(f"{prefix}{key}")
        angular = axis in ANGULAR_AXES
        parse = parse_angle if angular else parse_length
        check = _ANGLE_OFFSET if angular else _LENGTH_OFFSET
        if frame == "physical":
            parse, check = parse_fraction, _SPREAD
        try:
            parsed[str(key)] = check(parse(value))
        except ValueError as exc:
            raise ValueError(f"{prefix}{key}: {exc}") from None
    return parsed


_LENGTH_OFFSET = within(MAX_OFFSET_M, "cm", 0.01)
_ANGLE_OFFSET = within(MAX_OFFSET_RAD, "deg", math.pi / 180)
_SPREAD = within(MAX_PHYSICAL_SPREAD, "%", 0.01)


def check_axis_key(key: str) -> tuple[str, str]:
    """Split ``grasp.pitch`` into ("grasp", "pitch"), ``friction`` into ("physical",
    "friction"), or raise ValueError naming the choices."""
    if key in PHYSICAL_AXES:
        return "physical", key
    frame, _, axis = key.partition(".")
    if frame not in ("grasp", "env") or axis not in AXES:
        raise ValueError(
            f"unknown uncertainty axis {key!r}; use grasp.AXIS or env.AXIS with AXIS one of "
            f"{', '.join(AXES)}, or {' or '.join(PHYSICAL_AXES)}"
        )
    return frame, axis
