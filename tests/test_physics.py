"""Rollouts on the PyBullet Panda and the floating model (real physics, no mocks)."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest

from bilba_dist.belief.particles import initial_belief, make_particle
from bilba_dist.belief.start import start_state
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.pose import pose_from_xyz_rpy
from bilba_dist.robot.panda import HAND
from bilba_dist.rollout import Motion, RolloutRequest
from bilba_dist.task.loader import load_task, with_planner
from bilba_dist.workers.rollout_worker import RolloutWorker
from bilba_dist.workers.settings import SimSettings
from bilba_dist.workers.urdf import FLANGE_LINK, panda_with_part

VERY_STIFF = np.diag([100.0, 100.0, 100.0, 600.0, 600.0, 600.0])
FLAT = "tests/data/flat.yaml"


def moved(X: pin.SE3, xyz=(0, 0, 0), rpy=(0, 0, 0)) -> pin.SE3:
    """``X`` translated in world axes and rotated about its own axes."""
    return pin.SE3(X.rotation, X.translation + np.array(xyz)) * pose_from_xyz_rpy([0, 0, 0], rpy)


@pytest.fixture(scope="module")
def nominal_peg():
    task = load_task("peg-in-hole", ["grasp.pitch=0deg"])
    return task, initial_belief(task)[0]


@pytest.fixture(scope="module", params=["panda", "floating"])
def worker(request, nominal_peg):
    w = RolloutWorker(nominal_peg[0], request.param, SimSettings(early_stop=False))
    yield w
    w.close()


def run(worker, task, particle, G_d, K=VERY_STIFF, state=None):
    state = state or start_state(task, particle)
    (result,) = worker.simulate([RolloutRequest(particle, state, Motion(K, G_d))])
    return result


def gripper(result, particle) -> pin.SE3:
    return result.state.X_WM * particle.X_GM.inverse()


def test_arm_holds_still_under_gravity(nominal_peg):
    task, particle = nominal_peg
    worker = RolloutWorker(task, "panda", SimSettings(early_stop=False))
    result = run(worker, task, particle, task.X_WG0)
    assert result.sim_time_s == pytest.approx(5.0)
    drift = np.linalg.norm(gripper(result, particle).translation - task.X_WG0.translation)
    assert drift < 1e-3
    worker.close()


def test_free_space_motion_converges(worker, nominal_peg):
    task, particle = nominal_peg
    G_d = moved(task.X_WG0, xyz=(0.04, -0.03, 0.05), rpy=(0, 0, 0.2))
    X_WG = gripper(run(worker, task, particle, G_d), particle)
    assert np.linalg.norm(X_WG.translation - G_d.translation) < 2e-3
    assert np.degrees(np.linalg.norm(pin.log3(X_WG.rotation.T @ G_d.rotation))) < 1.0


def test_peg_pressed_onto_a_flat_face_reports_exactly_that_pair():
    task = load_task(FLAT)
    (particle,) = initial_belief(task)
    for model in ("panda", "floating"):
        worker = RolloutWorker(task, model)
        result = run(worker, task, particle, moved(task.X_WG0, xyz=(0, 0, -0.11)))
        assert result.contacts == {ContactPair("block/+z", "peg/-z")}, model
        worker.close()


def test_spring_wrench_is_clipped_when_pressing_deep():
    """A setpoint 10 cm inside a flat face stretches the 600 N/m spring by ~10 cm: the arm
    pushes with the 20 N norm limit, not ~60 N (the limit's branch of the control loop)."""
    task = load_task(FLAT)
    (particle,) = initial_belief(task)
    deep = moved(task.X_WG0, xyz=(0, 0, -0.21))
    forces = {}
    for limit in (20.0, 1000.0):
        worker = RolloutWorker(task, "panda", SimSettings(spring_limit=limit))
        result = run(worker, task, particle, deep)
        assert result.contacts == {ContactPair("block/+z", "peg/-z")}
        sim = worker.panda_sim(particle.X_GM)
        points = p.getContactPoints(bodyA=sim.robot, physicsClientId=sim.client)
        forces[limit] = sum(pt[9] for pt in points)
        # the rollout's peak spring wrench (what export sets the collision thresholds from)
        # is the force the face holds
        assert result.peak_wrench[5] == pytest.approx(forces[limit], rel=0.1)
        assert result.peak_joint_torque.shape == (7,) and result.peak_joint_torque.max() > 1
        worker.close()
    assert forces[20.0] == pytest.approx(20.0, abs=1.5)
    assert forces[1000.0] > 45.0


def test_cartesian_ramp_keeps_the_hand_on_the_straight_line(nominal_peg):
    """A straight joint ramp bows the hand ~2 mm off an 8 cm descent; the IK-waypoint ramp
    stays within 0.05 mm, and both end at the joint setpoint."""
    from bilba_dist.robot.panda import Q_CENTRE
    from bilba_dist.workers.motion import ramp_steps

    task, particle = nominal_peg
    X0 = task.X_WG0
    X1 = moved(X0, xyz=(0.03, 0, -0.08))
    off_line = {}
    for cartesian in (False, True):
        worker = RolloutWorker(task, "panda", SimSettings(cartesian_ramp=cartesian))
        sim = worker.panda_sim(particle.X_GM)
        q0 = sim.model.ik(X0, Q_CENTRE)
        q1 = sim.model.ik(X1, q0)
        ramp = sim._ramp(q0, q1, X1, ramp_steps(X0, X1, sim.settings))
        assert np.allclose(ramp[-1], q1, rtol=0, atol=1e-12)
        u = (X1.translation - X0.translation) / np.linalg.norm(X1.translation - X0.translation)
        offsets = [sim.model.fk(q).translation - X0.translation for q in ramp]
        off_line[cartesian] = max(np.linalg.norm(d - (d @ u) * u) for d in offsets)
        worker.close()
    assert off_line[False] > 1e-3
    assert off_line[True] < 5e-5


def test_task_file_switches_the_cartesian_ramp_on(nominal_peg):
    task, particle = nominal_peg
    planner = task.spec.planner.model_copy(update={"cartesian_ramp": True})
    spec = task.spec.model_copy(update={"planner": planner})
    worker = RolloutWorker(task, "panda")
    sim = worker.panda_sim(particle.X_GM)
    assert not sim.settings.cartesian_ramp
    worker.set_task(spec)  # same parts: the world is kept, and follows the new settings
    assert worker.panda_sim(particle.X_GM) is sim and sim.settings.cartesian_ramp
    worker.close()
    assert RolloutWorker(spec, "panda").settings.cartesian_ramp


def test_ramped_motion_into_the_hole_reaches_the_bottom(worker, nominal_peg):
    task, particle = nominal_peg
    down = moved(task.X_WG0, xyz=(0, 0, -0.135))  # 5 mm below the hole bottom
    result = run(worker, task, particle, down)
    assert task.goal in result.contacts
    assert result.state.X_WM.translation[2] == pytest.approx(0.04 + 0.075, abs=1e-3)


def test_same_rollout_twice_is_bit_identical(worker, nominal_peg):
    task, particle = nominal_peg
    down = moved(task.X_WG0, xyz=(0.01, 0, -0.135))
    first = run(worker, task, particle, down)
    run(worker, task, particle, moved(task.X_WG0, xyz=(-0.02, 0.01, -0.1)))  # history between
    again = run(worker, task, particle, down)
    assert np.array_equal(first.state.X_WM.homogeneous, again.state.X_WM.homogeneous)
    assert np.array_equal(first.state.q, again.state.q)
    assert first.contacts == again.contacts and first.sim_time_s == again.sim_time_s


def test_unreachable_setpoint_is_reported_not_raised(nominal_peg):
    task, particle = nominal_peg
    worker = RolloutWorker(task, "panda")
    result = run(worker, task, particle, moved(task.X_WG0, xyz=(2.0, 0, 0)))
    assert not result.reachable
    assert result.sim_time_s == 0.0
    worker.close()


def test_a_joint_at_its_limit_stops_the_particle_as_a_reflex_would():
    """A Franka halts with a reflex when a joint reaches its limit; the simulated arm would
    rest on the stop and go on. From a posture with joint 7 on its upper limit, holding the
    hand there, the particle stops: no contact, the reason kept, and every later rollout
    leaves it where it is without simulating; a belief holding it counts no particle in.
    0.05 rad inside the limit, the same motion runs as usual."""
    from bilba_dist.belief.state import Belief

    task = load_task(FLAT)
    (particle,) = initial_belief(task)
    worker = RolloutWorker(task, "panda")
    model = worker.panda_sim(particle.X_GM).model
    for inside, stops in ((0.0, True), (0.05, False)):
        q = start_state(task, particle).q.copy()
        q[6] = model.upper[6] - inside
        X_WG = model.fk(q)
        state = start_state(task, particle).__class__(X_WM=X_WG * particle.X_GM, q=q)
        result = run(worker, task, particle, X_WG, state=state)
        assert (result.state.stopped is not None) == stops
        if not stops:
            continue
        assert result.state.stopped.startswith("joint 7 reached its upper limit (2.8973 rad)")
        assert result.contacts == frozenset() and result.sim_time_s > 0
        later = run(
            worker, task, particle, moved(task.X_WG0, xyz=(0, 0, -0.11)), state=result.state
        )
        assert later.state is result.state and later.sim_time_s == 0.0
        belief = Belief((particle,), (later.state,), ({ContactPair("block/+z", "peg/-z")},))
        assert belief.count(frozenset({ContactPair("block/+z", "peg/-z")})) == 0
    worker.close()


def test_the_start_posture_keeps_clear_of_every_joint_limit():
    """A start given by joints with joint 7 on its limit would stop a Franka before the
    first motion: the start IK takes another posture of the same hand pose."""
    import yaml

    from bilba_dist.belief.start import start_joints
    from bilba_dist.robot.panda import LIMIT_MARGIN_RAD, Q_CENTRE, PandaModel

    model = PandaModel()
    on_limit = Q_CENTRE.copy()
    on_limit[6] = model.upper[6]
    data = yaml.safe_load(Path(FLAT).read_text())
    data["robot_start"] = {"joints": on_limit.tolist()}
    task = load_task(data)
    q = start_joints(task)
    assert np.all(q > model.lower + LIMIT_MARGIN_RAD) and np.all(q < model.upper - LIMIT_MARGIN_RAD)
    assert np.allclose(model.fk(q).homogeneous, task.X_WG0.homogeneous, atol=1e-5)


def link_index(robot: int, client: int, name: str) -> int:
    return next(
        j
        for j in range(p.getNumJoints(robot, physicsClientId=client))
        if p.getJointInfo(robot, j, physicsClientId=client)[12] == name.encode()
    )


def test_pinocchio_gravity_and_jacobian_match_pybullet(nominal_peg):
    task, particle = nominal_peg
    worker = RolloutWorker(task, "panda")
    sim = worker.panda_sim(particle.X_GM)
    rng = np.random.default_rng(0)
    client, robot = sim.client, sim.robot
    flange = link_index(robot, client, FLANGE_LINK)  # the hand is merged into it
    model = sim.model.model
    hand_in_flange = model.frames[model.getFrameId(HAND)].placement.translation
    # measured (pybullet 3.2.7): the point is taken from the link frame's origin, but in the
    # axes of the link's inertial frame (the merged flange's principal axes)
    inertial_axes = p.getLinkState(robot, flange, physicsClientId=client)[3]
    R_inertial = np.reshape(p.getMatrixFromQuaternion(inertial_axes), (3, 3))
    for _ in range(10):
        q = rng.uniform(sim.model.lower, sim.model.upper)
        J, g = sim.model.jacobian_and_gravity(q)
        g_bullet = p.calculateInverseDynamics(
            robot, q.tolist(), [0.0] * 7, [0.0] * 7, physicsClientId=client
        )
        assert np.allclose(g, g_bullet, atol=1e-8)
        sim.reset(particle.X_WO, q, np.zeros(7), (1.0, 1.0))
        linear, angular = p.calculateJacobian(
            robot,
            flange,
            (R_inertial.T @ hand_in_flange).tolist(),
            q.tolist(),
            [0.0] * 7,
            [0.0] * 7,
            physicsClientId=client,
        )
        assert np.allclose(J, np.vstack([angular, linear]), atol=1e-8)
    worker.close()


def test_the_merged_hand_has_the_dynamics_of_its_links(tmp_path, nominal_peg):
    """The hand's fixed links merged into the flange: 8 links instead of 13, and PyBullet's
    mass matrix and gravity torques those of the unmerged robot (to rounding)."""
    task, particle = nominal_peg
    client = p.connect(p.DIRECT)
    try:
        robots = [
            p.loadURDF(
                str(
                    panda_with_part(
                        task.manipuland, particle.X_GM, 0.3, tmp_path / str(merge), merge_hand=merge
                    )
                ),
                useFixedBase=True,
                flags=p.URDF_USE_INERTIA_FROM_FILE,
                physicsClientId=client,
            )
            for merge in (False, True)
        ]
        assert [p.getNumJoints(r, physicsClientId=client) for r in robots] == [13, 8]
        rng = np.random.default_rng(1)
        for _ in range(5):
            q7 = rng.uniform(-1.5, 1.5, 7).tolist()
            M = [np.array(p.calculateMassMatrix(r, q7, physicsClientId=client)) for r in robots]
            g = [
                p.calculateInverseDynamics(r, q7, [0.0] * 7, [0.0] * 7, physicsClientId=client)
                for r in robots
            ]
            assert np.allclose(M[0], M[1], rtol=1e-12, atol=1e-12)
            assert np.allclose(g[0], g[1], rtol=1e-12, atol=1e-12)
    finally:
        p.disconnect(client)


def test_worker_keeps_its_worlds_until_the_geometry_changes(nominal_peg):
    task, particle = nominal_peg
    worker = RolloutWorker(task, "panda")
    sim = worker.panda_sim(particle.X_GM)
    assert worker.panda_sim(particle.X_GM.copy()) is sim
    worker.set_task(load_task("peg-in-hole", ["grasp.x=1cm"]))  # same parts: kept
    assert worker.panda_sim(particle.X_GM) is sim
    changed = load_task("peg-in-hole")
    spec = changed.spec.model_copy(update={"friction": 0.3})
    worker.set_task(spec)  # new friction: rebuilt
    assert worker.panda_sim(particle.X_GM) is not sim
    worker.close()


def fixed_motion_set(task, n: int, seed: int):
    """Seeded motions from the start towards and into the hole, for every particle."""
    rng = np.random.default_rng(seed)
    particles = initial_belief(task)
    requests = []
    for k in range(n):
        particle = particles[k % len(particles)]
        offset = rng.uniform([-0.02, -0.02, -0.15], [0.02, 0.02, -0.08])
        K = VERY_STIFF if k % 2 else np.diag([60.0, 60.0, 60.0, 400.0, 400.0, 400.0])
        requests.append(
            RolloutRequest(
                particle, start_state(task, particle), Motion(K, moved(task.X_WG0, offset))
            )
        )
    return requests


@pytest.mark.parametrize(
    "K",
    [
        np.triu(np.ones((6, 6))),  # not symmetric
        np.diag([100.0, 100.0, 100.0, 600.0, 600.0, -1.0]),  # a negative stiffness
        np.full((6, 6), np.nan),
    ],
)
def test_a_motion_refuses_a_stiffness_that_is_not_symmetric_psd(K):
    for _ in range(2):  # the check is cached: a refused K stays refused
        with pytest.raises(ValueError, match="symmetric positive semi-definite"):
            Motion(K, pin.SE3.Identity())


@pytest.mark.parametrize("rate_hz", [240, 120])
@pytest.mark.parametrize("model", ["panda", "floating"])
def test_early_stop_changes_at_most_a_grazing_contact(model, rate_hz):
    task = with_planner(load_task("peg-in-hole", ["grasp.x=1cm"]), sim_timestep_s=1 / rate_hz)
    requests = fixed_motion_set(task, 50, seed=11)
    full = RolloutWorker(task, model, SimSettings(early_stop=False)).simulate(requests)
    early = RolloutWorker(task, model, SimSettings(early_stop=True)).simulate(requests)
    # A contact set may differ by a pair grazing the 0.2 mm contact distance (the Panda: one
    # of 50 at 240 Hz, two at 120 Hz, a corner on a chamfer with the part 0.02 mm from where
    # the full-length rollout leaves it), no more
    differ = [(e, f) for e, f in zip(early, full, strict=True) if e.contacts != f.contacts]
    assert len(differ) <= (1 if rate_hz == 240 else 2)
    for e, f in differ:
        apart = np.linalg.norm(e.state.X_WM.translation - f.state.X_WM.translation)
        assert apart < SimSettings().contact_distance_m
    assert sum(r.settled for r in early) >= 40  # it does stop early on most
    assert sum(r.sim_time_s for r in early) < 0.6 * sum(r.sim_time_s for r in full)


@pytest.mark.parametrize("far", [False, True], ids=["within the spring limit", "clipped"])
def test_compiled_control_step_matches_the_impedance_law(far):
    """The compiled step against the law written out in numpy, at random gains and states:
    τ = clip(Jᵀ·clip(K J e) + k_n N e − B_q q̇ + g, ±limits), e = q_ref − q."""
    from scipy.linalg import sqrtm

    from bilba_dist.robot.panda import Q_CENTRE, TORQUE_LIMITS, PandaModel
    from bilba_dist.workers.control_step import joint_torque
    from bilba_dist.workers.panda_sim import JointImpedance

    rng = np.random.default_rng(7)
    model, settings = PandaModel(), SimSettings()
    settled = 0
    for _ in range(40):
        q_d = Q_CENTRE + rng.normal(scale=0.2, size=7)
        A = rng.normal(size=(6, 6))
        K = A @ A.T * 50 + np.diag([10, 10, 10, 100, 100, 100.0])
        gains = JointImpedance.at(model, q_d, K, settings)
        J, _ = model.jacobian_and_gravity(q_d)
        N = np.eye(7) - J.T @ np.linalg.inv(J @ J.T + 1e-6 * np.eye(6)) @ J  # damped, as used
        K_null = settings.null_stiffness * N
        B_q = J.T @ (2 * np.real(sqrtm(K))) @ J + settings.null_damping * N
        ramp = q_d + rng.normal(scale=0.02, size=(5, 7))
        x = np.concatenate(
            [
                ramp[3] + rng.normal(scale=0.3 if far else 0.002, size=7),
                rng.normal(scale=0.05, size=7),
            ]
        )
        g = rng.normal(scale=5, size=7)
        e = ramp[3] - x[:7]
        wrench = K @ J @ e
        norm = np.linalg.norm(wrench)
        assert (norm > 20.0) == far
        wrench = wrench * min(1.0, 20.0 / norm)
        expected = J.T @ wrench + K_null @ e - B_q @ x[7:] + g
        expected = np.clip(expected, -TORQUE_LIMITS, TORQUE_LIMITS)
        tau = np.zeros(34)
        tau[7:20] = 0.5  # peaks so far: kept where the step's own are lower
        tau[20:27], tau[27:] = x[:7] + 0.01, x[:7] - 0.01  # joint ranges so far
        feed = ramp @ gains.ref_gains.T
        calm = 0.1
        still = joint_torque(
            gains.state_gains, feed, 3, x, gains.Jt, 20.0, g, TORQUE_LIMITS, tau, calm
        )
        assert np.allclose(tau[:7], expected, rtol=1e-9, atol=1e-9)
        assert np.allclose(tau[7:13], np.maximum(0.5, np.abs(wrench)), rtol=1e-9)
        assert np.allclose(tau[13:20], np.maximum(0.5, np.abs(J.T @ wrench)), rtol=1e-9)
        assert np.array_equal(tau[20:27], x[:7]) and np.array_equal(tau[27:], x[:7])
        assert still == bool(np.all(np.abs(x[7:]) < calm))
        settled += still
    assert 0 < settled < 40  # both answers of the settle test were checked


@pytest.mark.parametrize("rate_hz", [240.0, 480.0])
def test_a_four_motion_puzzle_plan_works_across_the_grasp_interval(rate_hz):
    """The puzzle has a conformant plan in our physics for every grasp offset in ±1 cm (not
    just the three planning particles): land on the -x bar's top, slide +x pressing down
    until the part drops against the +x slot wall, drop onto the rail, slide +y until the
    neck meets the far bar. Found by hand (benchmarks/HISTORY.md, the puzzle); 9 particles,
    36 rollouts. At twice the step rate too: its success is not luck of the time step, as
    the planner's puzzle plans' is (benchmarks/README.md)."""
    task = with_planner(load_task("puzzle"), sim_timestep_s=1 / rate_hz)
    particles = [make_particle(task, {"grasp.x": dx}) for dx in np.linspace(-0.01, 0.01, 9)]
    soft_x = np.diag([100.0, 100.0, 100.0, 400.0, 600.0, 600.0])
    R, x0 = task.X_WG0.rotation, task.X_WG0.translation[0]
    motions = [  # (gripper x offset, y, z) [m], K
        ((-0.01525, 0.0, 0.293), soft_x),
        ((0.025, 0.0, 0.263), soft_x),
        ((0.005, 0.0, 0.212), VERY_STIFF),
        ((0.005, 0.0205, 0.215), VERY_STIFF),
    ]
    worker = RolloutWorker(task, "panda")
    states = [start_state(task, q) for q in particles]
    for (dx, y, z), K in motions:
        G_d = pin.SE3(R, np.array([x0 + dx, y, z]))
        results = worker.simulate(
            [RolloutRequest(q, s, Motion(K, G_d)) for q, s in zip(particles, states, strict=True)]
        )
        states = [r.state for r in results]
    worker.close()
    assert [task.goal in r.contacts for r in results] == [True] * 9


def test_a_rollout_does_not_depend_on_what_its_world_ran_before():
    """restoreState leaves the broadphase pairs and contact manifolds: a rollout that starts
    resting on a bar right after the rollout that put it there warm-started from that
    rollout's contacts, and a seeded puzzle plan differed in-process and on Ray. Motions
    from that plan (puzzle, nominal particle: a landing on the -y bar, then a slide)."""
    task = load_task("puzzle")
    particle = initial_belief(task)[0]
    R = task.X_WG0.rotation
    land_K = np.zeros((6, 6))
    land_K[:3, :3] = [[60.7307, 0.0, -5.35658], [0.0, 100.0, 0.0], [-5.35658, 0.0, 99.2693]]
    land_K[3:, 3:] = np.diag([600.0, 400.0, 600.0])
    land = Motion(land_K, pin.SE3(R, np.array([0.490227, -0.003333, 0.267477])))
    slide_K = np.diag([100.0, 60.0, 100.0, 400.0, 600.0, 600.0])
    slide = Motion(slide_K, pin.SE3(R, np.array([0.493704, -0.000342, 0.266828])))
    worker = RolloutWorker(task, "panda")
    (landed,) = worker.simulate([RolloutRequest(particle, start_state(task, particle), land)])
    request = RolloutRequest(particle, landed.state, slide)
    (after,) = worker.simulate([request])  # the same world, straight after the landing
    fresh = RolloutWorker(task, "panda")
    (alone,) = fresh.simulate([request])
    worker.close()
    fresh.close()
    assert np.array_equal(after.state.q, alone.state.q)
    assert np.array_equal(after.state.X_WM.homogeneous, alone.state.X_WM.homogeneous)


def test_a_worker_dropped_without_close_disconnects_its_worlds():
    """Each world is a PyBullet connection (~33 MB); a RolloutWorker that is dropped without
    close() must not keep them until the process ends (a benchmark grew to 12 GB so)."""
    import gc

    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    worker = RolloutWorker(task, "floating")
    clients = [worker.panda_sim(p.X_GM).client for p in initial_belief(task)]
    clients.append(worker._floating_sim().client)
    assert len(set(clients)) == 4 and all(p.isConnected(c) for c in clients)
    del worker
    gc.collect()
    assert not any(p.isConnected(c) for c in clients)
    with RolloutWorker(task) as worker:  # or closed at the end of a with block
        client = worker.panda_sim(task.X_GM).client
    assert not p.isConnected(client)


def test_a_closed_world_never_disconnects_a_client_reused_after_it():
    """PyBullet reuses a closed connection's id: closing twice (close(), then the drop)
    must not close the world that got the id next."""
    task = load_task("peg-in-hole")
    first = RolloutWorker(task)
    sim = first.panda_sim(task.X_GM)
    first.close()
    second = RolloutWorker(task)
    client = second.panda_sim(task.X_GM).client
    sim.close()
    del sim, first
    assert p.isConnected(client)
    second.close()
