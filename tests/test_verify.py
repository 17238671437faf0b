"""Verification (planning/verify.py): a plan is replayed on particles it was not planned on
before it is returned, and one that loses some is not returned while time is left."""

import json

import numpy as np
import pytest

from bilba_dist import load_task, plan
from bilba_dist.belief.particles import initial_belief, make_particle
from bilba_dist.belief.start import start_belief
from bilba_dist.geometry.contact import FREE
from bilba_dist.planning import bilba, verify
from bilba_dist.planning.evaluate import Evaluator
from bilba_dist.planning.make_contact import Step
from bilba_dist.planning.result import Verification
from bilba_dist.planning.verify import VERIFY_SEED, verify_particles, within_budget
from bilba_dist.plans.file import read_plan
from bilba_dist.plans.replay import run_motions
from bilba_dist.record.reader import read_log
from bilba_dist.rollout import Motion
from bilba_dist.task.loader import with_planner, with_points, with_preset
from bilba_dist.workers.rollout_worker import RolloutWorker
from tests.conftest import prism_file, prism_task, write_task
from tests.test_task_files import run_cli


def test_verification_particles_are_a_fixed_draw_inside_the_bounds_at_three_frictions():
    task = load_task("puzzle", ["grasp.x=1cm"])
    assert task.spec.planner.verify_particles == 14  # the default
    particles = verify_particles(task, 0.5)
    assert len(particles) == 14 * 3
    assert [p.friction_scale for p in particles[:6]] == [0.5, 1.0, 1.5] * 2
    xs = np.array([p.offsets["grasp.x"] for p in particles])
    assert np.all(np.abs(xs) <= 0.01) and len(set(xs.round(9))) == 14
    assert verify_particles(task, 0.5) == particles  # seed VERIFY_SEED, not the planning seed
    assert VERIFY_SEED not in (0, 1)  # `bilba validate`'s usual held-out draws
    without_margin = verify_particles(task, 0.0)
    assert [p.friction_scale for p in without_margin] == [1.0] * 14
    assert verify_particles(with_preset(task, "paper"), 0.0) == ()  # the authors: none


@pytest.mark.parametrize(
    ("budget", "offsets"), [(0, 1), (29, 1), (30, 2), (10_000, 14)]
)  # 3 particles an offset, 5 motions: 15 rollouts an offset
def test_verification_spends_at_most_its_share_of_the_search(budget, offsets):
    particles = verify_particles(load_task("puzzle", ["grasp.x=1cm"]), 0.5)
    assert within_budget(particles, 3, 5, budget) == particles[: 3 * offsets]


def test_a_verified_plan_says_so_in_its_file_and_log(tmp_path):
    out, log = tmp_path / "p.json", tmp_path / "l.mcap"
    result = run_cli("plan", "peg-in-hole", "--workers", "0", "--out", str(out), "--log", str(log))
    assert result.exit_code == 0, result.output
    assert "verified   passed on" in result.output
    document = json.loads(out.read_text())
    check = document["verification"]
    assert check["passed"] and check["plan"] == 1 and check["particles"] % 3 == 0
    assert check["held"] == {"0.5": 1.0, "1": 1.0, "1.5": 1.0}
    (logged,) = read_log(log).json("/verify")
    assert logged == check
    (outcome,) = read_log(log).json("/outcome")
    assert outcome["verified"] is True
    # its replay is counted: more rollouts than the same search without it
    task = with_planner(load_task("peg-in-hole"), verify_particles=0)
    plain = plan(task, RolloutWorker(task), "bilba-variable", seed=0)
    motions = len(document["motions"])
    assert document["rollouts"] == plain.rollouts + check["particles"] * motions


