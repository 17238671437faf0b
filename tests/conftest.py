"""Shared fixtures: the built-in tasks, and helpers to write task files."""

import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import settings

from bilba_dist.task.loader import Task, builtin_tasks, load_task

# Property tests draw their examples from a fixed seed: a failure in CI replays anywhere.
settings.register_profile("seeded", derandomize=True)
settings.load_profile("seeded")


@pytest.fixture(scope="session")
def peg() -> Task:
    return load_task("peg-in-hole")


@pytest.fixture(scope="session")
def puzzle() -> Task:
    return load_task("puzzle")


@pytest.fixture
def peg_yaml() -> dict:
    """The peg-in-hole task file as plain data, to break in a test."""
    return yaml.safe_load(builtin_tasks()["peg-in-hole"].read_text())


def write_task(tmp_path: Path, data: dict | str, name: str = "task.yaml") -> Path:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data, sort_keys=False))
    return path


def prism_file(
    tmp_path: Path,
    sides: int,
    clearance_m: float,
    planner: dict | None = None,
    uncertainty: dict[str, str] | None = None,
) -> Path:
    """A task file of our own: a regular prism in a chamfered hole with that clearance
    (``uncertainty`` by default grasp.pitch ±2°)."""
    from bilba_dist.task.prismatic import peg_in_hole_task, regular_polygon

    outline = [regular_polygon(sides, 0.05)]
    data = peg_in_hole_task(f"{sides}-gon", outline, clearance_m, 0.004, uncertainty)
    if planner is not None:
        data["planner"] = planner
    return write_task(tmp_path, yaml.safe_dump(data))


def prism_task(tmp_path: Path, *args: Any, **kwargs: Any) -> Task:
    """`prism_file`'s task, loaded."""
    return load_task(str(prism_file(tmp_path, *args, **kwargs)))


@pytest.fixture(scope="session")
def default_plan_file(tmp_path_factory) -> Path:
    """A plan of the default task, planned in-process with `bilba plan`, as a file."""
    from tests.test_task_files import run_cli

    out = tmp_path_factory.mktemp("plan") / "peg.json"
    result = run_cli("plan", "peg-in-hole", "--workers", "0", "--no-log", "--out", str(out))
    assert result.exit_code == 0, result.output
    return out


def raylets_of(pid: int) -> list:
    """The raylet processes a command started (its local Ray instance), via psutil."""
    import psutil

    return [p for p in psutil.Process(pid).children(recursive=True) if p.name() == "raylet"]


def planner_in_progress(tmp_path: Path, workers: int) -> tuple[subprocess.Popen, Path]:
    """`bilba plan puzzle` in a subprocess, once its log holds a transition or two (and, on
    Ray, its raylet is up): a planner to interrupt. Its plan would go to tmp_path/p.json."""
    log = tmp_path / "l.mcap"
    bilba = Path(sys.executable).parent / "bilba"
    planner = subprocess.Popen(
        [bilba, "plan", "puzzle", "--workers", str(workers), "--log", log,
         "--out", tmp_path / "p.json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.time() + 120
    while (
        not log.exists()
        or log.stat().st_size < 200_000
        or (workers and not raylets_of(planner.pid))
    ):
        assert time.time() < deadline and planner.poll() is None, "no transition in 120 s"
        time.sleep(0.2)
    return planner, log
