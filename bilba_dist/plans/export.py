"""`bilba export`: a plan file in one Franka driver's terms (docs/drivers.md).

`driver_motions` turns each motion into what the driver will hold — the setpoint moved from
``panda_hand`` to the driver's EE frame, K carried there by the adjoint, axes swapped to
translation first, then fitted to the driver's form and limits — with a line for every
approximation. `bilba execute --driver` simulates the same fitted stiffness, so what the
export warns about is what the simulation tries.

The scripts need only the driver's package and numpy on the robot's PC. Each has a
``build()`` that makes every driver object a motion needs without a robot (the tests call
it against the installed packages) and a ``main(host)`` that homes, sets the payload and
runs the motions, each ramping the EE setpoint at the plan's rates and holding it until the
motion's timeout.
"""

import json
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pinocchio as pin

from bilba_dist.errors import BilbaError
from bilba_dist.planning.result import PlannedMotion
from bilba_dist.plans.file import PlanFile
from bilba_dist.plans.loads import (
    Load,
    Thresholds,
    collision_thresholds,
    friction_twins,
    plan_loads,
    threshold_note,
)
from bilba_dist.robot.drivers import (
    R_FLANGE_HAND,
    Driver,
    Fit,
    fit_hand,
    hand_to_ee,
    joint_limit_warnings,
)
from bilba_dist.task.loader import Task


@dataclass(frozen=True)
class DriverMotion:
    X_WE: pin.SE3  # the EE setpoint
    fit: Fit  # the stiffness the driver holds, translation first at the EE
    K_hand: np.ndarray  # the same, back in the plan's frame (what execute simulates)
    timeout_s: float
    contact: str


@dataclass(frozen=True)
class Export:
    driver: Driver
    offset: np.ndarray
    motions: list[DriverMotion]
    warnings: list[str]
    #: collision thresholds the script sets (`with_thresholds`); None: franka_control's usual
    thresholds: Thresholds | None = None


def driver_motions(plan: PlanFile, driver: Driver, offset: np.ndarray) -> Export:
    """Each motion of ``plan`` as ``driver`` will run it, with a warning per change."""
    warnings: list[str] = []
    motions = []
    for i, m in enumerate(plan.motions):
        K_hand, fitted = fit_hand(m.K, m.G_d.rotation, driver, offset)
        warnings += [f"motion {i + 1}: {change}" for change in fitted.changes]
        contact = f"({m.contact.env}, {m.contact.manip})"
        motions.append(
            DriverMotion(hand_to_ee(m.G_d, offset), fitted, K_hand, m.timeout_s, contact)
        )
    controller = plan.document.get("controller", {})
    if controller.get("wrench_clip") and not driver.wrench_clip:
        warnings.append(
            f"{driver.name} cannot bound the spring wrench; the plan was simulated with a "
            f"{controller['wrench_clip']:g} N clip (bilba execute --driver {driver.name} "
            "simulates without it)"
        )
    if driver.name == "franka-ros":
        warnings.append(
            "franka-ros's example controller filters the equilibrium pose (first order, "
            "~0.2 s); ramp the pose you publish at the plan's rates, given in the parameter file"
        )
    warnings += joint_limit_warnings(driver, plan.start_joints, [m.q_d for m in plan.motions])
    planned_for = (plan.document.get("robot") or {}).get("driver")
    if planned_for not in (None, driver.name):
        warnings.append(f"the plan was made for {planned_for}, exported for {driver.name}")
    return Export(driver, offset, motions, warnings)


def driven_motions(plan: PlanFile, export: Export | None) -> list[PlannedMotion]:
    """The plan's motions with each K replaced by what the driver holds."""
    if export is None:
        return list(plan.motions)
    return [replace(m, K=d.K_hand) for m, d in zip(plan.motions, export.motions, strict=True)]


def with_thresholds(plan: PlanFile, export: Export) -> Export:
    """``export`` with the collision thresholds its plan needs: the plan replayed as the
    driver runs it (`bilba execute --driver`) on its planning particles at the verification
    frictions, each motion's peak load kept (plans/loads.py). Where the driver's arm cannot
    reach the plan's start within its joint limits (already a warning), the loads are the
    plan's as planned, on its own arm, and a warning says so."""
    from bilba_dist.errors import TaskError
    from bilba_dist.task.loader import with_planner

    warnings = list(export.warnings)
    try:
        loads = _replay_loads(with_planner(plan.task(), driver=export.driver.name), plan, export)
    except TaskError:
        loads = _replay_loads(plan.task(), plan, export)
        warnings.append(
            f"the start is past the {export.driver.name} arm's joint limits: the collision "
            "thresholds come from the plan replayed on the arm it was made for"
        )
    thresholds = collision_thresholds(loads)
    if thresholds.raised:
        warnings.append(threshold_note(thresholds))
    return replace(export, thresholds=thresholds, warnings=warnings)