def test_a_plan_that_fails_verification_is_not_returned_while_time_is_left(monkeypatch):
    """A verification particle the first plan does not bring home (the hole 3 cm away) fails
    it: that particle becomes a check particle and the search starts over; with no
    plan that passes within 3x the first one's time, the one that held best comes back,
    marked failed."""
    task = with_planner(load_task("peg-in-hole"), verify_effort=3.0)
    worker = RolloutWorker(task)
    first = plan(task, worker, "bilba-fixed", seed=0)  # verified: the nominal particles pass
    assert first.verification is not None and first.verification.passed
    lost = make_particle(task, {"env.y": 0.03})
    home = make_particle(task, {})
    monkeypatch.setattr(bilba, "verify_particles", lambda task, f: (home, lost))
    added = []
    more_checks = verify.with_more_checks

    def spy(task, b0, extra):
        added.extend(extra)
        return more_checks(task, b0, extra)

    monkeypatch.setattr(bilba, "with_more_checks", spy)
    result = plan(task, worker, "bilba-fixed", seed=0, timeout_s=12)
    assert added[:1] == [lost]
    assert result.success and result.verification is not None
    assert not result.verification.passed and result.verification.held == {"1": 0.5}
    assert result.reason.startswith("no plan passed verification within 3x the time of the first")
    assert [m.G_d for m in result.motions] == [m.G_d for m in first.motions]


def test_of_plans_that_fail_verification_the_one_kept_lost_least():
    """The worst fraction first, then the mean: a later plan that loses an offset only at
    0.5 μ replaces one that lost it at 0.5 and 1 μ (puzzle grasp.x ±1 cm, seed 0: its
    third plan), so the hint names what the kept plan lost."""
    twice = Verification(42, {"0.5": 13 / 14, "1": 13 / 14, "1.5": 1.0}, passed=False)
    once = Verification(42, {"0.5": 13 / 14, "1": 1.0, "1.5": 1.0}, passed=False)
    worse = Verification(42, {"0.5": 12 / 14, "1": 1.0, "1.5": 1.0}, passed=False)
    assert once.holds_better_than(twice) and not twice.holds_better_than(once)
    assert not once.holds_better_than(once)  # a tie keeps the earlier plan
    assert twice.holds_better_than(worse) and not worse.holds_better_than(twice)


@pytest.mark.parametrize(
    ("planner", "words"),
    [
        ({"verify_min": 2}, "verify_min"),
        ({"verify_particles": -1}, "verify_particles"),
        ({"verify_share": 0}, "verify_share"),
        ({"verify_effort": 0.5}, "verify_effort"),
    ],
)
def test_a_verification_setting_out_of_range_is_one_line(tmp_path, peg_yaml, planner, words):
    path = write_task(tmp_path, {**peg_yaml, "planner": planner})
    result = run_cli("plan", str(path), "--workers", "0", "--no-log")
    assert result.exit_code == 2 and words in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_with_a_friction_axis_the_verification_particles_draw_their_own_friction():
    """Robust acceptance is off then (the particles span the friction the user gave), and the
    verification particles are drawn on every axis, friction included: one fraction."""
    task = load_task("peg-in-hole", ["grasp.pitch=2deg", "friction=30%"])
    particles = verify_particles(task, 0.0)
    frictions = [p.friction_scale for p in particles]
    assert len(particles) == 14 and len(set(frictions)) == 14
    assert all(0.7 <= f <= 1.3 for f in frictions)
    result = plan(task, RolloutWorker(task), "bilba-fixed", seed=0)
    assert result.success and result.verification is not None
    assert list(result.verification.held) == ["all"]


