"""Plans beyond their particles: friction and mass as belief axes, robust acceptance, and
`bilba validate --map`."""

import csv
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from bilba_dist.belief.particles import initial_belief, make_particle
from bilba_dist.belief.start import start_belief
from bilba_dist.planning.bilba import check_belief, plan, planning_particles
from bilba_dist.plans.file import read_plan
from bilba_dist.plans.replay import replay
from bilba_dist.rollout import Motion
from bilba_dist.task.loader import load_task, with_friction, with_planner, with_preset
from bilba_dist.workers.rollout_worker import RolloutWorker
from tests.test_task_files import run_cli


def test_friction_and_mass_are_axes_of_the_belief():
    task = load_task("peg-in-hole", ["grasp.x=1cm", "friction=50%", "mass=20%"])
    assert task.spec.uncertainty == pytest.approx({"grasp.x": 0.01, "friction": 0.5, "mass": 0.2})
    scales = sorted((p.friction_scale, p.mass_scale) for p in initial_belief(task))
    expected = [(0.5, 1), (1, 0.8), (1, 1), (1, 1), (1, 1), (1, 1.2), (1.5, 1)]
    assert np.allclose(scales, expected)
    hot = make_particle(task, {"friction": 0.5})
    assert hot.X_GM.isApprox(task.X_GM) and hot.X_WO.isApprox(task.X_WO)  # no pose change


@pytest.mark.parametrize(
    ("bound", "fragment"),
    [
        ("friction=150%", "friction: 150 % is outside ±90 %"),
        ("friction=-10%", "bounds must be >= 0: friction"),
        ("mass=2cm", "unit 'cm' is not a fraction unit"),
        ("grip.friction=5%", "unknown uncertainty axis 'grip.friction'"),
        ("friction=nan", "cannot read 'nan' as a fraction"),
    ],
)
def test_a_bad_physical_bound_is_one_line(bound, fragment):
    result = run_cli("graph", "peg-in-hole", "-u", bound)
    assert result.exit_code == 2, result.output
    assert fragment in result.stderr and len(result.stderr.strip().splitlines()) == 1


@pytest.fixture(scope="module")
def slide():
    """A motion that slides the peg across the hole's top (pressed down, pulled along x)."""
    task = load_task("peg-in-hole", ["friction=50%"])
    G_d = task.X_WG0 * pin.SE3(np.eye(3), np.array([0.05, 0.0, 0.0]))
    G_d = pin.SE3(G_d.rotation, G_d.translation - np.array([0.0, 0.0, 0.05]))
    return task, Motion(np.diag([60.0, 60, 60, 400, 400, 400]), G_d, 3.0)


def test_a_particles_friction_is_the_tasks_friction_scaled(slide):
    """A particle at friction +50 % ends exactly where the nominal particle of a task with
    1.5 μ ends, and elsewhere than at nominal friction."""
    task, motion = slide
    hot = make_particle(task, {"friction": 0.5})
    worker = RolloutWorker(task)
    (by_particle,) = replay(task, [_planned(motion)], [hot], worker).states
    (nominal,) = replay(task, [_planned(motion)], [make_particle(task, {})], worker).states
    scaled = with_friction(task, 1.5)
    (by_task,) = replay(scaled, [_planned(motion)], [make_particle(scaled, {})],
                        RolloutWorker(scaled)).states  # fmt: skip
    assert np.allclose(by_particle.X_WM.translation, by_task.X_WM.translation, atol=1e-9)
    assert np.linalg.norm(by_particle.X_WM.translation - nominal.X_WM.translation) > 1e-4


def test_a_particles_mass_moves_the_part_but_not_the_controllers_model(slide):
    task, motion = slide
    heavy = make_particle(task, {"mass": 0.8})
    worker = RolloutWorker(task)
    (light,) = replay(task, [_planned(motion)], [make_particle(task, {})], worker).states
    (loaded,) = replay(task, [_planned(motion)], [heavy], worker).states
    assert np.linalg.norm(loaded.q - light.q) > 1e-5  # gravity compensation is for 1x


def _planned(motion: Motion):
    from bilba_dist.geometry.contact import ContactPair
    from bilba_dist.planning.result import PlannedMotion

    free = ContactPair("free", "free")
    return PlannedMotion(motion.K, motion.G_d, np.zeros(7), motion.timeout_s, free, 0.0)


