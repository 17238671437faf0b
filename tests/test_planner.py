"""The BILBA planner end to end (real PyBullet rollouts, in-process), plan files, replay."""

import json
from collections import Counter

import numpy as np
import pinocchio as pin
import pytest
from click.testing import CliRunner

from bilba_dist.belief.particles import initial_belief
from bilba_dist.belief.start import start_state
from bilba_dist.belief.state import LAMBDA, Belief, contact_iou, d_bel, d_bel_union
from bilba_dist.cli.main import cli, register
from bilba_dist.geometry.contact import FREE, ContactPair
from bilba_dist.modes.schedule import SliceCache
from bilba_dist.planning.bilba import furthest_common, plan
from bilba_dist.planning.recorder import NullRecorder
from bilba_dist.planning.result import PlannedMotion, PlanResult
from bilba_dist.planning.setpoints import SetpointParams, sample_setpoints
from bilba_dist.planning.stiffness import VERY_STIFF, variable_stiffness
from bilba_dist.plans.file import plan_document, read_plan, write_plan
from bilba_dist.plans.replay import replay
from bilba_dist.rollout import ParticleState
from bilba_dist.task.loader import load_task
from bilba_dist.workers.rollout_worker import RolloutWorker

A, B, C = (ContactPair(f"e/{k}", "m/-z") for k in "abc")
#: A MakeContact too cheap to reach any contact: one setpoint per particle, no GP, 10 ms
#: motions. Every edge it tries fails and is pruned.
CHEAP = {
    "setpoints_per_particle": 1,
    "noisy_setpoints": 0,
    "gp_rounds": 0,
    "motion_timeout_s": 0.01,
}


def belief_with(contacts):
    states = tuple(ParticleState(X_WM=pin.SE3.Identity()) for _ in contacts)
    return Belief((None,) * len(contacts), states, tuple(map(frozenset, contacts)))  # type: ignore[arg-type]


def test_score_counts_particles_and_adds_contact_iou():
    b = belief_with([{A, B}, {A}, {C}])
    assert d_bel(b.contacts) == frozenset() and d_bel_union(b.contacts) == {A, B, C}
    assert b.count(frozenset({A})) == 2
    assert b.score(frozenset({A})) == pytest.approx(2 + LAMBDA * 0.0)
    same = belief_with([{A, B}, {A, B}])
    assert contact_iou(same.contacts) == 1.0
    assert same.score(frozenset({B})) == pytest.approx(2 + LAMBDA)
    assert b.count(frozenset({B, C})) == 2  # a later schedule mode counts as reached


def test_furthest_common_mode_of_a_belief():
    schedule = [FREE, A, B, C]
    assert furthest_common(schedule, belief_with([{B}, {C}, {A, B}])) == B
    assert furthest_common(schedule, belief_with([{C}, {C}])) == C
    assert furthest_common(schedule, belief_with([{C}, set()])) == FREE


def test_furthest_common_mode_waits_for_the_check_particles():
    """Robust acceptance: planning particles carried on to the goal (C) while a check
    particle stays at the contact sought (B) have made B, not the goal."""
    schedule = [FREE, A, B, C]
    planned = belief_with([{B, C}, {C}])
    assert furthest_common(schedule, planned.with_check(belief_with([{C}, {B}]))) == B
    assert furthest_common(schedule, planned.with_check(belief_with([{C}, {B, C}]))) == C


def test_variable_stiffness_is_soft_along_the_contact_normal(peg):
    X_OM = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.16]))
    K = variable_stiffness(peg, ContactPair("wall_px/inner", "peg/+x"), X_OM)
    normal = np.array([-1.0, 0.0, 0.0])
    assert np.allclose(K[3:, 3:] @ normal, 400 * normal)
    assert np.allclose(K[3:, 3:] @ [0, 0, 1], [0, 0, 600])
    assert np.allclose(K, K.T) and np.allclose(K[:3, 3:], 0)
    assert np.linalg.eigvalsh(K[:3, :3]).min() == pytest.approx(
        60
    )  # soft about the rotation normal


