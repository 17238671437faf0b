"""Plans toward a real Panda: frames, driver fits, exported scripts, `bilba execute`.

The exported scripts are checked against franky-control, panda-python and pylibfranka as
installed (the dev extra), without a robot: each script's ``build()`` makes its driver
objects for real, and every method its ``main()`` calls on a robot-side object must exist
on that class with the keywords used (pybind11 signatures, read from the docstrings)."""

import ast
import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.linalg import sqrtm

from bilba_dist.planning.stiffness import VERY_STIFF
from bilba_dist.robot.drivers import (
    DEFAULT_EE_OFFSET_M,
    DRIVER_NAMES,
    DRIVERS,
    ee_to_hand,
    fit,
    fit_hand,
    hand_to_ee,
    joint_limit_warnings,
    to_ee,
    to_hand,
)
from bilba_dist.robot.panda import JOINT_LIMITS
from bilba_dist.task.prismatic import peg_in_hole_task, regular_polygon
from tests.test_task_files import run_cli

ROOT = Path(__file__).resolve().parents[1]
OFFSET = np.array([0.0, 0.0, DEFAULT_EE_OFFSET_M])
finite = st.floats(-1.0, 1.0, allow_nan=False)


def psd(A: np.ndarray) -> np.ndarray:
    return 300.0 * A @ A.T


@given(arrays(float, (6, 6), elements=finite), arrays(float, 3, elements=st.floats(-0.3, 0.3)))
def test_stiffness_moves_between_hand_and_ee_by_the_adjoint(A, r):
    """Round trip hand → EE → hand, and the spring energy of one body displacement is the
    same measured at either point."""
    K = psd(A)
    K_ee = to_ee(K, r)
    assert np.allclose(to_hand(K_ee, r), K, atol=1e-9 * max(1.0, np.abs(K).max()))
    d = np.array([0.01, -0.02, 0.03, 0.001, 0.002, -0.003])  # [ω; v] at the hand
    w, v = d[:3], d[3:]
    d_ee = np.concatenate([v + np.cross(w, r), w])  # [v; ω] at the EE, translation first
    assert d @ K @ d == pytest.approx(d_ee @ K_ee @ d_ee, rel=1e-9, abs=1e-12)


def test_setpoints_move_between_hand_and_ee():
    G = pin.SE3(pin.utils.rotate("x", np.pi) @ pin.utils.rotate("z", 0.3), np.array([0.5, 0, 0.3]))
    X_WE = hand_to_ee(G, OFFSET)
    assert np.allclose(X_WE.translation, G.translation - [0, 0, DEFAULT_EE_OFFSET_M])
    assert ee_to_hand(X_WE, OFFSET).isApprox(G)


@pytest.mark.parametrize("name", DRIVER_NAMES)
@given(arrays(float, (6, 6), elements=finite))
def test_each_fit_is_a_stiffness_the_driver_takes(name, A):
    """PSD, of the driver's form, inside its limits, and a fixed point: fitting again
    changes nothing and says so."""
    driver = DRIVERS[name]
    fitted = fit(psd(A), driver)
    K = fitted.K_ee
    assert np.allclose(K, K.T) and np.linalg.eigvalsh(K).min() >= -1e-9
    block = np.kron(np.eye(2), fitted.frame)
    inner = block.T @ K @ block
    if driver.form != "full":
        assert np.allclose(inner, np.diag(np.diag(inner)), atol=1e-9)
        assert np.allclose(fitted.frame.T @ fitted.frame, np.eye(3))
    low, high = driver.translational
    assert np.all(np.diag(inner)[:3] >= low - 1e-9) and np.all(np.diag(inner)[:3] <= high + 1e-9)
    low, high = driver.rotational
    assert np.all(np.diag(inner)[3:] >= low - 1e-9) and np.all(np.diag(inner)[3:] <= high + 1e-9)
    if driver.form == "scalar":
        assert np.allclose(np.diag(inner)[:3], inner[0, 0])
    again = fit(K, driver)
    assert np.allclose(again.K_ee, K) and again.changes == []