def test_robust_acceptance_brings_every_check_particle_home():
    """By default the planning particles are simulated at 1.5 μ and their twins at μ and
    0.5 μ (and, with check_random, particles drawn inside the bounds at all three) are check
    particles: the plan brings each of them to the goal when replayed on it from the start
    (what the planner believed of them is what happens)."""
    task = with_planner(load_task("peg-in-hole", ["grasp.pitch=2deg"]), check_random=2)
    assert task.spec.planner.check_friction == 0.5  # the default
    worker = RolloutWorker(task)
    result = plan(task, worker, "bilba-fixed", seed=0)
    assert result.success, result.reason
    planning = planning_particles(task, initial_belief(task))
    assert [p.friction_scale for p in planning] == [1.5] * 3
    check = check_belief(task, initial_belief(task))
    assert check is not None and len(check) == 2 * 3 + 3 * 2
    assert sorted(p.friction_scale for p in check.particles) == [0.5] * 5 + [1.0] * 5 + [1.5] * 2
    assert result.final_belief is not None and result.final_belief.check is not None
    assert result.final_belief.check.count(frozenset([task.goal])) == len(check)
    final = replay(task, result.motions, [*planning, *check.particles], worker)
    assert all(task.goal in c for c in final.contacts)


@pytest.mark.parametrize(
    ("task", "why"),
    [
        (with_planner(load_task("peg-in-hole"), check_friction=0.0), "switched off"),
        (load_task("peg-in-hole", ["grasp.x=1cm", "friction=30%"]), "friction is an axis"),
        (with_preset(load_task("peg-in-hole"), "paper"), "the authors' planner"),
    ],
)
def test_without_robust_acceptance_the_belief_is_planned_as_given(task, why):
    particles = initial_belief(task)
    assert planning_particles(task, particles) == particles, why
    assert check_belief(task, particles) is None, why
    assert start_belief(task, particles).check is None


def test_validate_maps_success_over_two_axes(default_plan_file, tmp_path):
    prefix = tmp_path / "maps" / "map.v2"  # a folder that is not there yet; a dotted name
    args = ["--map", "grasp.x=2cm", "--map", "friction=50%", "--points", "5"]
    result = run_cli(
        "validate", str(default_plan_file), "--workers", "0", *args, "--map-out", str(prefix)
    )
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader((tmp_path / "maps" / "map.v2.csv").open()))
    assert len(rows) == 25 and set(rows[0]) == {"grasp.x", "friction", "success"}
    at = {(float(r["grasp.x"]), float(r["friction"])): int(r["success"]) for r in rows}
    assert at[(0.0, 0.0)] == 1  # the nominal particle: the plan works there
    assert at[(0.02, 0.0)] == 0 and at[(-0.02, 0.0)] == 0  # 2 cm off in x: no pitch plan does
    assert (tmp_path / "maps" / "map.v2.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    fraction = sum(at.values()) / 25
    assert (
        f"map:             {fraction:.3f} of 25 over grasp.x ±2cm x friction ±50%" in result.output
    )


def test_validate_replays_at_the_time_step_asked_for(default_plan_file):
    """`--timestep` replays in a finer (or coarser) simulation than the plan's; the header
    names the step of the task the replay ran on."""
    plain = run_cli("validate", str(default_plan_file), "--workers", "0")
    assert plain.exit_code == 0, plain.output
    step = read_plan(default_plan_file).task().spec.planner.sim_timestep_s
    assert f"step {step * 1000:g} ms)" in plain.output
    fine = run_cli("validate", str(default_plan_file), "--workers", "0", "--timestep", "0.002")
    assert fine.exit_code == 0, fine.output
    assert "step 2 ms)" in fine.output and "1.000 of 3 reach" in fine.output
    bad = run_cli("validate", str(default_plan_file), "--workers", "0", "--timestep", "0.5")
    assert bad.exit_code == 2 and "Traceback" not in bad.output
    assert "'--timestep': 0.5 is not within" in bad.stderr, bad.output


@pytest.mark.parametrize(
    ("given", "csv_name", "png_name"),
    [
        ("out/run.v2", "run.v2.csv", "run.v2.png"),  # with_suffix wrote run.png, run.csv
        ("out/step0.00208", "step0.00208.csv", "step0.00208.png"),
        ("out/map.PNG", "map.csv", "map.png"),
        ("out/map.csv", "map.csv", "map.png"),
        ("out/map", "map.csv", "map.png"),
    ],
)
def test_a_map_prefix_keeps_its_dots(given, csv_name, png_name):
    from bilba_dist.cli.validate import map_paths

    csv_path, png_path = map_paths(Path(given))
    assert (csv_path, png_path) == (Path("out") / csv_name, Path("out") / png_name)


def test_a_map_that_cannot_be_written_is_refused_before_it_is_computed(
    default_plan_file, tmp_path, monkeypatch
):
    """A folder that cannot be made (here: under a file) is reported before any replay, not
    after the map's rollouts."""

    def replayed(*args, **kwargs):
        raise AssertionError("replayed before the output folder was checked")

    monkeypatch.setattr("bilba_dist.cli.validate.validate_plan", replayed)
    monkeypatch.setattr("bilba_dist.cli.validate.success_map", replayed)
    (tmp_path / "a-file").write_text("")
    out = tmp_path / "a-file" / "maps" / "map"
    args = ["--map", "grasp.x=1cm", "--map-out", str(out)]
    result = run_cli("validate", str(default_plan_file), "--workers", "0", *args)
    assert result.exit_code == 2, result.output
    assert f"bilba: error: {out}.csv: cannot make its folder" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    ("maps", "fragment"),
    [
        (["grasp.x=1cm", "env.y=1cm", "friction=5%"], "one or two axes"),
        (["grasp.x=1cm", "grasp.x=2cm"], "given twice"),
        (["grasp.x=0cm"], "bounds must be > 0"),
        (["speed=3"], "unknown uncertainty axis 'speed'"),
        (["grasp.x"], "write AXIS=VALUE"),
    ],
)
def test_a_bad_map_is_one_line(default_plan_file, maps, fragment):
    args = [a for m in maps for a in ("--map", m)]
    result = run_cli("validate", str(default_plan_file), "--workers", "0", *args)
    assert result.exit_code == 2 and fragment in result.stderr, result.output
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_motion_that_loses_a_check_particle_does_not_win(default_plan_file):
    """The default plan's first motion wins its contact on the planning belief; with a
    check particle it cannot bring along (the environment 5 cm off) it is scored, its check
    simulated, and not returned as the winner."""
    from bilba_dist.planning.evaluate import Candidate, Evaluator

    plan_file = read_plan(default_plan_file)
    task = plan_file.task()
    first = plan_file.motions[0]
    accept = frozenset(m.contact for m in plan_file.motions)
    evaluator = Evaluator(RolloutWorker(task))
    belief = start_belief(task, initial_belief(task))
    candidate = Candidate(Motion(first.K, first.G_d, first.timeout_s), 0)
    _, winner = evaluator.score(belief, [candidate], accept)
    assert winner is not None and winner.checked == -1
    far = start_belief(task, [make_particle(task, {"env.y": 0.05})])
    scored, winner = evaluator.score(belief.with_check(far), [candidate], accept)
    assert winner is None
    assert scored[0].count == len(belief) and scored[0].checked == 0
    assert scored[0].posterior is not None and scored[0].posterior.check is not None