@pytest.fixture(scope="module")
def pitch_plan():
    task = load_task("peg-in-hole", ["grasp.pitch=2deg"])
    worker = RolloutWorker(task, "panda")
    result = plan(task, worker, "bilba-variable", seed=3)
    yield task, worker, result
    worker.close()


def test_setpoints_fall_back_to_the_start_rotation_where_a_tilt_loses_the_mode():
    """Turned 0.02 rad about z, the puzzle part's lower block (50 × 30 mm) spans 50.6 mm in
    x, more than the 50.5 mm slot: at that rotation the slot-wall mode has no region, so the
    samples come from the start rotation, and the setpoints command it."""
    task = load_task("puzzle")
    particle, cache = initial_belief(task)[0], SliceCache(task)
    mode = ContactPair("bar_px/-x", "lower/+x")
    start = task.X_WG0 * particle.X_GM
    tilted = start * pin.SE3(pin.exp3(np.array([0.0, 0.0, 0.02])), np.zeros(3))
    R_tilted = (particle.X_WO.inverse() * tilted).rotation
    assert len(cache.get(R_tilted).sample_mode(mode, 16, np.random.default_rng(0))) == 0
    params = SetpointParams(press_m=0.0)  # surface samples exactly on the mode's region
    setpoints = sample_setpoints(particle, tilted, mode, cache, params, np.random.default_rng(0))
    assert len(setpoints) == params.on_surface + params.noisy
    X_OMs = [particle.X_WO.inverse() * G_d * particle.X_GM for G_d in setpoints]
    R_start = (particle.X_WO.inverse() * start).rotation
    assert all(np.allclose(X_OM.rotation, R_start) for X_OM in X_OMs)
    surface = np.array([X_OM.translation for X_OM in X_OMs[: params.on_surface]])
    assert all(mode in c for c in cache.get(R_start).contacts(surface))


def test_setpoints_fall_back_to_the_nominal_rotation_where_the_grasp_tilt_loses_the_mode():
    """Held 2° pitched in the gripper, the puzzle part's neck fits the goal slot neither at
    its current nor at its start rotation (both tilted): the samples come from the part's
    nominal rotation, and each setpoint turns the gripper so that this particle's part is
    level (before, such a particle had no setpoints: puzzle grasp.pitch ±2°, 4 of 7)."""
    from bilba_dist.belief.particles import make_particle

    task = load_task("puzzle", ["grasp.pitch=2deg"])
    particle, cache = make_particle(task, {"grasp.pitch": np.deg2rad(2.0)}), SliceCache(task)
    start = task.X_WG0 * particle.X_GM
    R_start = (particle.X_WO.inverse() * start).rotation
    assert len(cache.get(R_start).sample_mode(task.goal, 16, np.random.default_rng(0))) == 0
    params, rng = SetpointParams(press_m=0.0), np.random.default_rng(0)
    setpoints = sample_setpoints(particle, start, task.goal, cache, params, rng)
    assert len(setpoints) == params.on_surface + params.noisy
    nominal = make_particle(task, {})
    R_level = (nominal.X_WO.inverse() * task.X_WG0 * nominal.X_GM).rotation
    X_OMs = [particle.X_WO.inverse() * G_d * particle.X_GM for G_d in setpoints]
    assert all(np.allclose(X_OM.rotation, R_level) for X_OM in X_OMs)
    surface = np.array([X_OM.translation for X_OM in X_OMs[: params.on_surface]])
    assert all(task.goal in c for c in cache.get(R_level).contacts(surface))


def test_seeded_plan_brings_every_particle_to_the_hole_bottom(pitch_plan):
    task, _, result = pitch_plan
    assert result.success, result.reason
    assert result.final_belief is not None
    assert all(task.goal in c for c in result.final_belief.contacts)
    assert result.motions[-1].contact == task.goal
    assert result.rollouts > 0


