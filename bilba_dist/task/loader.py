"""Load a task by built-in name or path: validate the YAML, build the parts, check the goal."""

import hashlib
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from importlib import resources
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from pydantic import BaseModel, ValidationError

from bilba_dist.errors import BilbaError, GeometryError, TaskError
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.mesh import mesh_bodies
from bilba_dist.geometry.piece import (
    SMOOTH_ANGLE,
    Part,
    box_piece,
    convex_piece,
    smooth_surfaces,
)
from bilba_dist.geometry.pose import pose_from_xyz_rpy
from bilba_dist.task.schema import (
    MAX_PIECES,
    PAPER_PLANNER,
    PRESETS,
    AxisBelief,
    ConvexSpec,
    PartSpec,
    PlannerParams,
    PoseSpec,
    TaskSpec,
    parse_axis_values,
    piece_pairs_problem,
)
from bilba_dist.task.timestep import auto_timestep
from bilba_dist.task.yaml_lines import Location, line_of, load_yaml_with_lines, read_text


@dataclass(frozen=True)
class Task:
    """A validated task with its parts built. Poses: ``X_GM`` nominal grasp, ``X_WO`` nominal
    environment pose, ``X_WG0`` gripper at the start."""

    spec: TaskSpec
    source: str
    manipuland: Part
    environment: Part
    X_GM: pin.SE3
    X_WO: pin.SE3
    X_WG0: pin.SE3
    goal: ContactPair

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def timestep_s(self) -> float:
        """The physics step: the task file's, or the one read off its parts on loading."""
        step = self.spec.planner.sim_timestep_s
        assert step is not None  # build_task sets it
        return step

    @property
    def hash(self) -> str:
        """SHA-256 of the validated task (after overrides), in canonical JSON."""
        canonical = json.dumps(self.spec.model_dump(mode="json"), sort_keys=True)
        return hashlib.sha256(canonical.encode()).hexdigest()


def builtin_tasks() -> dict[str, Path]:
    """Built-in task names and their YAML files (shipped inside the package)."""
    folder = resources.files("bilba_dist.task") / "tasks"
    return {
        Path(str(entry)).stem: Path(str(entry))
        for entry in folder.iterdir()
        if str(entry).endswith(".yaml")
    }


def resolve_task_path(name_or_path: str) -> Path:
    path = Path(name_or_path)
    if path.exists() and not path.is_dir():  # a pipe or device too: read_text refuses it
        return path
    builtins = builtin_tasks()
    if name_or_path in builtins:
        return builtins[name_or_path]
    if path.suffix in (".yaml", ".yml") or "/" in name_or_path:
        raise TaskError(f"{name_or_path}: no such task file")
    raise TaskError(
        f"no task file or built-in task named {name_or_path!r}; built-in: "
        f"{', '.join(sorted(builtins))}"
    )


def load_task(
    task: str | PathLike[str] | Mapping[str, Any],
    uncertainty: Sequence[str] | None = None,
    folder: str | PathLike[str] | None = None,
) -> Task:
    """Load and validate a task: a built-in name, a task file, or what a task file holds
    as a mapping (a task built in Python: its mesh files relative to ``folder``, by default
    the working directory). ``uncertainty`` (``["grasp.pitch=2deg", …]``) replaces the
    task's bounds when given."""
    if isinstance(task, Mapping):
        name = task.get("name")
        source = f"task {name!r}" if isinstance(name, str) else "task"
        data, lines, base = dict(task), dict[Location, int](), Path(folder or ".")
    else:
        path = resolve_task_path(str(task))
        source, base = str(path), path.parent
        data, lines = load_yaml_with_lines(read_text(path), source)
    if not isinstance(data, dict):
        raise TaskError(f"{source}: a task file must be a YAML mapping at the top level")
    if uncertainty:
        data = {**data, "uncertainty": parse_overrides(uncertainty)}
    try:
        spec = TaskSpec.model_validate(data)
    except ValidationError as exc:
        raise TaskError(describe_error(exc, source, lines)) from None
    spec = with_meshes_loaded(spec, base, source, lines)
    try:
        return build_task(spec, source)
    except BilbaError as exc:
        raise TaskError(f"{source}: {exc}") from None


def parse_axis_items(items: Iterable[str], option: str, example: str) -> dict[str, float]:
    """``AXIS=VALUE`` items of a command-line option → {axis: value} in SI units (signed);
    a malformed item, an axis given twice, an unknown axis or a bad value is one TaskError
    line naming ``option``."""
    raw: dict[str, Any] = {}
    for item in items:
        key, sep, value = (part.strip() for part in item.partition("="))
        if not sep or not key or not value:
            raise TaskError(f"{option} {item!r}: write AXIS=VALUE, e.g. {example}")
        if key in raw:
            raise TaskError(f"{option}: {key} given twice")
        raw[key] = value
    try:
        return parse_axis_values(raw, prefix="")
    except ValueError as exc:
        raise TaskError(f"{option}: {exc}") from None