def _replay_loads(task: Task, plan: PlanFile, export: Export) -> list[Load]:
    from bilba_dist.belief.particles import initial_belief
    from bilba_dist.workers.rollout_worker import RolloutWorker

    worker = RolloutWorker(task, "panda")
    try:
        particles = friction_twins(task, initial_belief(task))
        return plan_loads(task, driven_motions(plan, export), particles, worker)
    finally:
        worker.close()


def payload(plan: PlanFile) -> tuple[float, list[float], list[float]]:
    """Mass [kg], centre of mass in the flange frame [m], inertia about it in the flange
    axes (column-major 3×3) [kg·m²]: the part as a solid box of its bounds."""
    doc = plan.document
    if "payload" not in doc:
        return 0.0, [0.0, 0.0, 0.0], [0.0] * 9
    task = plan.task()
    mass = float(doc["payload"]["mass_kg"])
    low, high = task.manipuland.bounds()
    a, b, c = high - low
    I_M = mass / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    R_FM = R_FLANGE_HAND @ task.X_GM.rotation
    com_F = R_FLANGE_HAND @ np.array(doc["payload"]["com_hand_m"], dtype=float)
    I_F = R_FM @ I_M @ R_FM.T
    return mass, com_F.tolist(), I_F.flatten(order="F").tolist()


def _rates(plan: PlanFile) -> tuple[float, float, float]:
    c = plan.document.get("controller", {})
    return c.get("ramp_speed_m_s", 0.1), c.get("ramp_speed_rad_s", 0.5), c.get("min_ramp_s", 0.2)


def _data(plan: PlanFile, export: Export) -> dict[str, Any]:
    """What every script holds, as plain lists (printed with repr: exact floats)."""
    mass, com, inertia = payload(plan)
    start = plan.start_joints
    if start is None:
        raise BilbaError("a version-1 plan file has no start joints: replan to export it")
    motions = []
    for m in export.motions:
        quat = pin.Quaternion(m.X_WE.rotation).coeffs()  # x, y, z, w
        K = m.fit.K_ee
        motions.append(
            {
                "position": m.X_WE.translation.tolist(),
                "quat_xyzw": quat.tolist(),
                "O_T_EE": m.X_WE.homogeneous.flatten(order="F").tolist(),
                "K": K.tolist(),
                "D": m.fit.damping().tolist(),
                "frame": m.fit.frame.tolist(),
                "diagonal": m.fit.diagonal.tolist(),
                "timeout_s": m.timeout_s,
                "contact": m.contact,
                "error_clip": _error_clip(K, plan),
            }
        )
    speed, turn, min_s = _rates(plan)
    t = export.thresholds or collision_thresholds([])
    return {
        "collision": [t.lower_torque, t.upper_torque, t.lower_wrench, t.upper_wrench],
        "start_joints": start.tolist(),
        "payload": [mass, com, inertia],
        "ramp": [speed, turn, min_s],
        "ee_offset": export.offset.tolist(),
        "motions": motions,
    }


def _error_clip(K: np.ndarray, plan: PlanFile) -> list[list[float]]:
    """franky's per-axis error clips that keep each spring force within the plan's wrench
    clip (translational [m], rotational [rad])."""
    clip = float(plan.document.get("controller", {}).get("wrench_clip", 20.0))
    t = clip / max(float(np.linalg.eigvalsh(K[:3, :3]).max()), 1e-9)
    r = clip / max(float(np.linalg.eigvalsh(K[3:, 3:]).max()), 1e-9)
    return [[t] * 3, [r] * 3]


