"""The Python API: what `bilba_dist` exports, that importing it stays light, and that the
scripts in examples/ run as a user would run them."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

import bilba_dist
from bilba_dist.record.reader import read_log

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))


def test_every_exported_name_resolves_and_is_listed():
    assert set(bilba_dist.__all__) == {"__version__", *bilba_dist._EXPORTS}
    for name in bilba_dist._EXPORTS:
        value = getattr(bilba_dist, name)
        assert getattr(value, "__module__", bilba_dist._EXPORTS[name]).startswith("bilba_dist")
    assert callable(bilba_dist.plan) and bilba_dist.plan.__module__ == "bilba_dist.planning.bilba"
    with pytest.raises(AttributeError):
        bilba_dist.no_such_name  # noqa: B018


def test_importing_the_package_loads_neither_physics_nor_ray():
    probe = (
        "import sys, bilba_dist; "
        "heavy = [m for m in ('pybullet', 'ray', 'pinocchio') if m in sys.modules]; "
        "print(heavy); sys.exit(1 if heavy else 0)"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout


def test_there_are_examples():
    assert EXAMPLES


@pytest.mark.parametrize("script", EXAMPLES, ids=lambda p: p.name)
def test_example_runs_and_writes_a_plan_and_a_log(script, tmp_path):
    done = subprocess.run(
        [sys.executable, str(script), "peg-in-hole", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "1.00 of the planning belief" in done.stdout
    (plan,) = tmp_path.glob("*.json")
    assert json.loads(plan.read_text())["success"] is True
    (log,) = tmp_path.glob("*.mcap")
    assert len(read_log(log).json("/transition")) >= 1


def test_file_functions_take_str_paths_as_well_as_paths(default_plan_file, tmp_path):
    """A Python user passes a path as a string as often as a `Path`."""
    from bilba_dist import LogWriter, dumps, read_log, read_plan, write_plan

    plan = read_plan(str(default_plan_file))
    assert plan.motions
    copy = tmp_path / "sub" / "copy.json"
    write_plan(json.loads(default_plan_file.read_text()), str(copy))
    assert [m.G_d for m in read_plan(copy).motions] == [m.G_d for m in plan.motions]
    log_path = tmp_path / "logs" / "log.mcap"
    log = LogWriter(str(log_path), plan.task(), "bilba-variable", seed=0)
    log.finish(dumps(json.loads(copy.read_text())), {"success": True})
    assert read_log(str(log_path)).json("/metadata")[0]["seed"] == 0


def test_a_task_built_in_python_loads_as_its_file_would(tmp_path):
    """`load_task` takes what a task file holds as a mapping: the same task as the file
    (hash), its errors one line naming the task (no line numbers to give), and mesh files
    relative to ``folder``."""
    import yaml

    from bilba_dist.errors import BilbaError
    from bilba_dist.task.prismatic import peg_in_hole_task, regular_polygon
    from tests.conftest import prism_file

    data = peg_in_hole_task("7-gon", [regular_polygon(7, 0.05)], 0.001, 0.004, None)
    from_file = bilba_dist.load_task(prism_file(tmp_path, 7, 0.001))
    assert bilba_dist.load_task(data).hash == from_file.hash
    assert bilba_dist.load_task(data, ["grasp.x=1cm"]).spec.uncertainty == {"grasp.x": 0.01}
    with pytest.raises(BilbaError, match=r"^task '7-gon': friction: Input should be greater"):
        bilba_dist.load_task({**data, "friction": -1})
    example = Path(__file__).parents[1] / "examples" / "round-peg"
    meshed = yaml.safe_load((example / "round-peg.yaml").read_text())
    assert len(bilba_dist.load_task(meshed, folder=example).environment.pieces) == 17
    with pytest.raises(BilbaError, match=r"^task 'round-peg': manipuland\.pieces\[0\]: mesh "):
        bilba_dist.load_task(meshed, folder=tmp_path)
    twice = {**data, "environment": {**data["environment"]}}
    twice["environment"]["pieces"] = [
        *data["environment"]["pieces"],
        data["environment"]["pieces"][0],
    ]
    with pytest.raises(BilbaError, match=r"^task '7-gon': environment: a second piece named"):
        bilba_dist.load_task(twice)
