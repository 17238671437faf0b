"""Task files: built-ins load; every kind of bad file is one clear line and exit code 2."""

import copy
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from bilba_dist.cli.main import cli, register
from bilba_dist.errors import TaskError
from bilba_dist.task.loader import builtin_tasks, load_task
from bilba_dist.task.schema import PAPER_PLANNER
from tests.conftest import write_task


def run_cli(*args: str):
    register()
    return CliRunner().invoke(cli, list(args))


def test_builtin_tasks_load_by_name_and_path():
    assert set(builtin_tasks()) == {"hex-peg", "peg-in-hole", "puzzle"}
    for name, path in builtin_tasks().items():
        assert load_task(name).hash == load_task(str(path)).hash


def test_peg_in_hole_has_the_authors_dimensions(peg):
    (piece,) = peg.manipuland.pieces
    assert (piece.vertices.max(axis=0) - piece.vertices.min(axis=0)).tolist() == pytest.approx(
        [0.06, 0.06, 0.15]
    )
    px, mx = peg.environment.face("wall_px/inner"), peg.environment.face("wall_mx/inner")
    assert px.normal.tolist() == [-1, 0, 0] and mx.normal.tolist() == [1, 0, 0]
    width = px.offset / px.normal[0] - mx.offset / mx.normal[0]  # x of each face's plane
    assert width == pytest.approx(0.0655)
    assert peg.spec.friction == 0.45


def test_uncertainty_override_replaces_the_file_bounds():
    task = load_task("peg-in-hole", ["grasp.x=1cm", "env.y=5mm"])
    assert task.spec.uncertainty == pytest.approx({"grasp.x": 0.01, "env.y": 0.005})
    assert task.hash != load_task("peg-in-hole").hash


def _drop(data, *path):
    node = data
    for key in path[:-1]:
        node = node[key]
    del node[path[-1]]


def _set(data, value, *path):
    node = data
    for key in path[:-1]:
        node = node[key] if isinstance(node, list) else node.setdefault(key, {})
    node[path[-1]] = value


BAD_FILES = {
    "missing field": (lambda d: _drop(d, "goal"), r"goal: Field required"),
    "unknown key": (
        lambda d: _set(d, 3, "grasp", "zz"),
        r":\d+: grasp\.zz: unknown key 'zz'; allowed: rpy, xyz",
    ),
    "unknown top-level key": (lambda d: _set(d, 1, "frobnicate"), r"unknown key 'frobnicate'"),
    "wrong unit": (
        lambda d: _set(d, ["180cm", 0, 0], "grasp", "rpy"),
        r":\d+: grasp\.rpy\[0\]: .*'cm' is not an angle unit",
    ),
    "wrong unit in bounds": (
        lambda d: _set(d, "2cm", "uncertainty", "grasp.pitch"),
        r"uncertainty: .*grasp\.pitch.*not an angle unit",
    ),
    "unknown uncertainty axis": (
        lambda d: _set(d, "1cm", "uncertainty", "grasp.w"),
        r"unknown uncertainty axis 'grasp\.w'",
    ),
    "wrong type": (lambda d: _set(d, "slippery", "friction"), r"friction: .*number"),
    "negative planner patience": (
        lambda d: _set(d, -1, "planner", "sample_patience"),
        r":\d+: planner\.sample_patience: .*greater than or equal to 0",
    ),
    "negative race": (
        lambda d: _set(d, -2, "planner", "race_contacts"),
        r":\d+: planner\.race_contacts: .*greater than or equal to 0",
    ),
    "non-convex piece": (
        lambda d: d["environment"]["pieces"][1]["convex"]["vertices"].append([0.05, 0.0, 0.05]),
        r"piece 'wall_px' is not convex",
    ),
    "goal face that does not exist": (
        lambda d: _set(d, "floor/+w", "goal", "env"),
        r"no face 'floor/\+w'; its faces: floor/-z, floor/-y, floor/\+x, floor/-x, floor/\+y, "
        r"floor/\+z$",
    ),
    "goal face of a piece that does not exist": (
        lambda d: _set(d, "+z", "goal", "env"),
        r"goal\.env: part 'hole' has no piece '\+z' \(faces are PIECE/FACE\); pieces: floor, ",
    ),
    "degenerate piece": (
        lambda d: _set(d, {"size": [0.06, 0.06, 0]}, "manipuland", "pieces", 0, "box"),
        r"box size must be three positive lengths",
    ),
    "flat convex piece": (
        lambda d: (
            _set(
                d,
                {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]},
                "manipuland",
                "pieces",
                0,
                "convex",
            )
            or _drop(d, "manipuland", "pieces", 0, "box")
        ),
        r"degenerate",
    ),
    "box and convex both": (
        lambda d: _set(d, {"vertices": [[0, 0, 0]] * 4}, "manipuland", "pieces", 0, "convex"),
        r"exactly one of 'box', 'convex', 'mesh'",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_task_file_is_one_line_and_exit_2(case, peg_yaml, tmp_path):
    breaker, pattern = BAD_FILES[case]
    data = copy.deepcopy(peg_yaml)
    breaker(data)
    path = write_task(tmp_path, data)
    result = run_cli("graph", str(path))
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("bilba: error: ")
    assert str(path) in lines[0]
    assert re.search(pattern, lines[0]), lines[0]


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("name: [unclosed\n", r"task\.yaml:\d+: not valid YAML"),
        ("- a list\n", r"must be a YAML mapping"),
    ],
)
def test_unparsable_task_files(text, pattern, tmp_path):
    result = run_cli("graph", str(write_task(tmp_path, text)))
    assert result.exit_code == 2
    assert re.search(pattern, result.stderr), result.stderr