def test_a_search_whose_plans_keep_failing_stops_at_its_effort_limit(monkeypatch):
    """With a verification particle no plan can bring home (its hole half a metre away), the
    search gives up at verify_effort times its first plan's time, long before the timeout,
    and returns that plan, marked failed."""
    task = with_planner(load_task("peg-in-hole"), verify_effort=2.0)
    monkeypatch.setattr(
        bilba, "verify_particles", lambda task, f: (make_particle(task, {"env.y": 0.5}),)
    )
    result = plan(task, RolloutWorker(task), "bilba-fixed", seed=0, timeout_s=600)
    assert result.success and result.verification is not None
    assert not result.verification.passed and result.verification.held == {"1": 0.0}
    assert "within 2x the time of the first" in result.reason
    assert result.first_plan_s > 0 and result.planning_time_s < 2 * result.first_plan_s + 30
    assert result.verification.lost == [{"grasp.pitch": 0.0, "env.y": 0.5}]
    assert "; it lost offsets it was not planned on ((grasp.pitch +0.00 deg, env.y +500.0 mm))" in (
        result.reason
    )


@pytest.mark.parametrize(
    ("uncertainty", "belief", "lost", "says"),
    [
        (  # one axis: its values, sorted, in the file's units; the axis generator's knob
            {"grasp.pitch": "2deg"},
            {"generator": "axis", "points": 5},
            [{"grasp.pitch": 0.02}, {"grasp.pitch": -0.0105}],
            "(grasp.pitch -0.60, +1.15 deg): try planning on more particles (belief: {points: 7} "
            "puts particles between them); `bilba validate PLAN --map grasp.pitch=2.00deg` shows",
        ),
        (  # two axes: each offset whole; extremal+random's knob; both axes mapped
            {"grasp.x": "1cm", "friction": "50%"},
            {"generator": "extremal+random", "random": 2},
            [{"grasp.x": 0.0031, "friction": -0.25}],
            "((grasp.x +3.1 mm, friction -25 %)): try planning on more particles (belief: "
            "{random: 6} draws more of them); `bilba validate PLAN --map grasp.x=10.0mm --map "
            "friction=50%`",
        ),
        (
            {"env.y": "1cm"},
            {"generator": "explicit", "particles": [{}, {"env": {"y": "1cm"}}]},
            [{"env.y": 0.004}],
            "(env.y +4.0 mm): try planning on more particles (add offsets like these to "
            "belief.particles)",
        ),
    ],
)
def test_a_plan_that_failed_verification_says_what_it_lost_and_how_to_plan_on_it(
    uncertainty, belief, lost, says
):
    import yaml

    from bilba_dist.planning.verify import more_particles_hint
    from bilba_dist.task.loader import builtin_tasks

    data = yaml.safe_load(builtin_tasks()["peg-in-hole"].read_text())
    task = load_task({**data, "uncertainty": uncertainty, "belief": belief})
    failed = Verification(42, {"1": 0.9}, passed=False, lost=lost)
    assert says in more_particles_hint(task, failed)
    assert more_particles_hint(task, Verification(42, {"1": 1.0})) == ""


@pytest.mark.parametrize(
    ("particles", "held", "says"),
    [
        (3, {"0.5": 1.0, "1": 1.0, "1.5": 1.0}, "1 offset × 3 frictions (3 particles), in"),
        (42, {"0.5": 1.0, "1": 0.93, "1.5": 1.0}, "14 offsets × 3 frictions (42 particles), in"),
        (14, {"1": 1.0}, "14 offsets, in the goal 1.00 at 1 μ"),
        (14, {"all": 0.5}, "14 particles, in the goal 0.50"),
    ],
)
def test_verification_says_how_many_offsets_at_how_many_frictions(particles, held, says):
    assert Verification(particles, held).text().startswith(says)


def test_a_search_out_of_time_before_its_effort_limit_says_the_timeout_ended_it(monkeypatch):
    """The same search with an effort limit it cannot reach: the timeout ends it, and the
    reason says so (not the effort limit)."""
    task = with_planner(load_task("peg-in-hole"), verify_effort=1000.0)
    monkeypatch.setattr(
        bilba, "verify_particles", lambda task, f: (make_particle(task, {"env.y": 0.5}),)
    )
    result = plan(task, RolloutWorker(task), "bilba-fixed", seed=0, timeout_s=8)
    assert result.success and result.verification is not None
    assert not result.verification.passed
    assert result.reason.startswith("no plan passed verification before the timeout after")