def _default_plan_start(plan_path):
    """The default plan's task, first motion and accept set, a worker, and the planning and
    check particles at the start."""
    plan_file = read_plan(plan_path)
    task = plan_file.task()
    accept = frozenset(m.contact for m in plan_file.motions)
    particles = initial_belief(task)
    planning = start_belief(task, planning_particles(task, particles))
    check = check_belief(task, particles)
    assert check is not None
    return task, plan_file.motions[0], accept, RolloutWorker(task), planning, check


def test_when_only_check_particles_lag_a_candidate_is_screened_on_one_of_them(default_plan_file):
    """Every planning particle in the default plan's first contact, its check particles still
    at the start: a motion that brings none of them in costs one rollout (screened on a
    lagging check particle; no planning particle is run), the plan's first motion is run on
    all and wins, and MakeContact samples setpoints on the lagging check particles too."""
    from bilba_dist.planning.bilba import contact_search
    from bilba_dist.planning.evaluate import Candidate, Evaluator, lagging_checks
    from bilba_dist.planning.make_contact import sampled_candidates

    task, first, accept, worker, planning, check = _default_plan_start(default_plan_file)
    motion = Motion(first.K, first.G_d, first.timeout_s)
    _, reached = Evaluator(worker).score(planning, [Candidate(motion, 0)], accept)
    assert reached is not None and reached.posterior is not None
    lagging = reached.posterior.with_check(check)  # planning particles in, checks at the start
    assert lagging_checks(lagging, accept) == list(range(len(check)))
    assert lagging_checks(planning.with_check(check), accept) == []  # planning ones not in yet

    # The same motion cut short: the planning particles stay pressed in, the check particles
    # do not get there from the start (before, it was run on all 9 to find that out).
    short = Motion(first.K, first.G_d, 0.05)
    for candidate, rollouts in ((Candidate(short, 0), 1), (Candidate(motion, 0), 3 + 6)):
        evaluator = Evaluator(worker)
        scored, winner = evaluator.score(lagging, [candidate], accept)
        assert evaluator.rollouts == rollouts
        if candidate.motion is short:
            assert winner is None and scored[0].posterior is None
        else:
            assert winner is not None and (winner.count, winner.checked) == (3, 6)

    search = contact_search(task, Evaluator(worker), "bilba-fixed", deadline=float("inf"))
    rng = np.random.default_rng(0)
    _, candidates = sampled_candidates(search, lagging, first.contact, accept, rng)
    on_check = [c.screen_on for c in candidates if c.on_check]
    assert set(on_check) == set(range(len(check)))  # the lagging ones take turns too
    assert {c.screen_on for c in candidates if not c.on_check} == set(range(len(planning)))
    _, candidates = sampled_candidates(search, planning, first.contact, accept, rng)
    assert candidates and not any(c.on_check for c in candidates)
    worker.close()


