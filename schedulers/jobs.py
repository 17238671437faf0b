"""Jobs files: a grid of planning jobs (tasks × uncertainty settings × planners × seeds).

    name: paper-peg
    tasks: [peg-in-hole]            # built-in names, or paths relative to this file
    uncertainty:                    # setting name -> bounds (replacing the task file's);
      pitch: [grasp.pitch=2deg]     #   [] keeps the task file's own bounds
      x: [grasp.x=1cm]
    planners: [bilba-variable, bilba-fixed]
    seeds: 5                        # 0..4, or a list such as [0, 7, 9]
    timeout_s: 600                  # per job: a job that runs out is recorded as a timeout
    model: panda                    # or floating (plans checked on the Panda before use)

Every task and setting is loaded and validated on the driver before anything runs, so a bad
file fails in one line without starting Ray; workers receive the validated `TaskSpec`.
"""

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from bilba_dist.belief.particles import initial_belief
from bilba_dist.belief.start import (
    check_gripper_reaches_goal,
    check_gripper_start,
    check_start_free,
)
from bilba_dist.errors import BilbaError
from bilba_dist.planning.bilba import Variant
from bilba_dist.rollout import DynamicsModel
from bilba_dist.task.loader import Task, describe_error, load_task, with_preset
from bilba_dist.task.schema import TaskSpec
from bilba_dist.task.yaml_lines import load_yaml_with_lines, read_text

#: Seeds per cell of a jobs file.
MAX_SEEDS = 10_000


def _task_bounds() -> dict[str, list[str]]:
    return {"task": []}


def _default_planners() -> list[Variant]:
    return ["bilba-variable"]


class JobsSpec(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    name: str = Field(pattern=r"^[A-Za-z0-9_.-]+$")
    tasks: list[str] = Field(min_length=1)
    uncertainty: dict[str, list[str]] = Field(default_factory=_task_bounds)
    planners: list[Variant] = Field(default_factory=_default_planners, min_length=1)
    seeds: int | list[int] = 1
    timeout_s: float = Field(default=900.0, gt=0, le=7 * 86400)
    model: Literal["panda", "floating"] = "panda"
    # Planner settings for every job: paper (the authors') or default (ours); unset keeps
    # each task file's.
    preset: Literal["default", "paper"] | None = None

    @field_validator("uncertainty")
    @classmethod
    def _setting_names(cls, value: dict[str, list[str]]) -> dict[str, list[str]]:
        for name in value:
            if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
                raise ValueError(f"setting name {name!r}: use letters, digits, '_', '.', '-'")
        if not value:
            raise ValueError("give at least one setting ([] keeps the task file's bounds)")
        return value

    @field_validator("seeds")
    @classmethod
    def _seed_range(cls, seeds: int | list[int]) -> int | list[int]:
        count = seeds if isinstance(seeds, int) else len(seeds)
        listed = [] if isinstance(seeds, int) else seeds
        if not 1 <= count <= MAX_SEEDS or not all(0 <= s < 2**32 for s in listed):
            raise ValueError(f"give 1 to {MAX_SEEDS} seeds, each in [0, 2^32)")
        return seeds

    @property
    def seed_list(self) -> list[int]:
        return list(range(self.seeds)) if isinstance(self.seeds, int) else self.seeds


@dataclass(frozen=True)
class Job:
    """One planning job of a grid; ``id`` names its record, plan and log."""

    id: str
    task: str  # as written in the jobs file
    setting: str
    uncertainty: tuple[str, ...]
    planner: Variant
    seed: int
    timeout_s: float
    model: DynamicsModel


@dataclass(frozen=True)
class Batch:
    name: str
    jobs: list[Job]
    tasks: dict[tuple[str, str], Task]  # (task, setting) -> validated task

    def spec(self, job: Job) -> TaskSpec:
        return self.tasks[(job.task, job.setting)].spec


def load_jobs(path: Path) -> Batch:
    """Read, validate and expand a jobs file; every task and setting is loaded here."""
    source = str(path)
    data, lines = load_yaml_with_lines(read_text(path, "jobs file"), source)
    if not isinstance(data, dict):
        raise BilbaError(f"{source}: a jobs file must be a YAML mapping at the top level")
    try:
        spec = JobsSpec.model_validate(data)
    except ValidationError as exc:
        raise BilbaError(describe_error(exc, source, lines, JobsSpec)) from None
    tasks: dict[tuple[str, str], Task] = {}
    for task in spec.tasks:
        beside = path.parent / task
        where = str(beside) if beside.is_file() else task
        for n, (setting, bounds) in enumerate(spec.uncertainty.items()):
            try:
                loaded = load_task(where, bounds)
                if spec.preset is not None:
                    loaded = with_preset(loaded, spec.preset)
                tasks[(task, setting)] = loaded
                particles = initial_belief(loaded)
                check_start_free(loaded, particles)
                check_gripper_start(loaded, particles)
                if n == 0:  # the goal is the same in every setting
                    check_gripper_reaches_goal(loaded)
            except BilbaError as exc:
                raise BilbaError(f"{source}: task {task!r}, setting {setting!r}: {exc}") from None
    jobs = [
        Job(
            id=f"{tasks[(task, setting)].name}-{setting}-{planner}-s{seed}",
            task=task,
            setting=setting,
            uncertainty=tuple(bounds),
            planner=planner,
            seed=seed,
            timeout_s=spec.timeout_s,
            model=spec.model,
        )
        for task in spec.tasks
        for setting, bounds in spec.uncertainty.items()
        for planner in spec.planners
        for seed in spec.seed_list
    ]
    ids = [job.id for job in jobs]
    if len(set(ids)) != len(ids):
        duplicate = next(i for i in ids if ids.count(i) > 1)
        raise BilbaError(f"{source}: two jobs would both be named {duplicate!r}")
    return Batch(spec.name, jobs, tasks)