def _made(task, motions, worker):
    """A plan's steps and the contacts it made on the planning particles, as the search
    keeps them (bilba.Reached): the start, then the belief after each motion."""
    particles = bilba.planning_particles(task, initial_belief(task))
    beliefs = [start_belief(task, particles), *run_motions(task, motions, particles, worker)]
    steps = [Step(Motion(m.K, m.G_d, m.timeout_s), m.contact, m.score) for m in motions]
    modes = [FREE, *(m.contact for m in motions)]
    return steps, [
        bilba.Reached(b, mode, j) for j, (b, mode) in enumerate(zip(beliefs, modes, strict=True))
    ]


@pytest.fixture(scope="module")
def fixed_peg_plan():
    task = load_task("peg-in-hole")
    worker = RolloutWorker(task)
    result = plan(task, worker, "bilba-fixed", seed=0)
    assert result.success and result.verification is not None and result.verification.passed
    return task, worker, result


@pytest.mark.parametrize(
    ("offsets", "resumed_at"),
    [
        ({}, 2),  # the nominal part: in every contact but the goal's, the last one
        ({"friction": 2.0}, 1),  # at 3x friction it sticks on the chamfer it first meets
        ({"grasp.x": 0.02}, None),  # 2 cm aside: on the wall's top, in none of the plan's
    ],
)
def test_a_plan_that_lost_a_particle_resumes_from_the_last_contact_that_particle_made(
    fixed_peg_plan, offsets, resumed_at
):
    task, worker, result = fixed_peg_plan
    assert [str(m.contact) for m in result.motions] == [
        "(wall_my/chamfer, peg/-z)",
        "(wall_my/inner, peg/-y)",
        "(floor/+z, peg/-z)",
    ]
    steps, reached = _made(task, result.motions, worker)
    lost = make_particle(task, offsets)
    evaluator = Evaluator(worker)
    search = bilba.contact_search(task, evaluator, "bilba-fixed", deadline=float("inf"))
    at = bilba.resume_at(task, search, steps, reached, [lost])
    assert evaluator.rollouts == 2  # the lost particle replayed up to the last contact
    if resumed_at is None:
        assert at is None
        return
    k, check = at
    assert k == resumed_at
    assert check.particles == (lost,)  # no check particles there before (made without)
    assert reached[k].mode in check.contacts[0]
    # with check particles there, the lost one joins them, last
    there = reached[k].belief.with_check(reached[k].belief)
    reached[k] = bilba.Reached(there, reached[k].mode, reached[k].steps)
    _, joined = bilba.resume_at(task, search, steps, reached, [lost])
    assert joined.particles == (*there.particles, lost)
    assert all(a is b for a, b in zip(joined.states, there.states, strict=False))
    replayed, before = joined.states[-1], check.states[0]  # the same rollouts again
    assert np.array_equal(replayed.X_WM.homogeneous, before.X_WM.homogeneous)
    # lost again after it was added in this attempt: once, last
    reached[k] = bilba.Reached(there.with_check(joined), reached[k].mode, reached[k].steps)
    _, again = bilba.resume_at(task, search, steps, reached, [lost])
    assert again.particles == joined.particles


def test_verification_replays_a_share_of_the_plans_rollouts_before_a_restart_too(
    fixed_peg_plan,
):
    """A fifth of the rollouts spent on the plan pays for its replay: a search that has
    spent none checks one offset (at each friction), and a restarted one, which resumes
    from the contacts of the search before it and spends few of its own before its first
    plan, counts that search's rollouts as well (counted alone, 3 of 11 restarted puzzle
    plans were checked on one offset)."""
    task, worker, result = fixed_peg_plan
    particles = verify_particles(task, 0.5)
    assert len(particles) == 42  # 14 offsets at 3 frictions
    checked = []
    for spent in (0, 10_000):
        search = bilba.contact_search(task, Evaluator(worker), "bilba-fixed", float("inf"))
        outcome = bilba.PlanResult(False, "", [], "bilba-fixed", 0)
        bilba._verify(task, result.motions, particles, search, outcome, spent)
        assert outcome.verification is not None and outcome.verification.passed
        checked.append(outcome.verification.particles)
    assert checked == [3, 42]