def test_plan_file_replays_to_the_same_contacts(pitch_plan, tmp_path):
    task, worker, result = pitch_plan
    path = tmp_path / "plan.json"
    write_plan(plan_document(result, task), path)
    loaded = read_plan(path)
    document = json.loads(path.read_text())
    assert document["task"]["hash"] == task.hash and document["success"] is True
    for written, read in zip(result.motions, loaded.motions, strict=True):
        assert np.array_equal(written.K, read.K)
        assert np.array_equal(written.G_d.homogeneous, read.G_d.homogeneous)
        assert read.contact == written.contact
    final = replay(task, loaded.motions, initial_belief(task), worker)
    assert final.contacts == result.final_belief.contacts


def _one_motion_plan(tmp_path, R: np.ndarray):
    """A plan file of one motion whose setpoint has rotation ``R``."""
    motion = PlannedMotion(
        VERY_STIFF, pin.SE3(R, np.array([0.5, 0.0, 0.3])), np.zeros(7), 5.0, FREE, 0.0
    )
    task = load_task("peg-in-hole")
    result = PlanResult(True, "", [motion], "bilba-fixed", 0)
    path = tmp_path / "plan.json"
    write_plan(plan_document(result, task), path)
    return path


def test_plan_file_keeps_the_simulated_rotation_exactly(tmp_path):
    """A setpoint rotation a little off orthonormal (as composed poses are) reads back bit
    for bit; through the quaternion alone it would not."""
    R = pin.rpy.rpyToMatrix(np.pi, 0.1, 0.2) + 3e-12 * np.eye(3)
    path = _one_motion_plan(tmp_path, R)
    (read,) = read_plan(path).motions
    assert np.array_equal(read.G_d.rotation, R)
    document = json.loads(path.read_text())
    del document["motions"][0]["G_d"]["rotation"]  # a plan file written before the matrix
    path.write_text(json.dumps(document))
    (old,) = read_plan(path).motions
    assert np.allclose(old.G_d.rotation, R, atol=1e-9) and not np.array_equal(old.G_d.rotation, R)


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        (
            "rotation",
            [[1, 0, 0], [0, 1, 0]],
            "at motions/0/G_d/rotation: [[1, 0, 0], [0, 1, 0]] is too short",
        ),
        ("rotation", [[2, 0, 0], [0, 1, 0], [0, 0, 1]], "must be a 3x3 rotation matrix"),
        # 1e308 overflowed R.T @ R and printed numpy's warning above the error line
        ("rotation", [[1e308, 0, 0], [0, 1, 0], [0, 0, 1]], "must be a 3x3 rotation matrix"),
        ("rotation", [[1, 0, 0], [0, -1, 0], [0, 0, -1]], "rotation and quat_xyzw disagree"),
        ("quat_xyzw", [1e308, 1e308, 0, 0], "quat_xyzw must be a unit quaternion"),
    ],
)
@pytest.mark.filterwarnings("error::RuntimeWarning")  # a numpy warning is a second line
def test_validate_rejects_a_bad_setpoint_rotation(key, value, message, tmp_path):
    register()
    path = _one_motion_plan(tmp_path, np.eye(3))
    document = json.loads(path.read_text())
    document["motions"][0]["G_d"][key] = value
    path.write_text(json.dumps(document))
    result = CliRunner().invoke(cli, ["validate", str(path), "--workers", "0"])
    assert result.exit_code == 2
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_plan_motion_setpoints_are_reachable_joint_targets(pitch_plan):
    from bilba_dist.robot.panda import PandaModel

    _, _, result = pitch_plan
    model = PandaModel()
    for motion in result.motions:
        assert model.fk(motion.q_d).isApprox(motion.G_d, 1e-4)


