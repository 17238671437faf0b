"""The plan file: versioned JSON holding everything needed to run the motions on a Panda
without the planner or the task file (docs/plan-file.md). Version 2: the frames and axis
order stated in the file; per motion K and its damping D (6×6, rotation first, world axes at
the panda_hand origin), G_d (panda_hand in the world: xyz and quaternion xyzw, plus the
rotation matrix exactly as simulated), q_d, timeout, the contact it should reach and its
score; the start joints, the nominal environment pose X_WO, the payload, the controller's
ramp rates and wrench clip, the driver the plan was made for, and the validated task itself
(its hash checked on reading). Checked on reading against ``plan-v2.schema.json`` (shipped
beside this module). Version 1 files still read."""

import hashlib
import json
from dataclasses import dataclass
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from pydantic import ValidationError

from bilba_dist import __version__
from bilba_dist.errors import BilbaError
from bilba_dist.files import PathArg
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.pose import pose_json, setpoint_json
from bilba_dist.planning.result import PlannedMotion, PlanResult, verification_json
from bilba_dist.rollout import damping, is_symmetric_psd
from bilba_dist.task.loader import Task, build_task, builtin_tasks, load_task
from bilba_dist.task.schema import MAX_MOTION_TIMEOUT_S, TaskSpec
from bilba_dist.task.units import WORKSPACE_M
from bilba_dist.task.yaml_lines import read_text
from bilba_dist.workers.settings import SimSettings

FORMAT = "bilba-plan"
VERSION = 2
READS = (1, 2)
#: How far a G_d rotation may be from orthonormal, or from its quaternion, in a plan file.
ROTATION_TOL = 1e-6
#: How far a stored D may be from 2·sqrtm(K) (relative, max-abs) before the file is refused.
DAMPING_TOL = 1e-6

FRAMES = {
    "world": "panda_link0: the robot's base frame",
    "setpoint": "G_d is the panda_hand frame in the world, not a driver's EE (TCP) frame",
    "stiffness": (
        "K and D act at the panda_hand origin, in world axes, rotation first: [rx, ry, rz, x, y, z]"
    ),
    "units": "m, rad, s, kg; K in N·m/rad and N/m; D in N·m·s/rad and N·s/m",
}


def plan_document(result: PlanResult, task: Task) -> dict[str, Any]:
    """The plan file of ``result``, a plan for ``task``: it embeds the task planned on (the
    result's, where the planner raised its particles), which `bilba validate` replays."""
    from bilba_dist.belief.particles import initial_belief
    from bilba_dist.belief.start import start_state

    task = result.task or task
    particles = initial_belief(task)
    nominal = next((p for p in particles if not any(p.offsets.values())), particles[0])
    settings, planner = SimSettings(), task.spec.planner
    return {
        "format": FORMAT,
        "version": VERSION,
        "frames": FRAMES,
        "robot": {
            "model": "franka-panda",
            "hand_frame": "panda_hand",
            "start_joints": start_state(task, nominal).q.tolist(),
            "driver": None if planner.driver == "none" else planner.driver,
            "ee_offset_m": list(planner.ee_offset_m),
        },
        "environment": {"X_WO": pose_json(task.X_WO)},
        "payload": {
            "mass_kg": task.spec.manipuland.mass,
            "com_hand_m": task.X_GM.act(task.manipuland.centre()).tolist(),
            "X_GM": pose_json(task.X_GM),
        },
        "controller": {
            "damping": "2·sqrtm(K)",
            "ramp": "cartesian" if planner.cartesian_ramp else "joint",
            "ramp_speed_m_s": settings.ramp_speed_m_s,
            "ramp_speed_rad_s": settings.ramp_speed_rad_s,
            "min_ramp_s": settings.min_ramp_s,
            "wrench_clip": settings.spring_limit,
            "null_stiffness": settings.null_stiffness,
            "null_damping": settings.null_damping,
        },
        "task": {
            "name": task.name,
            "hash": task.hash,
            "source": _portable_source(task.source),
            "uncertainty": task.spec.uncertainty,
            "spec": task.spec.model_dump(mode="json"),
        },
        "planner": result.planner,
        "planner_version": __version__,
        "seed": result.seed,
        "parameters": task.spec.planner.model_dump(mode="json"),
        "success": result.success,
        "reason": result.reason,
        "planning_time_s": round(result.planning_time_s, 3),
        "rollouts": result.rollouts,
        "verification": (
            verification_json(result.verification) if result.verification is not None else None
        ),
        "motions": [_motion(m) for m in result.motions],
    }


def _portable_source(source: str) -> str:
    """A built-in task's name, or the task file's name alone: the plan embeds the task, so
    the planning machine's paths stay on it."""
    path = Path(source)
    builtin = {str(p.resolve()): name for name, p in builtin_tasks().items()}
    return builtin.get(str(path.resolve()), path.name) if path.suffix else source