def test_axis_belief_points_must_be_odd(tmp_path):
    text = builtin_tasks()["puzzle"].read_text() + "belief:\n  generator: axis\n  points: 4\n"
    expected = text.splitlines().index("  points: 4") + 1
    pattern = rf"task\.yaml:{expected}: belief\.points: must be odd .*got 4$"
    with pytest.raises(TaskError, match=pattern):
        load_task(str(write_task(tmp_path, text)))


def test_error_line_number_points_at_the_key(tmp_path):
    text = builtin_tasks()["peg-in-hole"].read_text()
    text = text.replace("friction: 0.45", "friction: 0.45\nfrobnicate: 1")
    expected = text.splitlines().index("frobnicate: 1") + 1
    with pytest.raises(TaskError, match=rf"task\.yaml:{expected}: frobnicate: unknown key"):
        load_task(str(write_task(tmp_path, text)))


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        (["graph", "no-such-task"], r"built-in: hex-peg, peg-in-hole, puzzle"),
        (["graph", "missing/task.yaml"], r"missing/task\.yaml: no such task file"),
        (["graph", "peg-in-hole", "-u", "grasp.pitch"], r"write AXIS=VALUE"),
        (["graph", "peg-in-hole", "-u", "grasp.pitch=-2deg"], r"bounds must be >= 0"),
        (["graph", "peg-in-hole", "-u", "grasp.pitch=2cm"], r"not an angle unit"),
    ],
)
def test_bad_command_lines(args, pattern):
    result = run_cli(*args)
    assert result.exit_code == 2
    assert re.search(pattern, result.stderr), result.stderr