def test_failed_search_says_why(peg):
    worker = RolloutWorker(peg, "panda")
    timeout = plan(peg, worker, "bilba-fixed", seed=0, timeout_s=0.0)
    assert not timeout.success and timeout.timed_out and timeout.reason.startswith("timeout")
    assert timeout.motions == []
    spec = peg.spec.model_copy(
        update={"goal": peg.spec.goal.model_copy(update={"env": "floor/-z"})}
    )
    from bilba_dist.task.loader import build_task

    impossible = plan(build_task(spec, "x"), worker, "bilba-fixed", seed=0)
    assert not impossible.success and "no contact schedule" in impossible.reason
    worker.close()


def test_running_out_of_attempts_says_so():
    """One candidate per particle, no GP, and motions of 10 ms, too short to reach any
    contact: MakeContact fails, its edge is pruned, and after n_attempts the reason names
    the attempts (not an empty graph), with the last failure."""
    from bilba_dist.task.loader import build_task

    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    cheap = {**CHEAP, "n_attempts": 2}
    spec = task.spec.model_copy(update={"planner": task.spec.planner.model_copy(update=cheap)})
    worker = RolloutWorker(spec, "panda")
    result = plan(build_task(spec, "x"), worker, "bilba-fixed", seed=0)
    worker.close()
    assert not result.success
    assert result.attempts == 2 and len(result.pruned) == 2
    assert result.reason.startswith("all 2 attempts failed (2 edges pruned); last: no motion")


def test_pruning_rounds_put_pruned_edges_back():
    """Free joined to one mode only, and MakeContact too cheap to go anywhere (10 ms
    motions): pruning empties the graph. A second round puts the pruned edges back and
    prunes again from there."""
    from bilba_dist.task.loader import build_task

    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    results = []
    for rounds in (1, 2):
        cheap = {**CHEAP, "n_free": 1, "prune_rounds": rounds}
        planner = task.spec.planner.model_copy(update=cheap)
        spec = task.spec.model_copy(update={"planner": planner})
        worker = RolloutWorker(spec, "panda")
        results.append(plan(build_task(spec, "x"), worker, "bilba-fixed", seed=0))
        worker.close()
    one, two = results
    assert not one.success and not two.success
    assert (one.rounds, two.rounds) == (1, 2)
    n = len(one.pruned)
    assert two.pruned[:n] == one.pruned and len(two.pruned) > n
    assert set(two.pruned[n:]) & set(one.pruned)  # an edge pruned, put back, pruned again
    assert one.reason.startswith(f"edges pruned until no schedule was left ({n} pruned); ")
    assert f"({len(two.pruned)} pruned in 2 rounds); last: no motion" in two.reason


def test_start_state_puts_the_gripper_at_the_start_pose(peg):
    from bilba_dist.robot.panda import PandaModel

    particle = initial_belief(peg)[1]
    state = start_state(peg, particle)
    assert PandaModel().fk(state.q).isApprox(peg.X_WG0, 1e-4)
    assert state.X_WM.isApprox(peg.X_WG0 * particle.X_GM, 1e-12)


def test_plan_command_without_a_plan_exits_1_and_keeps_the_result(tmp_path):
    register()
    out = tmp_path / "p.json"
    result = CliRunner().invoke(
        cli,
        ["plan", "peg-in-hole", "--workers", "0", "--timeout", "0", "--no-log", "--out", str(out)],
    )
    assert result.exit_code == 1, result.output
    assert "NO PLAN: timeout" in result.output
    assert json.loads(out.read_text())["success"] is False


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "cannot read plan file"),
        ("{not json", "invalid JSON at line 1"),
        ('{"format": "other"}', "not a plan file"),
        ('{"format": "bilba-plan", "version": 1, "task": {"name": "x"}}', "malformed plan file"),
    ],
)
def test_validate_rejects_bad_plan_files(content, message, tmp_path):
    register()
    path = tmp_path / "plan.json"
    if content is not None:
        path.write_text(content)
    result = CliRunner().invoke(cli, ["validate", str(path), "--workers", "0"])
    assert result.exit_code == 2
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_fixed_variant_uses_very_stiff_gains(pitch_plan):
    task, worker, _ = pitch_plan
    result = plan(task, worker, "bilba-fixed", seed=1, timeout_s=120)
    assert result.success, result.reason
    assert all(np.array_equal(m.K, VERY_STIFF) for m in result.motions)