_COMMON = '''
def ramp_s(p0, q0, p1, q1):
    """The plan's ramp: translation and rotation at their rates, the slower one sets it."""
    angle = 2 * np.arccos(min(1.0, abs(float(np.dot(q0, q1)))))
    return max(np.linalg.norm(np.subtract(p1, p0)) / RAMP[0], angle / RAMP[1], RAMP[2])


def interpolate(p0, q0, p1, q1, s):
    """Position and quaternion (x, y, z, w) a fraction s of the way (slerp)."""
    q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
    if np.dot(q0, q1) < 0:
        q1 = -q1
    theta = np.arccos(min(1.0, float(np.dot(q0, q1))))
    if theta < 1e-9:
        q = q0
    else:
        q = (np.sin((1 - s) * theta) * q0 + np.sin(s * theta) * q1) / np.sin(theta)
    return np.asarray(p0) + s * (np.subtract(p1, p0)), q / np.linalg.norm(q)


def quat_of(R):
    """(x, y, z, w) of a rotation matrix."""
    R = np.asarray(R, float)
    w = np.sqrt(max(0.0, 1 + R[0, 0] + R[1, 1] + R[2, 2])) / 2
    x = np.copysign(np.sqrt(max(0.0, 1 + R[0, 0] - R[1, 1] - R[2, 2])) / 2, R[2, 1] - R[1, 2])
    y = np.copysign(np.sqrt(max(0.0, 1 - R[0, 0] + R[1, 1] - R[2, 2])) / 2, R[0, 2] - R[2, 0])
    z = np.copysign(np.sqrt(max(0.0, 1 - R[0, 0] - R[1, 1] + R[2, 2])) / 2, R[1, 0] - R[0, 1])
    return np.array([x, y, z, w])
'''

_FRANKY = '''
from franky import (
    Affine,
    CartesianImpedanceGains,
    CartesianImpedanceTrackingMotion,
    CartesianReference,
    JointMotion,
    JointState,
    Robot,
)

RATE_HZ = 200  # setpoint updates per second during a ramp


def build():
    """Every motion's franky object, its gains set (full 6x6 K and D, translation first,
    base axes at the EE). Needs no robot."""
    built = []
    for m in MOTIONS:
        gains = CartesianImpedanceGains()
        gains.stiffness = np.array(m["K"])
        gains.damping = np.array(m["D"])
        motion = CartesianImpedanceTrackingMotion(
            translational_error_clip=np.array(m["error_clip"][0]),
            rotational_error_clip=np.array(m["error_clip"][1]),
        )
        motion.set_gains(gains)
        built.append(motion)
    return built


def main(host):
    robot = Robot(host)
    robot.recover_from_errors()
    robot.relative_dynamics_factor = 0.1
    robot.set_load(*PAYLOAD)
    robot.set_collision_behavior(
        lower_torque_threshold=COLLISION[0],
        upper_torque_threshold=COLLISION[1],
        lower_force_threshold=COLLISION[2],
        upper_force_threshold=COLLISION[3],
    )
    robot.move(JointMotion(JointState(np.array(START_JOINTS))))
    for i, (m, motion) in enumerate(zip(MOTIONS, build())):
        pose = robot.current_pose.end_effector_pose
        p0, q0 = pose.translation, pose.quaternion
        motion.set_reference(CartesianReference(Affine(p0, q0)))
        robot.move(motion, asynchronous=True)
        began, ramp = time.monotonic(), ramp_s(p0, q0, m["position"], m["quat_xyzw"])
        while (t := time.monotonic() - began) < m["timeout_s"]:
            p, q = interpolate(p0, q0, m["position"], m["quat_xyzw"], min(1.0, t / ramp))
            motion.set_reference(CartesianReference(Affine(p, q)))
            time.sleep(1 / RATE_HZ)
        robot.stop()
        print(f"motion {i + 1}/{len(MOTIONS)} done: meant to reach {m['contact']}")
'''

_PANDA_PY = '''
import panda_py
from panda_py import controllers

RATE_HZ = 200


def build():
    """Every motion's panda-py controller: K diagonal in base axes (its damping, 2*sqrt(K)
    element-wise, is then right). Needs no robot."""
    return [
        controllers.CartesianImpedance(
            impedance=np.array(m["K"]), damping_ratio=1.0, nullspace_stiffness=0.5
        )
        for m in MOTIONS
    ]


def main(host):
    panda = panda_py.Panda(host)
    robot = panda.get_robot()
    robot.set_load(*PAYLOAD)
    robot.set_collision_behavior(
        lower_torque_thresholds=COLLISION[0],
        upper_torque_thresholds=COLLISION[1],
        lower_force_thresholds=COLLISION[2],
        upper_force_thresholds=COLLISION[3],
    )
    panda.move_to_joint_position(np.array(START_JOINTS))
    for i, (m, controller) in enumerate(zip(MOTIONS, build())):
        p0, q0 = panda.get_position(), panda.get_orientation()
        ramp = ramp_s(p0, q0, m["position"], m["quat_xyzw"])
        q_null = panda.q
        panda.start_controller(controller)
        with panda.create_context(frequency=RATE_HZ, max_runtime=m["timeout_s"]) as ctx:
            while ctx.ok():
                t = controller.get_time()
                p, q = interpolate(p0, q0, m["position"], m["quat_xyzw"], min(1.0, t / ramp))
                controller.set_control(p, q, q_null)
        panda.stop_controller()
        print(f"motion {i + 1}/{len(MOTIONS)} done: meant to reach {m['contact']}")
'''

