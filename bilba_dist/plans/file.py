"""The plan file: versioned JSON holding everything needed to run the motions on a Panda
without the planner — per motion K (6×6, rotation first, world axes), G_d (xyz and quaternion
xyzw, world frame, plus the rotation matrix exactly as simulated), q_d (7 joints), timeout,
the contact it should reach, and its score — plus the task (name, hash, uncertainty),
planner, seed, parameters and planning time."""

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from bilba_dist import __version__
from bilba_dist.errors import BilbaError
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.pose import setpoint_json
from bilba_dist.planning.result import PlannedMotion, PlanResult
from bilba_dist.rollout import is_symmetric_psd
from bilba_dist.task.loader import Task
from bilba_dist.task.schema import MAX_MOTION_TIMEOUT_S
from bilba_dist.task.units import WORKSPACE_M
from bilba_dist.task.yaml_lines import read_text

FORMAT = "bilba-plan"
VERSION = 1
#: How far a G_d rotation may be from orthonormal, or from its quaternion, in a plan file.
ROTATION_TOL = 1e-6


def plan_document(result: PlanResult, task: Task) -> dict[str, Any]:
    return {
        "format": FORMAT,
        "version": VERSION,
        "task": {
            "name": task.name,
            "hash": task.hash,
            "source": task.source,
            "uncertainty": task.spec.uncertainty,
        },
        "planner": result.planner,
        "planner_version": __version__,
        "seed": result.seed,
        "parameters": task.spec.planner.model_dump(),
        "success": result.success,
        "reason": result.reason,
        "planning_time_s": round(result.planning_time_s, 3),
        "rollouts": result.rollouts,
        "motions": [_motion(m) for m in result.motions],
    }


def _motion(m: PlannedMotion) -> dict[str, Any]:
    return {
        "K": np.asarray(m.K).tolist(),
        "G_d": setpoint_json(m.G_d),
        "q_d": np.asarray(m.q_d).tolist(),
        "timeout_s": m.timeout_s,
        "contact": {"env": m.contact.env, "manip": m.contact.manip},
        "score": m.score,
    }


def dumps(document: dict[str, Any]) -> str:
    """Canonical text of a plan document (the MCAP log stores the same bytes)."""
    return json.dumps(document, indent=2, sort_keys=True) + "\n"


def write_plan(document: dict[str, Any], path: Path) -> None:
    write_plan_text(dumps(document), path)


def write_plan_text(text: str, path: Path) -> None:
    """A plan file's text (``dumps`` of its document, e.g. from a Ray task) at ``path``."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise BilbaError(f"{path}: cannot write plan file: {exc.strerror or exc}") from None


@dataclass(frozen=True)
class PlanFile:
    document: dict[str, Any]
    motions: list[PlannedMotion]

    @property
    def task_name(self) -> str:
        return str(self.document["task"]["name"])

    @property
    def uncertainty(self) -> dict[str, float]:
        return dict(self.document["task"].get("uncertainty", {}))


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


def read_plan(path: Path) -> PlanFile:
    """Read and check a plan file; any problem is one BilbaError line naming the file."""
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
    if document.get("version") != VERSION:
        raise BilbaError(
            f"{path}: plan file version {document.get('version')}; this reads {VERSION}"
        )
    try:
        motions = [_read_motion(m) for m in document["motions"]]
        document["task"]["name"]
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise BilbaError(f"{path}: malformed plan file: {type(exc).__name__} {exc}") from None
    return PlanFile(document, motions)


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
    if np.linalg.norm(xyzw) < 0.5:
        raise ValueError("G_d.quat_xyzw must be a unit quaternion")
    quat = pin.Quaternion(xyzw)  # x, y, z, w
    quat.normalize()
    if "rotation" not in G_d:
        return quat.matrix()
    R = np.array(G_d["rotation"], dtype=float)  # NaN fails the allclose below
    if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=ROTATION_TOL):
        raise ValueError("G_d rotation must be a 3x3 rotation matrix")
    if not np.allclose(R, quat.matrix(), atol=ROTATION_TOL):
        raise ValueError("G_d rotation and quat_xyzw disagree")
    return R