def test_floating_model_plan_is_validated_on_the_panda(pitch_plan):
    task, panda, _ = pitch_plan
    floating = RolloutWorker(task, "floating")
    result = plan(task, floating, seed=0, validate_on=panda)
    floating.close()
    assert result.success, result.reason
    final = replay(task, result.motions, initial_belief(task), panda)
    assert result.final_belief is not None
    assert final.contacts == result.final_belief.contacts  # the belief returned is the Panda's
    assert all(task.goal in c for c in final.contacts)


def test_a_plan_that_fails_on_the_panda_is_not_returned(pitch_plan):
    task, panda, _ = pitch_plan
    floating = RolloutWorker(task, "floating")
    good = plan(task, floating, seed=0)
    floating.close()
    from bilba_dist.belief.start import start_belief
    from bilba_dist.planning.bilba import _validate

    broken = PlanResult(True, "", good.motions[:1], good.planner, good.seed)  # first motion only
    _validate(task, broken, start_belief(task, initial_belief(task)), panda)
    assert not broken.success
    assert "failed validation on the Panda model" in broken.reason


def test_sample_patience_stops_scoring_when_nothing_improves(peg):
    """Setpoints in free space above the start never reach the goal: with patience 16 the
    evaluator gives up after two chunks of 8 (screening rollouts only), without it screens
    all 40."""
    from bilba_dist.belief.start import start_belief
    from bilba_dist.planning.evaluate import Candidate, Evaluator
    from bilba_dist.rollout import Motion

    belief = start_belief(peg, initial_belief(peg))
    lifts = [peg.X_WG0 * pin.SE3(np.eye(3), np.array([0, 0, -0.002 * k])) for k in range(40)]
    candidates = [Candidate(Motion(VERY_STIFF, G_d, 1.0), k % 3) for k, G_d in enumerate(lifts)]
    worker = RolloutWorker(peg, "floating")
    for patience, rollouts in ((16, 16), (0, 40)):
        evaluator = Evaluator(worker)
        scored, winner = evaluator.score(
            belief, candidates, frozenset({peg.goal}), patience=patience
        )
        assert winner is None and all(s.count == 0 for s in scored)
        assert evaluator.rollouts == rollouts
    worker.close()


def _first_contact(task, worker, rng_seed, race_contacts):
    """The first step from free of ``task``'s belief, with or without a race."""
    from bilba_dist.belief.start import start_belief
    from bilba_dist.modes.schedule import belief_graph
    from bilba_dist.planning.bilba import contact_search
    from bilba_dist.planning.evaluate import Evaluator
    from bilba_dist.planning.make_contact import make_contact, race
    from bilba_dist.task.loader import with_planner

    task = with_planner(task, race_contacts=race_contacts)
    search = contact_search(task, Evaluator(worker), "bilba-fixed", deadline=float("inf"))
    b0 = start_belief(task, initial_belief(task))
    graph, _ = belief_graph(task, initial_belief(task), task.X_WG0, search.cache)
    rng = np.random.default_rng(rng_seed)
    schedules = graph.alternatives(FREE, race_contacts)
    if race_contacts > 1:
        return schedules, race(search, b0, schedules, rng), search.evaluator.rollouts
    (schedule,) = schedules
    outcome = make_contact(search, b0, schedule[1], frozenset(schedule[1:]), rng)
    return schedules, (0, outcome), search.evaluator.rollouts