_LIBFRANKA = '''
from pylibfranka import CartesianPose, ControllerMode, JointPositions, Robot


def build():
    """Every motion's stiffness frame (EE_T_K, column-major) and its 6 values: K diagonal
    in that frame, as libfranka's internal impedance takes it. Needs no robot."""
    built = []
    for m in MOTIONS:
        pose = np.array(m["O_T_EE"]).reshape(4, 4, order="F")
        EE_T_K = np.eye(4)
        EE_T_K[:3, :3] = pose[:3, :3].T @ np.array(m["frame"])  # frame given in base axes
        built.append((EE_T_K.flatten(order="F").tolist(), list(m["diagonal"])))
    return built


BLEND_S = 0.1  # the ramp's speed eases in and out over this long (raised cosine)


def fraction(t, ramp):
    """How far along its ramp the setpoint is at time t: the plan's constant speed (1/ramp
    of the way a second), eased in and out over BLEND_S so that velocity and acceleration
    are continuous. libfranka's Cartesian pose generator does no rate limiting of its own
    and stops the arm on a jump (at 0.1 m/s in 1 ms: 100 m/s^2, past its 13); eased, the
    peaks are pi/2 the speed per BLEND_S (1.6 m/s^2 at 0.1 m/s) and about 49 m/s^3. The
    setpoint trails the plan's by speed * BLEND_S / 2 (5 mm) and arrives BLEND_S later."""
    b, v = BLEND_S, 1.0 / ramp

    def eased(u):  # distance covered u seconds into an ease-in
        return v * (u / 2 - b / (2 * np.pi) * np.sin(np.pi * u / b))

    if t <= 0:
        return 0.0
    if t < b:
        return eased(t)
    if t <= ramp:
        return v * (t - b / 2)
    if t < ramp + b:
        return 1.0 - eased(ramp + b - t)
    return 1.0


def home(robot):
    control = robot.start_joint_position_control(ControllerMode.JointImpedance)
    state, _ = control.readOnce()
    q0, elapsed, duration = np.array(state.q), 0.0, 5.0
    while elapsed < duration:
        state, period = control.readOnce()
        elapsed += period.to_sec()
        s = min(1.0, elapsed / duration)
        s = s * s * (3 - 2 * s)  # smooth start and stop
        command = JointPositions((q0 + s * (np.array(START_JOINTS) - q0)).tolist())
        command.motion_finished = elapsed >= duration
        control.writeOnce(command)


def main(host):
    robot = Robot(host)
    robot.set_load(*PAYLOAD)
    robot.set_collision_behavior(
        lower_torque_thresholds=COLLISION[0],
        upper_torque_thresholds=COLLISION[1],
        lower_force_thresholds=COLLISION[2],
        upper_force_thresholds=COLLISION[3],
    )
    home(robot)
    for i, (m, (EE_T_K, values)) in enumerate(zip(MOTIONS, build())):
        robot.set_K(EE_T_K)
        robot.set_cartesian_impedance(values)
        control = robot.start_cartesian_pose_control(ControllerMode.CartesianImpedance)
        state, _ = control.readOnce()
        start = np.array(state.O_T_EE_c).reshape(4, 4, order="F")  # the last commanded pose
        p0, q0 = start[:3, 3], quat_of(start[:3, :3])
        ramp = ramp_s(p0, q0, m["position"], m["quat_xyzw"])
        elapsed = 0.0
        while elapsed < m["timeout_s"]:
            state, period = control.readOnce()
            elapsed += period.to_sec()
            p, q = interpolate(p0, q0, m["position"], m["quat_xyzw"], fraction(elapsed, ramp))
            x, y, z, w = q
            R = np.array([
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ])
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = R, p
            command = CartesianPose(pose.flatten(order="F").tolist())
            command.motion_finished = elapsed >= m["timeout_s"]
            control.writeOnce(command)
        print(f"motion {i + 1}/{len(MOTIONS)} done: meant to reach {m['contact']}")
'''