def parse_overrides(items: Iterable[str]) -> dict[str, float]:
    """``["grasp.pitch=2deg", "env.y=1cm"]`` → bounds in SI units."""
    bounds = parse_axis_items(items, "--uncertainty", "grasp.pitch=2deg")
    negative = [key for key, value in bounds.items() if value < 0]
    if negative:
        raise TaskError(f"--uncertainty: bounds must be >= 0: {', '.join(negative)}")
    return bounds


def build_task(spec: TaskSpec, source: str) -> Task:
    keep = frozenset({spec.goal.env, spec.goal.manip})
    manipuland = build_part(spec.manipuland, keep=keep)
    environment = build_part(spec.environment, spread=SMOOTH_ANGLE, keep=keep)
    goal = ContactPair(spec.goal.env, spec.goal.manip)
    for part, face, key in (
        (environment, goal.env, "goal.env"),
        (manipuland, goal.manip, "goal.manip"),
    ):
        try:
            part.face(face)
        except GeometryError as exc:
            raise TaskError(f"{key}: {exc}") from None
    X_GM, X_WO, X_WG0 = (
        to_pose(spec.grasp),
        to_pose(spec.environment_pose),
        start_gripper_pose(spec),
    )
    if spec.planner.sim_timestep_s is None:  # unset: read off the parts, and written in
        step = auto_timestep(environment, manipuland, goal, X_WO.inverse() * X_WG0 * X_GM)
        planner = spec.planner.model_copy(update={"sim_timestep_s": step})
        spec = spec.model_copy(update={"planner": planner})
    return Task(
        spec=spec,
        source=source,
        manipuland=manipuland,
        environment=environment,
        X_GM=X_GM,
        X_WO=X_WO,
        X_WG0=X_WG0,
        goal=goal,
    )


def with_planner(task: Task, **changes: Any) -> Task:
    """``task`` with some planner parameters replaced, validated like a task file's (a
    pydantic ``model_copy`` would not check them): a bad value is a one-line TaskError."""
    try:
        planner = PlannerParams.model_validate({**task.spec.planner.model_dump(), **changes})
    except ValidationError as exc:
        error = exc.errors()[0]
        raise TaskError(f"planner.{_dotted(error['loc'])}: {error['msg']}") from None
    return build_task(task.spec.model_copy(update={"planner": planner}), task.source)


def with_friction(task: Task, factor: float) -> Task:
    """``task`` with its friction coefficient times ``factor`` (> 0)."""
    spec = task.spec.model_copy(update={"friction": task.spec.friction * factor})
    return build_task(spec, task.source)


def with_points(task: Task, points: int) -> Task:
    """``task`` on the axis belief of ``points`` particles a bounded axis (its parts as they
    are: only the belief differs)."""
    return replace(task, spec=task.spec.model_copy(update={"belief": AxisBelief(points=points)}))


def with_preset(task: Task, preset: str) -> Task:
    """``task`` with a planner preset's fields (``paper``: the authors' settings; ``default``:
    ours) replacing the task file's values for those fields."""
    values = PRESETS[preset] if preset != "default" else {
        name: PlannerParams.model_fields[name].default for name in PAPER_PLANNER
    }  # fmt: skip
    return with_planner(task, preset=preset, **values)


def start_gripper_pose(spec: TaskSpec) -> pin.SE3:
    """``X_WG`` at the start: as given, or the forward kinematics of the start joints."""
    start = spec.robot_start
    if start.gripper is not None:
        return to_pose(start.gripper)
    from bilba_dist.robot.panda import PandaModel  # loads the URDF: only when needed

    return PandaModel().fk(np.array(start.joints))


def to_pose(spec: PoseSpec) -> pin.SE3:
    return pose_from_xyz_rpy(spec.xyz, spec.rpy)