def test_every_clamp_and_projection_is_reported_with_its_size():
    _, ros = fit_hand(VERY_STIFF, pin.utils.rotate("x", np.pi), DRIVERS["franka-ros"], OFFSET)
    assert ros.changes[0].startswith("made isotropic: ")
    assert "translational 600.0 → 400.0 N/m" in ros.changes[1]
    assert re.search(r"rotational 10\d\.\d → 30\.0 N·m/rad", ros.changes[2])
    soft = np.diag([0.5, 0.5, 0.5, 5.0, 5.0, 5.0])  # rotation first, hand frame
    _, lib = fit_hand(soft, np.eye(3), DRIVERS["libfranka"], np.zeros(3))
    assert [c.split()[0:2] for c in lib.changes] == [
        ["x", "5.0"],
        ["y", "5.0"],
        ["z", "5.0"],
        ["rx", "0.5"],
        ["ry", "0.5"],
        ["rz", "0.5"],
    ]
    _, full = fit_hand(VERY_STIFF, np.eye(3), DRIVERS["franky"], OFFSET)
    assert full.changes == []


# -- exported scripts ---------------------------------------------------------------------


def load_script(path):
    spec = importlib.util.spec_from_file_location(path.stem.replace("-", "_"), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def robot_classes(target: str) -> dict[str, list[type]]:
    """Variable name in the scripts' main() → the classes it may hold."""
    if target == "franky":
        import franky

        return {
            "robot": [franky.Robot],
            "motion": [franky.CartesianImpedanceTrackingMotion],
            "pose": [franky.Affine],
        }
    if target == "panda-py":
        import panda_py
        from panda_py import controllers

        return {
            "panda": [panda_py.Panda],
            "robot": [panda_py.libfranka.Robot],
            "controller": [controllers.CartesianImpedance],
            "ctx": [panda_py._core.PandaContext],
        }
    import pylibfranka

    return {
        "robot": [pylibfranka.Robot],
        "control": [pylibfranka.ActiveControlBase],
        "state": [pylibfranka.RobotState],
        "period": [pylibfranka.Duration],
        "command": [pylibfranka.CartesianPose, pylibfranka.JointPositions],
    }


def keywords(member) -> set[str]:
    """Parameter names of a pybind11 method, from its docstring's signature lines."""
    names = set()
    for line in (member.__doc__ or "").splitlines():
        if "(" in line and ") ->" in line:
            names |= set(re.findall(r"[(,]\s*(\w+):", line))
    return names


def check_calls(source: str, classes: dict[str, list[type]]) -> int:
    """Every attribute used on a robot-side variable exists on its class; every keyword
    passed to one of its methods is a parameter of that method. Returns how many."""
    checked = 0
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            owners = classes.get(node.value.id)
            if owners is None:
                continue
            assert any(hasattr(c, node.attr) for c in owners), f"{node.value.id}.{node.attr}"
            checked += 1
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            base = node.func.value
            if isinstance(base, ast.Name) and base.id in classes and node.keywords:
                member = next(
                    getattr(c, node.func.attr)
                    for c in classes[base.id]
                    if hasattr(c, node.func.attr)
                )
                for kw in node.keywords:
                    assert kw.arg in keywords(member), f"{base.id}.{node.func.attr}({kw.arg}=)"
    return checked


def check_script(script: str, target: str, plan: str) -> None:
    """Everything checked of one exported script; run in its own process by the test
    (panda-python and pylibfranka each register a pybind11 type "Duration": one process
    cannot import both)."""
    source = Path(script).read_text()
    compile(source, script, "exec")
    module = load_script(Path(script))
    document = json.loads(Path(plan).read_text())
    assert document["robot"]["start_joints"] == module.START_JOINTS
    assert len(module.MOTIONS) == len(document["motions"])
    lower_torque, upper_torque, lower_force, upper_force = module.COLLISION
    assert len(lower_torque) == len(upper_torque) == 7 and len(lower_force) == len(upper_force) == 6
    assert all(
        lo <= hi
        for lo, hi in zip(lower_torque + lower_force, upper_torque + upper_force, strict=True)
    )
    assert "set_collision_behavior" in source
    built = module.build()  # the driver's own objects, made without a robot
    assert len(built) == len(document["motions"])
    main = next(n for n in ast.parse(source).body if getattr(n, "name", "") == "main")
    assert check_calls(ast.unparse(main), robot_classes(target)) >= 5
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            package = importlib.import_module(node.module)
            assert all(hasattr(package, alias.name) for alias in node.names), node.module
    motion = document["motions"][0]
    G_d = pin.SE3(np.array(motion["G_d"]["rotation"]), np.array(motion["G_d"]["xyz"]))
    K_ee = to_ee(np.array(motion["K"]), G_d.rotation @ OFFSET)
    assert np.allclose(module.MOTIONS[0]["position"], hand_to_ee(G_d, OFFSET).translation)
    if target == "franky":  # what franky holds is the plan's K at the EE, exactly
        assert np.allclose(built[0].get_gains().stiffness, K_ee)
        assert np.allclose(built[0].get_gains().damping, 2 * sqrtm(K_ee))
    if target == "libfranka":  # the diagonal in the stiffness frame, frame given to set_K
        EE_T_K = np.array(built[0][0]).reshape(4, 4, order="F")
        R_WK = G_d.rotation @ EE_T_K[:3, :3]
        block = np.kron(np.eye(2), R_WK)
        fitted = fit(K_ee, DRIVERS["libfranka"]).K_ee
        assert np.allclose(block.T @ fitted @ block, np.diag(built[0][1]))


@pytest.mark.parametrize("target", ["franky", "panda-py", "libfranka"])
def test_exported_scripts_use_only_what_the_driver_has(default_plan_file, target, tmp_path):
    out = tmp_path / f"plan-{target}.py"
    result = run_cli("export", str(default_plan_file), "--target", target, "--out", str(out))
    assert result.exit_code == 0, result.output
    code = "import sys; from tests.test_drivers import check_script; check_script(*sys.argv[1:])"
    checked = subprocess.run(
        [sys.executable, "-c", code, str(out), target, str(default_plan_file)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert checked.returncode == 0, checked.stderr[-3000:]


def test_postures_past_an_fr3s_joint_limits_are_named_for_the_drivers_that_drive_one():
    """Planned on the Panda's model, a start at joint 5 = 2.83 rad (a sideways hand) or a
    setpoint at joint 6 = 0.3 rad is inside the Panda's limits and past the FR3's."""
    panda_low, panda_high = JOINT_LIMITS["Panda"]
    start = np.array([0.0, -0.3, 0.0, -2.2, 2.83, 2.0, 0.78])
    setpoints = [start.copy(), np.array([0.0, -0.3, 0.0, -2.2, 0.0, 0.3, 0.78])]
    for q in (start, *setpoints):
        assert all(lo <= v <= hi for lo, v, hi in zip(panda_low, q, panda_high, strict=True))
    for name in ("franky", "libfranka", "franka-ros"):
        joint5, joint6 = joint_limit_warnings(DRIVERS[name], start, setpoints)
        assert joint5.startswith(
            "on a Franka Research 3, joint 5 is past its limits [-2.8065, 2.8065] rad at the "
            "start (2.8300 rad) and 1 of 2 motions' joint setpoints (to 2.8300)"
        )
        assert joint6.startswith("on a Franka Research 3, joint 6 is past its limits [0.5445, ")
        assert "at 1 of 2 motions' joint setpoints (to 0.3000)" in joint6
    assert joint_limit_warnings(DRIVERS["panda-py"], start, setpoints) == []


@pytest.mark.parametrize("target", DRIVER_NAMES)
def test_the_default_plan_is_within_every_drivers_joint_limits(default_plan_file, target):
    result = run_cli("export", str(default_plan_file), "--target", target)
    assert result.exit_code == 0 and "past its limits" not in result.output, result.output


@pytest.mark.parametrize("target", ["franky", "panda-py"])
def test_exported_collision_thresholds_let_the_plans_own_contacts_through(
    default_plan_file, target
):
    """The default plan presses the peg into its hole with 10-20 N: at franka_control's
    usual 20 N the robot would stop on its own contact. The export replays the plan as the
    driver runs it and raises the upper thresholds to twice the peak where that is needed;
    `bilba execute` reports the same peaks."""
    from bilba_dist.plans.export import driver_motions, with_thresholds
    from bilba_dist.plans.file import read_plan
    from bilba_dist.plans.loads import MARGIN, USUAL_TORQUE, USUAL_WRENCH

    plan = read_plan(default_plan_file)
    exported = with_thresholds(plan, driver_motions(plan, DRIVERS[target], OFFSET))
    t = exported.thresholds
    assert max(t.peak_wrench[:3]) > 5.0  # it does press
    for peak, usual, upper in zip(
        t.peak_wrench + t.peak_torque,
        USUAL_WRENCH + USUAL_TORQUE,
        t.upper_wrench + t.upper_torque,
        strict=True,
    ):
        assert upper >= max(usual, MARGIN * peak) and upper < max(usual, MARGIN * peak) + 1
    assert t.lower_wrench == list(USUAL_WRENCH) and t.lower_torque == list(USUAL_TORQUE)
    assert t.raised == any("raises those upper thresholds" in w for w in exported.warnings)
    if target == "franky":  # the planned clip: execute's peaks are the export's
        result = run_cli("execute", str(default_plan_file), "--driver", target)
        peaks = [float(v) for v in re.findall(r"peak load ([\d.]+) N", result.output)]
        assert len(peaks) == len(plan.motions) and max(peaks) <= max(t.peak_wrench[:3]) + 0.05


def test_a_plan_replays_from_its_recorded_start_joints(default_plan_file, tmp_path):
    """The robot homes to the plan's start_joints, so `execute`, `validate` and `export`
    start there too, even where this version's start IK would pick another posture (here
    the file edited to another IK solution of the same hand pose)."""
    from bilba_dist.belief.start import start_joints
    from bilba_dist.plans.file import read_plan
    from bilba_dist.robot.panda import PandaModel

    document = json.loads(default_plan_file.read_text())
    task = read_plan(default_plan_file).task()
    recorded = np.array(document["robot"]["start_joints"])
    assert np.array_equal(start_joints(task), recorded)
    other = PandaModel().ik(task.X_WG0, recorded + np.array([0.4, 0, -0.4, 0, 0.4, 0, 0.0]))
    assert np.abs(other - recorded).max() > 0.05  # another posture, the same hand pose
    document["robot"]["start_joints"] = other.tolist()
    path = tmp_path / "other.json"
    path.write_text(json.dumps(document))
    assert np.array_equal(start_joints(read_plan(path).task()), other)


def test_the_libfranka_ramp_keeps_within_the_pose_generators_limits(default_plan_file, tmp_path):
    """libfranka's Cartesian pose generator does no rate limiting and stops the arm where the
    commanded pose's acceleration or jerk passes 13 m/s² or 6500 m/s³: a linear ramp at
    0.1 m/s jumps to 100 m/s² in its first millisecond. The script eases the ramp in and out
    (run here at 1 kHz, numpy only), and the simulator runs the same profile."""
    from bilba_dist.workers.motion import ramp_fractions

    out = tmp_path / "lf.py"
    result = run_cli("export", str(default_plan_file), "--target", "libfranka", "--out", str(out))
    assert result.exit_code == 0, result.output
    tree = ast.parse(out.read_text())
    wanted = [n for n in tree.body if getattr(n, "name", "") == "fraction"]
    wanted += [n for n in tree.body if isinstance(n, ast.Assign) and "BLEND_S" in ast.unparse(n)]
    space: dict = {"np": np}
    exec(compile(ast.Module(wanted, []), "fraction", "exec"), space)
    fraction, blend = space["fraction"], space["BLEND_S"]
    assert blend == DRIVERS["libfranka"].ramp_blend_s > 0
    from bilba_dist.workers.settings import SimSettings, driver_settings

    assert driver_settings(SimSettings(), "libfranka").ramp_blend_s == blend
    assert driver_settings(SimSettings(), "franky").ramp_blend_s == 0.0
    dt = 1e-3
    for ramp in (0.2, 0.8, 3.0):  # the shortest ramp, and longer ones, at 0.1 m/s
        t = np.arange(0, ramp + blend + 0.05, dt)
        x = 0.1 * ramp * np.array([fraction(v, ramp) for v in t])
        v, a = np.diff(x) / dt, np.diff(x, 2) / dt**2
        assert x[0] == 0 and x[-1] == pytest.approx(0.1 * ramp)
        assert v.max() <= 0.1 + 1e-9 and abs(a).max() < 13 / 4 and abs(np.diff(a) / dt).max() < 100
        linear = 0.1 * ramp * np.minimum(1.0, t / ramp)
        assert abs(np.diff(linear, 2) / dt**2).max() > 13  # what the script used to send
        steps = round(ramp * 240)  # the simulator's steps at 240 Hz: the same profile
        sim = ramp_fractions(steps, round(blend * 240))
        script = [fraction(k / 240, steps / 240) for k in range(1, len(sim) + 1)]
        assert np.allclose(sim, script, atol=1e-12)


def test_a_plan_past_the_driven_arms_limits_still_exports_with_its_warnings(tmp_path):
    """Our sideways insertion planned on the Panda starts with joint 5 past a Franka
    Research 3's limit: export to franky warns (the robot would refuse it) and still writes
    the script, its collision thresholds from the plan replayed on the Panda."""
    from tests.test_planner import _sideways

    task, plan_path = tmp_path / "sideways.yaml", tmp_path / "sideways.json"
    task.write_text(yaml.safe_dump(_sideways([0.55, 0, 0.45])))
    planned = run_cli("plan", str(task), "--workers", "0", "--no-log", "--out", str(plan_path))
    assert planned.exit_code == 0, planned.output
    out = tmp_path / "sideways-franky.py"
    result = run_cli("export", str(plan_path), "--target", "franky", "--out", str(out))
    assert result.exit_code == 0, result.output
    assert "on a Franka Research 3, joint 5 is past its limits" in result.stderr
    assert "the collision thresholds come from the plan replayed on the arm it was made for" in (
        result.stderr
    )
    assert "COLLISION = " in out.read_text()
    run = run_cli("execute", str(plan_path), "--driver", "franky")
    assert run.exit_code == 2 and run.stderr.count("\n") == 1, run.output
    assert "its start is past the joint limits of the Franka Research 3 that franky" in run.stderr
    assert run.stderr.rstrip().endswith("plan again with --driver franky")


def test_collision_thresholds_rise_only_where_the_plan_needs_it():
    from bilba_dist.plans.loads import Load, collision_thresholds, threshold_note

    quiet = Load(np.array([3.0, 2.0, 9.9, 0.5, 0.5, 0.1]), np.full(7, 2.0))
    pressing = Load(np.array([1.0, 0.0, 14.2, 0.5, 13.0, 0.0]), np.array([11.0, 0, 0, 0, 0, 0, 0]))
    assert not collision_thresholds([quiet]).raised
    t = collision_thresholds([quiet, pressing])
    assert t.upper_wrench == [20.0, 20.0, 29.0, 25.0, 26.0, 25.0]
    assert t.upper_torque == [22.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0]
    note = threshold_note(t)
    assert "z 14.2 N, about y 13.0 N·m, joint 1 11.0 N·m" in note
    assert note.endswith("to z 29 N, about y 26 N·m, joint 1 22 N·m")


def test_franka_ros_parameters_are_its_scalars_within_limits(default_plan_file, tmp_path):
    out = tmp_path / "ros.yaml"
    result = run_cli("export", str(default_plan_file), "--target", "franka-ros", "--out", str(out))
    assert result.exit_code == 0
    assert "warning: motion 1: made isotropic" in result.stderr
    assert re.search(r"motion 1: translational \d+\.\d → 400.0 N/m", result.stderr)
    data = yaml.safe_load(out.read_text())
    for m in data["motions"]:
        assert 0 < m["translational_stiffness"] <= 400 and 0 < m["rotational_stiffness"] <= 30
        assert m["equilibrium_pose"]["frame_id"] == "panda_link0"
    config = data["collision_config"]  # franka_control's parameter, its eight arrays
    assert len(config) == 8 and "&" not in out.read_text()  # no YAML anchors
    assert config["upper_force_thresholds_nominal"] == config["upper_force_thresholds_acceleration"]
    assert all(len(v) == (7 if "torque" in k else 6) for k, v in config.items())


# -- bilba execute ------------------------------------------------------------------------


def test_execute_runs_the_default_plan_to_the_goal(default_plan_file):
    result = run_cli("execute", str(default_plan_file), "--particle", "grasp.pitch=1deg")
    assert result.exit_code == 0, result.output
    assert "goal       (floor/+z, peg/-z): 4 of 4 particles" in result.output
    assert re.search(r"motion 1 +meant \(.*\): 4 of 4 reached", result.output)


def test_execute_names_the_particles_a_driver_loses(default_plan_file):
    """The default plan (stiffer than franka-ros allows) run with its scalar gains: the
    command says which particles miss and where they are."""
    result = run_cli("execute", str(default_plan_file), "--driver", "franka-ros")
    assert result.exit_code == 1, result.output
    assert "missed by  particle 0 (nominal)" in result.output
    assert re.search(r"particle \d \(.*\) is in \(", result.output)


@pytest.fixture(scope="module")
def own_task(tmp_path_factory):
    """A task of our own: a hexagonal peg, 2 mm clearance, 5 mm chamfer."""
    path = tmp_path_factory.mktemp("task") / "hexagon.yaml"
    data = peg_in_hole_task("hexagon", [regular_polygon(6, 0.055)], 0.002, 0.005)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.mark.parametrize("driver", ["franka-ros", "libfranka"])
def test_a_plan_made_for_a_driver_executes_with_it(own_task, driver, tmp_path):
    out = tmp_path / "plan.json"
    result = run_cli("plan", str(own_task), "--driver", driver, "--workers", "0", "--no-log",
                     "--out", str(out), "-u", "grasp.x=5mm")  # fmt: skip
    assert result.exit_code == 0, result.output
    document = json.loads(out.read_text())
    assert document["robot"]["driver"] == driver
    exported = run_cli("export", str(out), "--target", driver, "--out", str(tmp_path / "x"))
    assert "% of |K|" not in exported.stderr and "limit" not in exported.stderr
    executed = run_cli("execute", str(out), "--driver", driver)
    assert executed.exit_code == 0, executed.output
    assert "3 of 3 particles" in executed.output


def test_plan_files_of_version_1_still_read_and_execute(tmp_path):
    v1 = Path(__file__).parent / "data" / "peg-plan-v1.json"
    result = run_cli("execute", str(v1))
    assert result.exit_code == 0, result.output
    refused = run_cli("export", str(v1), "--target", "franky", "--out", str(tmp_path / "x.py"))
    assert refused.exit_code == 2 and "no start joints" in refused.stderr


def test_the_plan_schema_is_valid_and_describes_what_we_write(default_plan_file):
    import jsonschema

    from bilba_dist.plans.file import plan_schema

    jsonschema.Draft202012Validator.check_schema(plan_schema())
    document = json.loads(default_plan_file.read_text())
    jsonschema.Draft202012Validator(plan_schema()).validate(document)
    assert set(document) == set(plan_schema()["properties"])


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["execute", "{plan}", "--particle", "grasp.q=3mm"], "unknown uncertainty axis 'grasp.q'"),
        (["execute", "{plan}", "--particle", "grasp.x=nan"], "--particle"),
        (["execute", "{plan}", "--particle", "grasp.x=1mm,grasp.x=2mm"], "given twice"),
        (["execute", "{broken}"], "malformed plan file"),
        (["execute", "{plan}", "--gui"], "--gui needs a display"),
        (["export", "{plan}", "--target", "franky", "--ee-offset", "0.1,0.2"], "three"),
        (["export", "{plan}", "--target", "franky", "--ee-offset", "9"], "is not within"),
        (["export", "{missing}", "--target", "franky"], "missing.json"),
    ],
)
def test_bad_input_to_execute_and_export_is_one_line(default_plan_file, args, fragment, tmp_path,
                                                     monkeypatch):  # fmt: skip
    monkeypatch.delenv("DISPLAY", raising=False)
    broken = tmp_path / "broken.json"
    document = json.loads(default_plan_file.read_text())
    document["motions"][0]["timeout_s"] = "five"
    broken.write_text(json.dumps(document))
    paths = {"plan": default_plan_file, "broken": broken, "missing": tmp_path / "missing.json"}
    result = run_cli(*[a.format(**paths) for a in args])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and fragment in result.output
    assert len(result.output.strip().splitlines()) == 1 or "Usage:" in result.output