_BODIES = {"franky": _FRANKY, "panda-py": _PANDA_PY, "libfranka": _LIBFRANKA}


def export_text(plan: PlanFile, export: Export, source: str) -> str:
    """The script (or franka-ros parameter file) for ``export``."""
    data = _data(plan, export)
    driver = export.driver
    header = [
        f"bilba plan {source} for {driver.name} ({driver.package}), written by bilba export.",
        f"Robot: {driver.robot}.",
        f"EE (TCP) origin assumed at {data['ee_offset']} m in the panda_hand frame: set the "
        "same in Desk, or export again with --ee-offset.",
        f"Stiffness: {driver.form}; damping {driver.damping}.",
        *[f"warning: {w}" for w in export.warnings],
    ]
    if driver.name == "franka-ros":
        return _franka_ros(data, header)
    lines = ['"""' + "\n".join(header) + "\n\nUsage: python3 THIS_FILE ROBOT_HOST\n" + '"""']
    lines += ["", "import sys", "import time", "", "import numpy as np"]
    body = _BODIES[driver.name]
    imports, _, rest = body.partition("\n\n\n")
    lines += [imports.rstrip(), ""]
    lines += [f"START_JOINTS = {data['start_joints']!r}"]
    lines += [f"PAYLOAD = {data['payload']!r}  # mass [kg], F_x_Cload [m], inertia [kg m^2]"]
    lines += [f"RAMP = {data['ramp']!r}  # [m/s], [rad/s], shortest ramp [s]"]
    lines += [
        "# Collision thresholds: lower and upper per joint [N m], lower and upper per Cartesian",
        "# axis at the EE, x y z [N] then about x y z [N m]; past an upper one the robot stops",
        f"COLLISION = {data['collision']!r}",
    ]
    lines += ["MOTIONS = " + json.dumps(data["motions"], indent=4), ""]
    lines += [_COMMON.rstrip(), "", rest.rstrip(), ""]
    lines += ['if __name__ == "__main__":']
    lines += ["    if len(sys.argv) != 2:", '        sys.exit(f"usage: {sys.argv[0]} ROBOT_HOST")']
    lines += ["    main(sys.argv[1])", ""]
    return "\n".join(lines)


CONTROLLER = "cartesian_impedance_example_controller"


def _collision_config(collision: list[list[float]]) -> dict[str, list[float]]:
    """franka_control's ``collision_config`` (its eight arrays: the same thresholds while the
    arm accelerates and at nominal speed)."""
    lower_torque, upper_torque, lower_force, upper_force = collision
    config = {}
    for phase in ("acceleration", "nominal"):  # copies: no YAML anchors in the file
        config[f"lower_torque_thresholds_{phase}"] = list(lower_torque)
        config[f"upper_torque_thresholds_{phase}"] = list(upper_torque)
        config[f"lower_force_thresholds_{phase}"] = list(lower_force)
        config[f"upper_force_thresholds_{phase}"] = list(upper_force)
    return config


def _franka_ros(data: dict[str, Any], header: list[str]) -> str:
    """A parameter file for franka_example_controllers' cartesian_impedance_example_controller
    (dynamic_reconfigure: translational_stiffness, rotational_stiffness; the equilibrium pose
    topic, panda_link0 frame)."""
    import yaml

    motions = []
    for m in data["motions"]:
        motions.append(
            {
                "translational_stiffness": m["diagonal"][0],
                "rotational_stiffness": m["diagonal"][3],
                "equilibrium_pose": {
                    "frame_id": "panda_link0",
                    "position": m["position"],
                    "orientation_xyzw": m["quat_xyzw"],
                },
                "timeout_s": m["timeout_s"],
                "contact": m["contact"],
            }
        )
    document = {
        "controller": "franka_example_controllers/CartesianImpedanceExampleController",
        "equilibrium_topic": f"/{CONTROLLER}/equilibrium_pose",
        "reconfigure": f"/{CONTROLLER}/dynamic_reconfigure_compliance_param_node",
        "start_joints": data["start_joints"],
        "payload": dict(zip(["mass_kg", "F_x_Cload_m", "inertia"], data["payload"], strict=True)),
        # franka_control's own parameter: load it into its namespace before it starts
        "collision_config": _collision_config(data["collision"]),
        "ramp": dict(zip(["speed_m_s", "speed_rad_s", "min_s"], data["ramp"], strict=True)),
        "motions": motions,
    }
    comment = "".join(f"# {line}\n" for line in header)
    return comment + yaml.safe_dump(document, sort_keys=False, width=100)