def test_race_finds_a_first_contact_that_holds_a_spread_belief():
    """Under grasp.x ±1 cm, Dijkstra's tie-break picks the chamfer facing the spread, which
    no motion makes for all three particles at once; the race follows a chamfer along it."""
    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    worker = RolloutWorker(task, "panda")
    schedules, (j, outcome), rollouts = _first_contact(task, worker, 0, 3)
    worker.close()
    assert schedules[0][1].env in ("wall_mx/chamfer", "wall_px/chamfer")  # along x
    assert outcome is not None
    assert j > 0 and outcome.success and len(outcome.steps) == 1
    accept = frozenset(schedules[j][1:])
    assert all(contacts & accept for contacts in outcome.belief.contacts)
    assert rollouts <= 2 * 3 * 3 * 8  # race_chunks rounds x 3 contacts x 3 particles x chunk


def test_race_won_by_dijkstras_contact_in_its_first_chunk_changes_nothing(peg):
    """Pitch ±2°: Dijkstra's first contact is made by the first chunk, so the race returns
    the motion MakeContact finds from the same random state."""
    worker = RolloutWorker(peg, "panda")
    _, (_, plain), plain_rollouts = _first_contact(peg, worker, 3, 0)
    _, (j, won), race_rollouts = _first_contact(peg, worker, 3, 3)
    worker.close()
    assert won is not None and j == 0 and plain.success
    assert race_rollouts == plain_rollouts <= 3 * 8  # one chunk, nothing else simulated
    (a,), (b,) = plain.steps, won.steps
    assert a.contact == b.contact and a.score == b.score
    assert np.array_equal(a.motion.G_d.homogeneous, b.motion.G_d.homogeneous)
    assert np.array_equal(a.motion.K, b.motion.K)


class _BestCounts(NullRecorder):
    """The most particles any simulated motion brought into each contact."""

    def __init__(self) -> None:
        self.best: dict = {}

    def transition(self, mode, motion, before, after, score, count, accepted) -> None:
        self.best[mode] = max(self.best.get(mode, 0), count)


def test_a_race_nobody_wins_hands_the_full_search_the_contact_it_got_furthest_with():
    """grasp.x ±2 cm, two setpoints per particle, one chunk: no chamfer takes all three pegs
    at once; the full search then goes to the contact whose best motion brought most
    particles in (ties: the earlier schedule), not to Dijkstra's first."""
    from bilba_dist.belief.start import start_belief
    from bilba_dist.modes.schedule import belief_graph
    from bilba_dist.planning.bilba import contact_search
    from bilba_dist.planning.evaluate import Evaluator
    from bilba_dist.planning.make_contact import race
    from bilba_dist.task.loader import with_planner

    task = with_planner(
        load_task("peg-in-hole", ["grasp.x=2cm"]),
        setpoints_per_particle=2,
        noisy_setpoints=0,
        race_chunks=1,
    )
    worker = RolloutWorker(task, "panda")
    counts = _BestCounts()
    search = contact_search(task, Evaluator(worker), "bilba-fixed", float("inf"), recorder=counts)
    graph, _ = belief_graph(task, initial_belief(task), task.X_WG0, search.cache)
    schedules = graph.alternatives(FREE, 3)
    b0 = start_belief(task, initial_belief(task))
    j, outcome = race(search, b0, schedules, np.random.default_rng(0))
    worker.close()
    best = [counts.best.get(s[1], 0) for s in schedules]
    assert outcome is None and max(best) < 3
    assert j == best.index(max(best)) and j > 0  # Dijkstra's first got fewer in