def _motion(m: PlannedMotion) -> dict[str, Any]:
    return {
        "K": np.asarray(m.K).tolist(),
        "D": damping(m.K).tolist(),
        "G_d": setpoint_json(m.G_d),
        "q_d": np.asarray(m.q_d).tolist(),
        "timeout_s": m.timeout_s,
        "contact": {"env": m.contact.env, "manip": m.contact.manip},
        "score": m.score,
    }


def dumps(document: dict[str, Any]) -> str:
    """Canonical text of a plan document (the MCAP log stores the same bytes)."""
    return json.dumps(document, indent=2, sort_keys=True) + "\n"


def write_plan(document: dict[str, Any], path: PathArg) -> None:
    write_plan_text(dumps(document), path)


def write_plan_text(text: str, path: PathArg) -> None:
    """A plan file's text (``dumps`` of its document, e.g. from a Ray task) at ``path``."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise BilbaError(f"{path}: cannot write plan file: {exc.strerror or exc}") from None


@dataclass(frozen=True)
class PlanFile:
    document: dict[str, Any]
    motions: list[PlannedMotion]
    spec: TaskSpec | None = None  # the embedded task, validated on reading (version 2)

    @property
    def task_name(self) -> str:
        return str(self.document["task"]["name"])

    @property
    def uncertainty(self) -> dict[str, float]:
        return dict(self.document["task"].get("uncertainty", {}))

    def task(self, override: str | None = None) -> Task:
        """The plan's task: the one embedded (version 2), else the built-in or file of its
        name with its uncertainty; ``override`` (a name or file) replaces either.

        The embedded task starts from the plan's recorded ``start_joints`` (they seed the start
        IK, which returns them as they are): the robot homes there, so a replay must start
        there too, even where this version's start IK would pick another posture."""
        if override is None and self.spec is not None:
            spec = self.spec
            if self.start_joints is not None:
                start = spec.robot_start.model_copy(update={"joints": tuple(self.start_joints)})
                spec = spec.model_copy(update={"robot_start": start})
            return build_task(spec, str(self.document["task"]["source"]))
        overrides = [f"{k}={v}" for k, v in self.uncertainty.items()]
        return load_task(override or self.task_name, overrides)

    @property
    def start_joints(self) -> np.ndarray | None:
        robot = self.document.get("robot")
        return None if robot is None else np.array(robot["start_joints"], dtype=float)


#: A plan file larger than this is refused unread [bytes].
MAX_PLAN_BYTES = 16 * 2**20


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    keys = [k for k, _ in pairs]
    duplicate = next((k for k in keys if keys.count(k) > 1), None)
    if duplicate is not None:
        raise ValueError(f"duplicate key {duplicate!r}")
    return dict(pairs)


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number a plan may hold")


def read_plan(path: PathArg) -> PlanFile:
    """Read and check a plan file; any problem is one BilbaError line naming the file."""
    path = Path(path)
    text = read_text(path, "plan file", MAX_PLAN_BYTES)
    try:
        document = json.loads(text, object_pairs_hook=_no_duplicates, parse_constant=_no_constant)
    except json.JSONDecodeError as exc:
        raise BilbaError(f"{path}: not a plan file (invalid JSON at line {exc.lineno})") from None
    except ValueError as exc:
        raise BilbaError(f"{path}: not a plan file: {exc}") from None
    except RecursionError:
        raise BilbaError(f"{path}: not a plan file (nested too deeply)") from None
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        raise BilbaError(f'{path}: not a plan file (no "format": "{FORMAT}")')
    version = document.get("version")
    if version not in READS:
        shown = json.dumps(version)[:40]
        raise BilbaError(
            f"{path}: plan file version {shown}; this bilba reads versions 1 and 2"
            + (" (a newer bilba wrote it)" if isinstance(version, int) and version > 2 else "")
        )
    if version == 2:
        _check_schema(document, path)
    try:
        motions = [_read_motion(m) for m in document["motions"]]
        document["task"]["name"]
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise BilbaError(f"{path}: malformed plan file: {type(exc).__name__} {exc}") from None
    if version == 1:
        return PlanFile(document, motions)
    _check_damping(document, motions, path)
    spec = _checked_task(document, path)
    _check_start(document, spec, path)
    return PlanFile(document, motions, spec)


#: How far the recorded start joints may put the hand from the task's start pose [m, rad]
#: (the start IK converges to 1e-5).
START_TOL = 1e-4


def _check_start(document: dict[str, Any], spec: TaskSpec, path: Path) -> None:
    """The robot homes to ``robot.start_joints`` before the first motion, and every replay
    starts there: they must put the hand at the task's start pose (an edited file could send
    the arm anywhere)."""
    from bilba_dist.robot.panda import PandaModel
    from bilba_dist.task.loader import start_gripper_pose

    q = np.array(document["robot"]["start_joints"], dtype=float)
    with np.errstate(all="ignore"):
        error = pin.log6(PandaModel().fk(q).actInv(start_gripper_pose(spec))).vector
    off = float(np.linalg.norm(error)) if np.all(np.isfinite(q)) else float("inf")
    if not off <= START_TOL:
        raise BilbaError(
            f"{path}: malformed plan file: robot/start_joints put the hand {off:.3g} (m, rad) "
            "from the task's start pose: edited, or from another task"
        )