def test_a_race_prefetches_no_screen_of_a_candidate_made_for_a_check_particle(
    default_plan_file,
):
    """In a race, the chunk after one contact's may be another contact's, sampled on its
    lagging check particles: its screens are on check particles, so the contact scored now
    (no check particle lagging) must not prefetch them as planning particles' (it raised an
    IndexError: a check particle's index past the planning particles', puzzle pitch ±2°)."""
    from bilba_dist.planning.evaluate import Candidate, Evaluator, lagging_checks

    _, first, accept, worker, planning, check = _default_plan_start(default_plan_file)
    assert len(check) > len(planning)
    belief = planning.with_check(check)
    assert lagging_checks(belief, accept) == []
    motion = Motion(first.K, first.G_d, first.timeout_s)
    then = [Candidate(motion, len(check) - 1, on_check=True)]
    evaluator = Evaluator(worker)
    _, winner = evaluator.score(belief, [Candidate(motion, 0)], accept, then=then)
    assert winner is not None and winner.count == len(planning)
    assert winner.checked == len(check) and evaluator.rollouts == len(planning) + len(check)
    worker.close()


def test_a_contact_every_particle_is_in_already_is_made_without_a_motion(default_plan_file):
    """A schedule from the contact reached need not be the one that reached it, so the
    belief may already be in its next contact: that contact is made with no motion and no
    rollout (before, MakeContact searched for a motion that adds a particle, found none,
    and pruned a good edge: puzzle env.y ±1 cm fixed, seed 1)."""
    from bilba_dist.modes.schedule import belief_graph
    from bilba_dist.planning.bilba import _next_contact, already_made, contact_search
    from bilba_dist.planning.evaluate import Evaluator
    from bilba_dist.planning.result import PlanResult

    task, _, _, worker, planning, check = _default_plan_start(default_plan_file)
    motions = read_plan(default_plan_file).motions
    home = replay(task, motions, planning.particles, worker).with_check(
        replay(task, motions, check.particles, worker)
    )
    evaluator = Evaluator(worker)
    search = contact_search(task, evaluator, "bilba-fixed", deadline=float("inf"))
    graph, _ = belief_graph(task, initial_belief(task), task.X_WG0, search.cache)
    schedule = graph.schedule()
    assert already_made(home, schedule) and not already_made(planning.with_check(check), schedule)
    result = PlanResult(False, "", [], "bilba-fixed", 0)
    rng = np.random.default_rng(0)
    followed, outcome = _next_contact(graph, home, schedule[0], search, rng, 0, result)
    assert outcome.success and outcome.steps == [] and outcome.belief is home
    assert followed == schedule and evaluator.rollouts == 0
    worker.close()


def test_a_heavy_particle_leaves_the_world_as_it_found_it(slide):
    """Particles' physics are set on the shared world only when they change, the part's
    inertia scaled with its mass (PyBullet, given a mass alone, recomputes the inertia from
    the collision shape): a nominal rollout after a heavy, slippery one is bit-identical to
    one before it, and the part's inertia is the URDF's again."""
    import pybullet as p

    task, motion = slide
    worker = RolloutWorker(task)
    nominal, heavy = make_particle(task, {}), make_particle(task, {"mass": 0.8, "friction": -0.5})
    sim = worker.panda_sim(nominal.X_GM)  # the world, before any rollout
    inertia = p.getDynamicsInfo(sim.robot, sim.part_link, physicsClientId=sim.client)[2]
    (first,) = replay(task, [_planned(motion)], [nominal], worker).states
    replay(task, [_planned(motion)], [heavy], worker)
    (again,) = replay(task, [_planned(motion)], [nominal], worker).states
    assert np.array_equal(first.q, again.q) and np.array_equal(first.dq, again.dq)
    after = p.getDynamicsInfo(sim.robot, sim.part_link, physicsClientId=sim.client)
    assert after[2] == inertia and after[0] == pytest.approx(task.spec.manipuland.mass)