def test_a_plan_from_before_a_new_setting_still_reads(default_plan_file, tmp_path):
    """The embedded task's hash is of the task as stored: a file whose planner section
    lacks a setting a later bilba added (here `check_random`) reads, and executes."""
    import hashlib

    document = json.loads(default_plan_file.read_text())
    spec = document["task"]["spec"]
    del spec["planner"]["check_random"]
    document["task"]["hash"] = hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()
    older = tmp_path / "older.json"
    older.write_text(json.dumps(document))
    result = run_cli("execute", str(older))
    assert result.exit_code == 0, result.output


def test_the_ik_keeps_to_the_pandas_specified_joint_limits_not_the_urdfs():
    """pybullet_data's Panda URDF allows joint 5 to ±2.9671 rad; the robot stops at ±2.8973.
    The IK clips to the model's limits, so those must be the specified ones."""
    from bilba_dist.robot.panda import PandaModel

    model = PandaModel()
    low, high = JOINT_LIMITS["Panda"]
    assert model.model.upperPositionLimit[4] > high[4]  # the URDF's is wider
    assert model.lower.tolist() == list(low) and model.upper.tolist() == list(high)


def test_a_plan_for_an_fr3_driver_keeps_to_the_fr3s_joint_limits():
    """planner.driver franky plans within the FR3's limits: the forward-pointing start that
    a Panda reaches with joint 5 at 2.83 rad (past the FR3's 2.8065) is refused for it, in
    one line naming the arm; for panda-py it is found."""
    from bilba_dist.belief.start import start_joints
    from bilba_dist.errors import TaskError
    from bilba_dist.robot.panda import PandaModel
    from bilba_dist.task.loader import load_task, with_planner
    from tests.test_planner import _sideways

    both = PandaModel(arms=("Panda", "Franka Research 3"))
    assert both.upper[4] == 2.8065 and both.lower[5] == 0.5445 and both.upper[5] == 3.7525
    task = load_task(_sideways([0.55, 0, 0.45]))
    q = start_joints(with_planner(task, driver="panda-py"))
    assert 2.8065 < abs(q[4]) <= 2.8973
    with pytest.raises(
        TaskError, match=r"within the Franka Research 3's \(planner.driver franky\) joint limits"
    ):
        start_joints(with_planner(task, driver="franky"))


@pytest.mark.parametrize("driver", ["none", "franky"])
def test_the_simulated_arm_stops_where_the_ik_does(driver):
    """The PyBullet arm's joint limits are the planning model's (the Panda's specified ones,
    or the FR3's within the URDF for franky), not pybullet_data's wider URDF limits."""
    import pybullet as p

    from bilba_dist.belief.particles import initial_belief
    from bilba_dist.task.loader import load_task, with_planner
    from bilba_dist.workers.rollout_worker import RolloutWorker

    task = with_planner(load_task("peg-in-hole"), driver=driver)
    worker = RolloutWorker(task)
    sim = worker.panda_sim(initial_belief(task)[0].X_GM)
    info = [p.getJointInfo(sim.robot, j, physicsClientId=sim.client) for j in sim.joints]
    worker.close()
    assert [i[8] for i in info] == pytest.approx(sim.model.lower.tolist(), abs=1e-12)
    assert [i[9] for i in info] == pytest.approx(sim.model.upper.tolist(), abs=1e-12)
    assert sim.model.upper[4] == (2.8973 if driver == "none" else 2.8065)