def test_a_restarted_search_goes_on_from_the_contacts_its_new_particles_made(fixed_peg_plan):
    """A restart on 5 particles replays the plan on 3 that failed verification from the new
    start belief, check particles included, and goes on from the last of its contacts
    that every one of them made; a belief that makes none of them starts over."""
    from bilba_dist.modes.schedule import belief_graph

    task, worker, result = fixed_peg_plan
    steps, reached = _made(task, result.motions, worker)
    raised = with_points(task, 5)
    particles = initial_belief(raised)
    b0 = start_belief(raised, bilba.planning_particles(raised, particles))
    b0 = b0.with_check(bilba.check_belief(raised, particles))
    evaluator = Evaluator(worker)
    search = bilba.contact_search(raised, evaluator, "bilba-fixed", deadline=float("inf"))
    graph, _ = belief_graph(raised, particles, raised.X_WG0, search.cache)
    made = bilba.restart_at(search, graph, b0, steps, reached)
    assert made is not None and made[0].belief is b0 and made[0].mode == FREE
    assert [r.mode for r in made[1:]] == [r.mode for r in reached[1:-1]]  # all but the goal
    assert [r.steps for r in made] == [0, 1, 2]
    last = made[-1].belief
    assert last.particles == b0.particles and last.check is not None
    assert last.check.particles == b0.check.particles  # the 10 twins carried along
    assert last.count(frozenset([reached[2].mode, task.goal])) == 5
    assert last.check.count(frozenset([reached[2].mode, task.goal])) == 10
    assert evaluator.rollouts == 2 * 15  # two motions on 5 particles and their 10 twins

    aside = start_belief(raised, [make_particle(raised, {"grasp.x": 0.02})])  # on a wall top
    assert bilba.restart_at(search, graph, aside, steps, reached) is None


def _watch_repair(monkeypatch) -> list[tuple]:
    """Spy on a search: ("verified", the plan's contacts, whether it lost particles) after
    each verification, ("from", mode, the last check particle's offsets) at each contact
    sought."""
    events: list[tuple] = []
    verify_plan, next_contact = bilba._verify, bilba._next_contact

    def verifying(task, motions, *args):
        lost = verify_plan(task, motions, *args)
        events.append(("verified", [str(m.contact) for m in motions], bool(lost)))
        return lost

    def searching(graph, belief, mode, *args):
        events.append(("from", str(mode), belief.check.particles[-1].offsets))
        return next_contact(graph, belief, mode, *args)

    monkeypatch.setattr(bilba, "_verify", verifying)
    monkeypatch.setattr(bilba, "_next_contact", searching)
    return events


def _after_first_refusal(events: list[tuple]) -> tuple[list[str], tuple]:
    """The first refused plan's contacts, and the event right after its verification."""
    k = next((k for k, e in enumerate(events) if e[0] == "verified" and e[2]), None)
    assert k is not None, "no plan was refused"
    return events[k][1], events[k + 1]


def test_a_plan_that_fails_verification_is_repaired_from_the_contact_both_made(monkeypatch):
    """The first plan loses a particle at 3x friction (stuck on the chamfer both reach with
    its first motion): the search goes on from that chamfer, the lost particle a check
    particle there, rather than from the start."""
    task = with_points(with_planner(load_task("peg-in-hole"), verify_effort=2.0), 3)  # no restart
    sticky = make_particle(task, {"friction": 2.0})
    monkeypatch.setattr(bilba, "verify_particles", lambda task, f: (sticky,))
    events = _watch_repair(monkeypatch)
    plan(task, RolloutWorker(task), "bilba-fixed", seed=0, timeout_s=30)
    first = next(k for k, e in enumerate(events) if e[0] == "verified")
    refused, after = _after_first_refusal(events)
    assert events[first][2] and refused[0] == "(wall_my/chamfer, peg/-z)"  # the first plan
    assert after == ("from", "(wall_my/chamfer, peg/-z)", sticky.offsets)