def with_meshes_loaded(
    spec: TaskSpec, folder: Path, source: str, lines: dict[Location, int]
) -> TaskSpec:
    """``spec`` with every ``mesh`` piece replaced by the ``convex`` piece it describes
    (files relative to ``folder``), so the spec alone rebuilds the task (Ray workers, logs,
    plan files). A file of several objects (CoACD's convex parts) gives one piece per
    object, ``NAME_0``, ``NAME_1``, … with the piece's pose and face names."""
    parts = {}
    for key in ("manipuland", "environment"):
        part: PartSpec = getattr(spec, key)
        pieces, origins = [], []  # origins: the index in the file of each piece
        for i, piece in enumerate(part.pieces):
            if piece.mesh is None:
                pieces.append(piece)
                origins.append(i)
                continue
            where = at(source, (key, "pieces", i, "mesh", "file"), lines)
            try:
                bodies = mesh_bodies(folder / piece.mesh.file, piece.mesh.scale)
            except BilbaError as exc:
                raise TaskError(f"{where}: {key}.pieces[{i}]: {exc}") from None
            for k, vertices in enumerate(bodies):
                convex = ConvexSpec(vertices=[tuple(v) for v in vertices], faces=piece.mesh.faces)
                name = piece.name if len(bodies) == 1 else f"{piece.name}_{k}"
                pieces.append(
                    piece.model_copy(update={"name": name, "mesh": None, "convex": convex})
                )
                origins.append(i)
        seen: dict[str, int] = {}
        for piece, i in zip(pieces, origins, strict=True):
            if piece.name in seen:
                j = seen[piece.name]
                first = line_of((key, "pieces", j, "name"), lines)
                raise TaskError(
                    f"{at(source, (key, 'pieces', i, 'name'), lines)}: {key}: a second piece "
                    f"named {piece.name!r} (the first "
                    f"{f'at line {first}' if first is not None else f'is pieces[{j}]'}; a mesh "
                    "file of several objects names its pieces NAME_0, NAME_1, …)"
                )
            seen[piece.name] = i
        if len(pieces) > MAX_PIECES:
            raise TaskError(
                f"{at(source, (key, 'pieces'), lines)}: {key}: {len(pieces)} pieces once its "
                f"mesh files are split into their objects, over {MAX_PIECES}"
            )
        parts[key] = part.model_copy(update={"pieces": pieces})
    env, manip = (len(parts[key].pieces) for key in ("environment", "manipuland"))
    if problem := piece_pairs_problem(env, manip):
        raise TaskError(f"{source}: {problem}")
    return spec.model_copy(update=parts)


def build_part(
    spec: PartSpec, spread: float | None = None, keep: frozenset[str] = frozenset()
) -> Part:
    """The part's pieces, each one's smooth surfaces made one face (geometry/piece.py
    ``smooth_surfaces``). The environment's (``spread``) are cut into patches whose normals
    differ by at most that: its face says where in the world the part touches, and a
    round wall made one face would call contacts on opposite sides one contact; which side
    of a round part touches says nothing a motion needs. Faces in ``keep`` (the goal's)
    stay apart."""
    pieces = []
    for piece in spec.pieces:
        X = to_pose(piece.pose)
        if piece.box is not None:
            pieces.append(box_piece(piece.name, piece.box.size, X))
        elif piece.convex is not None:
            pieces.append(convex_piece(piece.name, piece.convex.vertices, X, piece.convex.faces))
    return Part(spec.name, tuple(smooth_surfaces(p, spread, keep) for p in pieces))


def describe_error(
    exc: ValidationError,
    source: str,
    lines: dict[Location, int],
    root: type[BaseModel] = TaskSpec,
) -> str:
    """One line for the first validation error of a YAML file validated by model ``root``:
    file, line, key path, and what is wrong."""
    errors = exc.errors()
    first = errors[0]
    loc: Location = tuple(first["loc"])
    where, key = at(source, loc, lines), _dotted(loc)
    if first["type"] == "extra_forbidden":
        allowed = _allowed_keys(loc[:-1], root)
        message = f"unknown key {loc[-1]!r}" + (
            f"; allowed: {', '.join(allowed)}" if allowed else ""
        )
    else:
        message = first["msg"].removeprefix("Value error, ")
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return f"{where}: {key}: {message}{more}" if key else f"{where}: {message}{more}"


def at(source: str, location: Location, lines: dict[Location, int]) -> str:
    """``source:line`` of the key at ``location``, or ``source`` where no line is known (a
    task given as a mapping)."""
    line = line_of(location, lines)
    return f"{source}:{line}" if line is not None else source


def _dotted(loc: Location) -> str:
    text = ""
    for part in loc:
        if isinstance(part, int):
            text += f"[{part}]"
        elif part in ("axis", "extremal+random", "explicit"):
            continue  # pydantic's discriminator tag, not a key the user wrote
        else:
            text += f".{part}" if text else str(part)
    return text


def _allowed_keys(loc: Location, root: type[BaseModel]) -> list[str]:
    """The keys allowed at ``loc`` in the schema ``root``, found by walking the models."""
    candidates: list[type[BaseModel]] = [root]
    for part in loc:
        if isinstance(part, int):
            continue
        following: list[type[BaseModel]] = []
        for model in candidates:
            if part in model.model_fields:
                following += _models_in(model.model_fields[str(part)].annotation)
            elif part in _generator_tags(model):
                following.append(model)
        candidates = following
    return sorted(candidates[0].model_fields) if len(candidates) == 1 else []


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in getattr(annotation, "__args__", ()) for m in _models_in(arg)]


def _generator_tags(model: type[BaseModel]) -> tuple[str, ...]:
    field = model.model_fields.get("generator")
    return tuple(getattr(field.annotation, "__args__", ())) if field is not None else ()