@cache
def plan_schema() -> dict[str, Any]:
    """The JSON Schema of version 2 (shipped in the package)."""
    text = (resources.files("bilba_dist.plans") / "plan-v2.schema.json").read_text("utf-8")
    schema: dict[str, Any] = json.loads(text)
    return schema


def _check_schema(document: dict[str, Any], path: Path) -> None:
    import jsonschema

    validator = jsonschema.Draft202012Validator(plan_schema())
    error = jsonschema.exceptions.best_match(validator.iter_errors(document))
    if error is not None:
        where = "/".join(str(p) for p in error.absolute_path) or "the top level"
        message = error.message if len(error.message) <= 160 else error.message[:157] + "..."
        raise BilbaError(f"{path}: malformed plan file: at {where}: {message}")


def _check_damping(document: dict[str, Any], motions: list[PlannedMotion], path: Path) -> None:
    """Each motion's D must be the 2·sqrtm(K) the plan was simulated with."""
    for i, (m, motion) in enumerate(zip(document["motions"], motions, strict=True)):
        expected, D = damping(motion.K), np.array(m["D"], dtype=float)
        if not np.abs(D - expected).max() <= DAMPING_TOL * max(1.0, np.abs(expected).max()):
            raise BilbaError(f"{path}: malformed plan file: motions/{i}/D is not 2·sqrtm(K)")


def _checked_task(document: dict[str, Any], path: Path) -> TaskSpec:
    """The embedded task must validate and match its hash (an edited task would execute
    a plan on parts it was not made for). The hash is of the task as stored, so a file
    written before a newer bilba added a setting (with a default) still reads."""
    task = document["task"]
    try:
        spec = TaskSpec.model_validate(task["spec"])
    except ValidationError as exc:
        first = exc.errors()[0]
        where = "".join(f".{p}" for p in first["loc"])
        message = f"task.spec{where}: {first['msg'].removeprefix('Value error, ')}"
        raise BilbaError(f"{path}: malformed plan file: {message}") from None
    canonical = json.dumps(task["spec"], sort_keys=True)
    if hashlib.sha256(canonical.encode()).hexdigest() != task["hash"]:
        raise BilbaError(f"{path}: the embedded task does not match its hash (edited?)")
    return spec


def _read_motion(m: dict[str, Any]) -> PlannedMotion:
    K = _array(m["K"], (6, 6), "K")
    if not is_symmetric_psd(K.tobytes()):
        raise ValueError("K must be symmetric positive semi-definite")
    G_d = pin.SE3(_rotation(m["G_d"]), _array(m["G_d"]["xyz"], (3,), "G_d.xyz"))
    if np.abs(G_d.translation).max() > WORKSPACE_M:
        raise ValueError(f"G_d.xyz {G_d.translation.tolist()} is outside ±{WORKSPACE_M} m")
    timeout = float(m["timeout_s"])
    if not 0 < timeout <= MAX_MOTION_TIMEOUT_S:
        raise ValueError(f"timeout_s must be in (0, {MAX_MOTION_TIMEOUT_S:g}] s, got {timeout}")
    contact = ContactPair(str(m["contact"]["env"]), str(m["contact"]["manip"]))
    q_d = _array(m["q_d"], (7,), "q_d")
    return PlannedMotion(K, G_d, q_d, timeout, contact, float(m["score"]))


def _array(value: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    a = np.array(value, dtype=float)
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} holds a number that is not finite")
    return a


def _rotation(G_d: dict[str, Any]) -> np.ndarray:
    """G_d's rotation: the stored matrix where there is one (the quaternion's round trip
    moves it by up to ~1e-11, and the puzzle's 0.25 mm clearances turn a 1e-9 m change of
    setpoint into a different contact), else the quaternion's; both must agree."""
    xyzw = _array(G_d["quat_xyzw"], (4,), "G_d.quat_xyzw")
    if not (np.abs(xyzw) <= 2).all() or np.linalg.norm(xyzw) < 0.5:  # 1e308 overflows norm
        raise ValueError("G_d.quat_xyzw must be a unit quaternion")
    quat = pin.Quaternion(xyzw)  # x, y, z, w
    quat.normalize()
    if "rotation" not in G_d:
        return quat.matrix()
    R = np.array(G_d["rotation"], dtype=float)
    # entries past ±1 (or NaN) are refused before R.T @ R, which 1e308 would overflow
    if (
        R.shape != (3, 3)
        or not (np.abs(R) <= 1 + ROTATION_TOL).all()
        or not np.allclose(R.T @ R, np.eye(3), atol=ROTATION_TOL)
    ):
        raise ValueError("G_d rotation must be a 3x3 rotation matrix")
    if not np.allclose(R, quat.matrix(), atol=ROTATION_TOL):
        raise ValueError("G_d rotation and quat_xyzw disagree")
    return R