def test_installed_bilba_command_exits_2_without_a_traceback(tmp_path):
    path = write_task(tmp_path, {"name": "x"})
    proc = subprocess.run(
        [sys.executable, "-c", "from bilba_dist.cli.main import main; main()", "graph", str(path)],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_graph_command_prints_the_schedule_and_writes_dot(tmp_path):
    dot = tmp_path / "g.dot"
    result = run_cli("graph", "peg-in-hole", "--uncertainty", "grasp.x=1cm", "--dot", str(dot))
    assert result.exit_code == 0, result.output
    schedule = [line for line in result.output.splitlines() if line.startswith("schedule:")]
    assert schedule and schedule[0].endswith("(floor/+z, peg/-z)")
    assert dot.read_text().startswith("digraph")


def test_tasks_command_lists_builtins():
    result = run_cli("tasks")
    assert result.exit_code == 0
    assert "peg-in-hole" in result.output and "puzzle" in result.output


def test_written_yaml_roundtrip_is_the_same_task(peg_yaml, tmp_path):
    path = write_task(tmp_path, peg_yaml)
    assert load_task(str(path)).spec == load_task("peg-in-hole").spec
    assert yaml.safe_load(path.read_text())["name"] == "peg-in-hole"


def test_joint_angle_start_gives_the_forward_kinematics(peg_yaml, tmp_path):
    from bilba_dist.robot.panda import Q_CENTRE, PandaModel

    data = copy.deepcopy(peg_yaml)
    data["robot_start"] = {"joints": [float(v) for v in Q_CENTRE]}
    task = load_task(str(write_task(tmp_path, data)))
    expected = PandaModel().fk(Q_CENTRE)
    assert task.X_WG0.isApprox(expected, 1e-12)
    assert not task.X_WG0.isApprox(load_task("peg-in-hole").X_WG0, 1e-3)


def test_robot_start_needs_a_pose_or_joints(peg_yaml, tmp_path):
    data = copy.deepcopy(peg_yaml)
    data["robot_start"] = {}
    result = run_cli("graph", str(write_task(tmp_path, data)))
    assert result.exit_code == 2
    assert "robot_start: give the start as 'gripper'" in result.stderr


def test_with_planner_replaces_and_validates_planner_parameters(peg):
    from bilba_dist.errors import TaskError
    from bilba_dist.task.loader import with_planner

    changed = with_planner(peg, race_contacts=0, sample_patience=4)
    assert changed.spec.planner.race_contacts == 0 and changed.spec.planner.sample_patience == 4
    assert peg.spec.planner.race_contacts == 3  # the task file's; the original is untouched
    assert changed.goal == peg.goal and changed.source == peg.source
    with pytest.raises(TaskError, match=r"^planner\.race_chunks: .*greater than or equal to 1$"):
        with_planner(peg, race_chunks=0)
    with pytest.raises(TaskError, match=r"^planner\.racing: Extra inputs"):
        with_planner(peg, racing=3)


def test_the_readme_task_example_loads_with_hex_pegs_environment(tmp_path):
    """The README's task-file example, with its elided walls filled in from hex-peg.yaml and
    its mesh pointed at hex-peg.stl, is a valid task that matches the built-in."""
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    block = readme.split("```yaml\n", 1)[1].split("```", 1)[0]
    data = yaml.safe_load(block)
    builtin = builtin_tasks()["hex-peg"]
    hex_peg = yaml.safe_load(builtin.read_text())
    assert data["environment"]["pieces"] == ["..."]  # YAML reads [...] as one string
    data["environment"]["pieces"] = hex_peg["environment"]["pieces"]
    data["manipuland"]["pieces"][0]["mesh"]["file"] = str(builtin.parent / "hex-peg.stl")
    task = load_task(str(write_task(tmp_path, data)))
    reference = load_task("hex-peg")
    assert task.goal == reference.goal
    assert task.spec.uncertainty == reference.spec.uncertainty
    assert np.allclose(task.manipuland.pieces[0].vertices, reference.manipuland.pieces[0].vertices)


@pytest.mark.parametrize(
    ("planner", "expected"),
    [
        ({}, {"sample_patience": 16, "race_contacts": 3, "prune_rounds": 0, "n_attempts": 0}),
        ({"preset": "paper"}, PAPER_PLANNER),
        ({"preset": "paper", "race_contacts": 2}, {**PAPER_PLANNER, "race_contacts": 2}),
    ],
    ids=["defaults", "paper", "paper with a key of its own"],
)
def test_planner_presets_in_a_task_file(tmp_path, peg_yaml, planner, expected):
    peg_yaml["planner"] = planner
    task = load_task(str(write_task(tmp_path, peg_yaml)))
    assert {k: getattr(task.spec.planner, k) for k in expected} == expected


def test_plan_preset_option_replaces_the_files_settings(tmp_path, peg_yaml):
    """--preset paper gives the authors' values even over a task file's own (recorded in the
    plan file's parameters); an unknown preset is one line and exit 2."""
    peg_yaml["planner"] = {"race_contacts": 5, "gp_rounds": 2}
    path = write_task(tmp_path, peg_yaml)
    out = tmp_path / "plan.json"
    register()
    args = ["plan", str(path), "--workers", "0", "--no-log", "--timeout", "0", "--out", str(out)]
    CliRunner().invoke(cli, [*args, "--preset", "paper"])
    parameters = json.loads(out.read_text())["parameters"]
    assert parameters["race_contacts"] == 0 and parameters["preset"] == "paper"
    assert parameters["gp_rounds"] == 2  # not a preset field: the file's value stays
    bad = CliRunner().invoke(cli, [*args, "--preset", "fast"])
    assert bad.exit_code == 2 and "'fast' is not one of" in bad.output


def test_unknown_preset_in_a_task_file_is_one_line(tmp_path, peg_yaml):
    peg_yaml["planner"] = {"preset": "quick"}
    result = CliRunner().invoke(cli, ["graph", str(write_task(tmp_path, peg_yaml))])
    assert result.exit_code == 2
    assert re.search(r":\d+: planner\.preset: Input should be 'default' or 'paper'", result.output)