def test_a_search_out_of_schedules_goes_on_until_its_timeout():
    """With the defaults (no limit on pruning rounds or attempts), a search that prunes every
    edge out of free puts them back and tries again until the timeout, where the paper's
    settings stop at once."""
    from bilba_dist.task.loader import build_task, with_preset

    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    cheap = {**CHEAP, "n_free": 1, "race_contacts": 0}
    results = {}
    for preset in ("default", "paper"):
        preset_task = with_preset(task, preset)
        planner = preset_task.spec.planner.model_copy(update=cheap)
        spec = preset_task.spec.model_copy(update={"planner": planner})
        worker = RolloutWorker(spec, "panda")
        results[preset] = plan(build_task(spec, "x"), worker, "bilba-fixed", seed=0, timeout_s=4)
        worker.close()
    ours, paper = results["default"], results["paper"]
    assert paper.rounds == 1 and paper.reason.startswith("edges pruned until no schedule")
    assert paper.planning_time_s < 4
    assert ours.reason.startswith("timeout after") and ours.rounds > 2
    assert len(ours.pruned) > len(paper.pruned)


def test_no_plan_names_the_contact_that_blocked_it_and_why():
    """One setpoint per particle and no GP cannot bring the peg's three grasp.x particles onto
    one chamfer, starting over after each pruned edge: the reason names that chamfer and how
    far the best motion got. (With two setpoints, or going on from the contact reached, the
    planner now finds a plan.)"""
    from bilba_dist.task.loader import with_planner

    task = with_planner(
        load_task("peg-in-hole", ["grasp.x=1cm"]),
        n_attempts=3,
        setpoints_per_particle=1,
        noisy_setpoints=0,
        gp_rounds=0,
        race_contacts=0,
        keep_reached=False,
    )
    worker = RolloutWorker(task)
    result = plan(task, worker, "bilba-fixed", seed=0, timeout_s=120)
    worker.close()
    assert not result.success and len(result.blocked) == 3
    first = result.blocked[0]
    assert first.n == 3 and first.reached < 3 and first.no_region == 0
    assert first.spread_m == pytest.approx(0.02, abs=1e-3)  # ±1 cm of grasp x
    assert first.n_check == 6 and 0 <= first.checked <= 6  # robust acceptance's twins
    counts = Counter(b.contact for b in result.blocked)
    top = max(counts.values())
    worst = next(b.contact for b in reversed(result.blocked) if counts[b.contact] == top)
    assert f"blocked by {worst} (" in result.reason
    assert "particles into it" in result.reason


def _moved_hole(hand_yaw: str) -> dict:
    """The peg's hole as a user's fixture: 8 cm nearer the robot, 18 cm to its left, 5 cm
    up and turned 30° about z; the robot starts 31 cm above it, the hand turned ``hand_yaw``."""
    import yaml

    from bilba_dist.task.loader import builtin_tasks

    data = yaml.safe_load(builtin_tasks()["peg-in-hole"].read_text())
    data["environment_pose"] = {"xyz": [0.42, 0.18, 0.05], "rpy": [0, 0, "30deg"]}
    data["robot_start"] = {"gripper": {"xyz": [0.42, 0.18, 0.41], "rpy": ["180deg", 0, hand_yaw]}}
    return data


def test_a_hole_moved_and_turned_on_the_table_plans_with_the_defaults():
    """Plans are made in the environment's frame and run in the world's: the hole moved and
    turned 30° (the hand with it) plans under env.y ±1 cm (along world y, across the turned
    hole) and its plan holds on fresh particles."""
    task = load_task(_moved_hole("30deg"), ["env.y=1cm"])
    worker = RolloutWorker(task, "panda")
    result = plan(task, worker, "bilba-variable", seed=0, timeout_s=120)
    assert result.success, result.reason
    assert result.verification is not None and result.verification.passed
    _holds_clear_of_joint_stops(task, result, worker)
    assert all(task.goal in contacts for contacts in result.final_belief.contacts)


def _holds_clear_of_joint_stops(task, result, worker) -> None:
    """The wrist works near joint 5's limit: no particle of the plan, at any friction
    checked, leans on a joint's stop (where a Franka would halt with a reflex), and every
    one ends in the goal."""
    from bilba_dist.plans.loads import friction_twins
    from bilba_dist.plans.replay import transitions

    twins = friction_twins(task, initial_belief(task))
    beliefs = [b for b, _ in transitions(task, result.motions, twins, worker)]
    worker.close()
    assert len(twins) == 9 and all(b.stopped() == [] for b in beliefs)
    assert sum(task.goal in c for c in beliefs[-1].contacts) == 9