def test_a_task_of_our_own_is_repaired_from_a_contact_of_its_refused_plan(tmp_path, monkeypatch):
    """The repair on an octagonal peg of our own (not the peg whose plan the tests above
    pin): a particle stuck at 10x friction (it makes every contact of the plan but the
    goal) is not started over with, but taken on from a contact of the refused plan that it
    made too, where it joins the check particles."""
    task = prism_task(tmp_path, 8, 0.006, {"verify_effort": 2.0}, {"grasp.x": "1cm"})
    task = with_points(task, 3)  # its own points: repaired, not restarted on more
    sticky = make_particle(task, {"friction": 9.0})
    monkeypatch.setattr(bilba, "verify_particles", lambda task, f: (sticky,))
    events = _watch_repair(monkeypatch)
    plan(task, RolloutWorker(task), "bilba-fixed", seed=0, timeout_s=60)
    refused, (kind, mode, offsets) = _after_first_refusal(events)
    assert kind == "from" and mode != str(FREE)
    assert mode in refused[:-1]  # a contact of the refused plan before the goal
    assert offsets == sticky.offsets


def test_a_task_that_leaves_its_points_to_the_default_may_restart_on_two_more(tmp_path):
    """The restart's rule: only the axis belief's default points (our own prism task, the
    peg's `belief: {generator: axis}`), with verification on and bounds to verify; a task
    file's own points, another generator or the authors' preset are planned on as given.
    The rule survives the pickling that sends a task to a Ray worker."""
    import pickle
    from dataclasses import replace

    import yaml

    prism = prism_task(tmp_path, 6, 0.002)
    assert verify.raised_points(prism) == 5
    assert verify.raised_points(load_task("peg-in-hole", ["grasp.x=1cm", "env.y=1cm"])) == 5
    spec = pickle.loads(pickle.dumps(prism.spec))
    assert verify.raised_points(replace(prism, spec=spec)) == 5
    assert verify.raised_points(load_task("puzzle")) == 5  # no belief section: the default
    data = yaml.safe_load(prism_file(tmp_path, 6, 0.002).read_text())
    for belief in ({"generator": "axis", "points": 3}, {"generator": "extremal+random"}):
        assert verify.raised_points(load_task({**data, "belief": belief})) is None
    assert verify.raised_points(with_preset(prism, "paper")) is None  # verifies nothing
    assert verify.raised_points(load_task({**data, "uncertainty": {}})) is None
    raised = with_points(prism, 5)
    assert len(initial_belief(raised)) == 5 and verify.raised_points(raised) is None
    assert raised.manipuland is prism.manipuland  # only the belief differs


def test_only_offsets_inside_the_bounds_are_between_the_particles():
    task = load_task("peg-in-hole", ["grasp.x=1cm"])
    assert verify.between(task, list(verify_particles(task, 0.5)))  # drawn inside, 3 frictions
    assert verify.between(task, [make_particle(task, {"grasp.x": -0.01, "friction": 2.0})])
    assert not verify.between(task, [make_particle(task, {"grasp.x": 0.012})])  # beyond
    assert not verify.between(task, [make_particle(task, {"env.y": 0.001})])  # certain axis


def _friction_lost(monkeypatch, task):
    """Verification on the nominal offset at 3x friction, where the peg's plans stick on the
    chamfer: every plan fails it (offsets inside the bounds: a twin's friction aside)."""
    stuck = make_particle(task, {"friction": 2.0})
    monkeypatch.setattr(bilba, "verify_particles", lambda task, f: (make_particle(task, {}), stuck))