def test_friction_axis_and_map_on_a_task_of_our_own(tmp_path):
    """A hexagonal peg (2 mm clearance) planned with friction as a belief axis holds at its
    friction particles, and its map over grasp.x × friction has the plan's particles green."""
    import yaml

    from bilba_dist.task.prismatic import peg_in_hole_task, regular_polygon

    path = tmp_path / "hexagon.yaml"
    data = peg_in_hole_task("hexagon", [regular_polygon(6, 0.055)], 0.002, 0.005)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    out = tmp_path / "plan.json"
    planned = run_cli("plan", str(path), "-u", "grasp.x=3mm friction=30%", "--workers", "0",
                      "--no-log", "--out", str(out))  # fmt: skip
    assert planned.exit_code == 0, planned.output
    assert "planning belief: 1.000 of 5" in run_cli("validate", str(out), "--workers", "0").output
    args = ["--map", "grasp.x=3mm", "--map", "friction=30%", "--points", "3"]
    mapped = run_cli(
        "validate", str(out), "--workers", "0", *args, "--map-out", str(tmp_path / "m")
    )
    rows = {(float(r["grasp.x"]), float(r["friction"])): int(r["success"])
            for r in csv.DictReader((tmp_path / "m.csv").open())}  # fmt: skip
    assert mapped.exit_code == 0 and len(rows) == 9
    for corner in [(0.0, 0.0), (0.003, 0.0), (-0.003, 0.0), (0.0, 0.3), (0.0, -0.3)]:
        assert rows[corner] == 1, corner  # the plan's own particles lie on the grid


@pytest.mark.slow
def test_a_plan_that_carries_the_planning_particles_past_a_contact_waits_for_its_checks(
    tmp_path,
):
    """An octagonal peg read from an STL file (2 mm clearance), grasp.x ±5 mm, seed 1: the
    motion to its last wall contact carries the three planning particles (at 1.5 μ) on to
    the floor but leaves four check particles at the wall; the plan must not end there, and
    replayed from the start it brings every check particle home too."""
    import trimesh
    import yaml

    from bilba_dist.task.prismatic import peg_in_hole_task, prism, regular_polygon

    octagon = regular_polygon(8, 0.05)
    data = peg_in_hole_task("octagon", [octagon], 0.002, 0.005)
    mm = np.array(prism(np.array(octagon) * 1000, -75.0, 75.0))
    trimesh.convex.convex_hull(mm).export(tmp_path / "peg.stl")
    mesh = {"file": "peg.stl", "scale": 0.001, "faces": {"bottom": [0, 0, -1]}}
    data["manipuland"]["pieces"] = [{"name": "peg", "mesh": mesh}]
    path = tmp_path / "octagon.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    task = load_task(str(path), ["grasp.x=5mm"])
    worker = RolloutWorker(task)
    result = plan(task, worker, "bilba-variable", seed=1, timeout_s=120)
    assert result.success, result.reason
    check = check_belief(task, initial_belief(task))
    assert check is not None
    final = replay(task, result.motions, check.particles, worker)
    worker.close()
    assert [task.goal in c for c in final.contacts] == [True] * len(check)


def test_a_plan_is_not_replayed_or_made_on_a_worker_of_another_friction(default_plan_file):
    """A world carries its task's friction (a particle only scales it): validating a plan
    at half the friction on a worker made for the task itself would run at the task's
    friction and report it as the other. Refused in one line; a worker of the scaled task
    replays it."""
    from bilba_dist.errors import BilbaError
    from bilba_dist.plans.replay import validate_plan

    plan_file = read_plan(default_plan_file)
    task = plan_file.task()
    half = with_friction(task, 0.5)
    worker = RolloutWorker(task)
    with pytest.raises(BilbaError, match="another task's world"):
        validate_plan(half, plan_file.motions, worker)
    with pytest.raises(BilbaError, match="another task's world"):
        plan(half, worker, "bilba-fixed", timeout_s=1)
    worker.close()
    scaled = RolloutWorker(half)
    assert validate_plan(half, plan_file.motions, scaled).planning == 1.0
    scaled.close()