def test_a_part_held_turned_against_its_hole_says_how_it_is_turned(tmp_path):
    """The hole turned 30° and the hand not: the square peg fits at no rotation it is held
    at; the line says the goal is missing and how the part is turned in the hole's frame."""
    import yaml

    (path := tmp_path / "turned.yaml").write_text(yaml.safe_dump(_moved_hole("0deg")))
    register()
    result = CliRunner().invoke(cli, ["graph", str(path)])
    assert result.exit_code == 2, result.output
    (line,) = result.stderr.splitlines()
    assert "the goal contact (floor/+z, peg/-z) does not occur on the C-obs slice" in line
    assert line.endswith(
        "the first particle's part is turned rpy [0.0, 0.0, -30.0] deg in the environment's "
        "frame (robot_start and grasp against environment_pose)"
    )


def _sideways(hand_xyz: list[float]) -> dict:
    """The peg's hole in an upright panel facing the robot (its opening 85 cm out, 45 cm
    up), the peg held pointing forward: a horizontal insertion, gravity across it."""
    import yaml

    from bilba_dist.task.loader import builtin_tasks

    data = yaml.safe_load(builtin_tasks()["peg-in-hole"].read_text())
    data["environment_pose"] = {"xyz": [0.91, 0, 0.45], "rpy": [0, "-90deg", 0]}
    data["robot_start"] = {"gripper": {"xyz": hand_xyz, "rpy": [0, "90deg", 0]}}
    return data


def test_a_sideways_insertion_plans_from_a_start_the_centre_posture_cannot_reach():
    """The hand pointing forward with its wrist near a joint limit: IK from the centre
    posture stalls there, so the start is found from seeded postures (start_joints), and
    the peg goes into the upright panel with the defaults."""
    from bilba_dist.belief.start import start_joints
    from bilba_dist.errors import UnreachableError
    from bilba_dist.robot.panda import Q_CENTRE, PandaModel

    task = load_task(_sideways([0.55, 0, 0.45]), ["grasp.x=1cm"])  # 22 of its 490 rollouts
    model = PandaModel()  # stop a particle at joint 5's limit (2026-12-06)
    with pytest.raises(UnreachableError):
        model.ik(task.X_WG0, Q_CENTRE)
    q = start_joints(task)
    assert np.allclose(model.fk(q).homogeneous, task.X_WG0.homogeneous, atol=1e-4)
    worker = RolloutWorker(task, "panda")
    result = plan(task, worker, "bilba-variable", seed=0, timeout_s=120)
    assert result.success, result.reason
    assert result.verification is not None and result.verification.passed
    _holds_clear_of_joint_stops(task, result, worker)


def test_a_start_out_of_reach_is_one_line_naming_robot_start(tmp_path):
    import yaml

    (path := tmp_path / "near.yaml").write_text(yaml.safe_dump(_sideways([0.39, 0, 0.35])))
    register()
    result = CliRunner().invoke(cli, ["plan", str(path), "--workers", "0", "--no-log"])
    assert result.exit_code == 2, result.output
    (line,) = result.stderr.splitlines()
    assert (
        f"{path}: robot_start: no IK solution within the Panda's joint limits puts the hand "
        in line
    )
    assert "at [0.39, 0, 0.35] m turned as given" in line
    assert "from 17 starting postures" in line and "give robot_start.joints near it" in line
    graph = CliRunner().invoke(cli, ["graph", str(path)])  # the geometry, and a warning
    assert graph.exit_code == 0 and "schedule: free -> " in graph.stdout, graph.output
    assert graph.stderr.startswith(f"bilba: warning: {path}: robot_start: no IK solution")