def test_a_first_plan_that_fails_verification_between_the_particles_restarts_on_five(
    monkeypatch,
):
    """The peg on its default 3 particles: its first plan fails verification, so the search
    starts again on 5 within the same deadline, counting both searches' rollouts and plans;
    with none passing by verify_effort, the best comes back marked failed, for the task on 5.
    The same search on a task file's own `points: 3` is planned on 3 to the end."""
    import time

    import yaml

    from bilba_dist.planning.recorder import NullRecorder
    from bilba_dist.task.loader import builtin_tasks

    class Clocked(NullRecorder):
        def restarted(self, points: int, particles: int, reason: str) -> None:
            self.at = time.perf_counter()

    task = with_planner(load_task("peg-in-hole"), verify_effort=1.0)  # no time to repair
    worker = RolloutWorker(task)
    _friction_lost(monkeypatch, task)
    recorder, began = Clocked(), time.perf_counter()
    result = plan(task, worker, "bilba-fixed", seed=0, timeout_s=120, recorder=recorder)
    # verify_effort counts from the start of planning, the first search's time included
    # (the restarted search resumes: timed from its own start its first plan comes so soon
    # that the limit would cut its repairs short)
    assert result.first_plan_s > recorder.at - began
    assert result.planning_time_s < result.first_plan_s + 10
    assert result.resumed is not None
    assert result.task is not None and len(initial_belief(result.task)) == 5
    assert result.task.spec.belief.points == 5 and result.task.spec.planner == task.spec.planner
    check = result.verification
    assert result.success and check is not None and not check.passed and check.plans >= 2
    assert result.reason.startswith("no plan passed verification within 1x the time")
    assert "belief: {points: 7}" in result.reason  # the hint reads the task planned on

    data = yaml.safe_load(builtin_tasks()["peg-in-hole"].read_text())
    own = with_planner(load_task({**data, "belief": {"points": 3}}), verify_effort=1.0)
    kept = plan(own, worker, "bilba-fixed", seed=0, timeout_s=120)
    assert kept.task is own and kept.verification is not None and not kept.verification.passed
    assert "belief: {points: 5}" in kept.reason
    assert result.rollouts > kept.rollouts  # the first search's rollouts are counted too


def test_a_restarted_plan_embeds_its_task_and_its_log_says_why(tmp_path, monkeypatch, peg_yaml):
    """`bilba plan` prints the restart, the plan file embeds the task on 5 particles (so
    `bilba validate` replays those) and the log has a /restart message before the start
    belief is drawn again."""
    _friction_lost(monkeypatch, load_task("peg-in-hole"))
    out, log = tmp_path / "p.json", tmp_path / "l.mcap"
    path = write_task(tmp_path, {**peg_yaml, "planner": {"verify_effort": 2.0}})
    result = run_cli("plan", str(path), "--planner", "bilba-fixed", "--workers", "0",
                     "--out", str(out), "--log", str(log))  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "belief     restarted on 5 particles a bounded axis (5 in all)" in result.output
    document = json.loads(out.read_text())
    assert document["task"]["spec"]["belief"]["points"] == 5
    assert read_plan(out).task().spec.belief.points == 5
    messages = read_log(log)
    (restart,) = messages.json("/restart")
    assert restart["points"] == 5 and restart["particles"] == 5
    assert restart["reason"].startswith("a plan failed verification on")
    topics = [topic for topic, _, _ in messages.records]
    restarted = topics.index("/restart")
    assert "/verify" in topics[:restarted] and "/scene" in topics[restarted:]
    (resume,) = messages.json("/resume")  # the 5 made the first plan's chamfer contact too
    assert resume["motions"] >= 1 and topics.index("/resume") > restarted
    assert f"resumed at {resume['contact']}" in result.output
    validated = run_cli("validate", str(out))
    assert " of 5 reach " in validated.output, validated.output
