import numpy as np
import pytest

from bilba_dist.belief.particles import initial_belief, random_offsets, stratified_offsets
from bilba_dist.belief.start import start_belief
from bilba_dist.task.loader import build_task, load_task


def test_axis_belief_is_nominal_plus_and_minus_n(peg):
    particles = initial_belief(peg)
    assert [p.offsets for p in particles] == [
        {},
        {"grasp.pitch": pytest.approx(np.deg2rad(2))},
        {"grasp.pitch": pytest.approx(-np.deg2rad(2))},
    ]
    nominal = particles[0].X_OM(peg.X_WG0)
    assert np.allclose(nominal.rotation, np.eye(3))
    assert np.allclose(nominal.translation, [0, 0, 0.205])  # 0.36 - 0.155 above the table
    tilted = particles[1].X_OM(peg.X_WG0).rotation
    assert np.degrees(np.arccos((np.trace(tilted) - 1) / 2)) == pytest.approx(2.0)


def test_axis_belief_with_more_points_fills_in_between():
    task = load_task("puzzle", ["grasp.x=1cm"])
    offsets = [
        p.offsets for p in initial_belief(_with_belief(task, {"generator": "axis", "points": 5}))
    ]
    assert offsets == [{}, *({"grasp.x": pytest.approx(v)} for v in (0.01, -0.01, 0.005, -0.005))]
    seven = [
        p.offsets for p in initial_belief(_with_belief(task, {"generator": "axis", "points": 7}))
    ]
    steps = [1, -1, 2 / 3, -2 / 3, 1 / 3, -1 / 3]
    assert [o["grasp.x"] for o in seven[1:]] == pytest.approx([0.01 * k for k in steps])
    three = [
        p.offsets for p in initial_belief(_with_belief(task, {"generator": "axis", "points": 3}))
    ]
    assert three == offsets[:3]


def test_env_offset_moves_the_environment():
    task = load_task("peg-in-hole", ["env.y=1cm"])
    _, plus, minus = initial_belief(task)
    assert plus.X_WO.translation[1] == pytest.approx(0.01)
    assert plus.X_OM(task.X_WG0).translation[1] == pytest.approx(-0.01)
    assert minus.X_WO.translation[1] == pytest.approx(-0.01)


def test_a_belief_splits_and_joins_by_particle(peg):
    belief = start_belief(peg, initial_belief(peg))
    nominal, plus, minus = belief.particles
    rest = belief.without([plus])
    assert rest.particles == (nominal, minus)
    assert rest.states == (belief.states[0], belief.states[2])
    assert (rest + belief[1:2]).particles == (nominal, minus, plus)
    assert belief.without([]).particles == belief.particles
    assert len(belief.without(belief.particles)) == 0


def _with_belief(task, belief):
    spec = task.spec.model_validate({**task.spec.model_dump(), "belief": belief})
    return build_task(spec, task.source)


def test_extremal_random_is_seeded_and_inside_the_ellipsoid():
    task = load_task("peg-in-hole", ["grasp.x=1cm", "grasp.z=5mm", "grasp.pitch=3deg"])
    spec = {"generator": "extremal+random", "random": 8, "seed": 7}
    first = initial_belief(_with_belief(task, spec))
    again = initial_belief(_with_belief(task, spec))
    other = initial_belief(_with_belief(task, {**spec, "seed": 8}))
    assert len(first) == 6 + 8
    assert [p.offsets for p in first] == [p.offsets for p in again]
    assert [p.offsets for p in first] != [p.offsets for p in other]
    bounds = task.spec.uncertainty
    for p in first[6:]:
        assert sum((v / bounds[k]) ** 2 for k, v in p.offsets.items()) <= 1.0


def test_random_offsets_fill_the_ellipsoid():
    offsets = random_offsets({"a": 1.0, "b": 2.0}, 4000, seed=0)
    radii = np.array([np.hypot(o["a"], o["b"] / 2) for o in offsets])
    assert radii.max() <= 1.0
    assert np.mean(radii < 0.5) == pytest.approx(0.25, abs=0.03)  # uniform in 2-D: r² ~ U


def test_explicit_particles(peg):
    belief = {
        "generator": "explicit",
        "particles": [{}, {"grasp": {"x": "5mm"}, "env": {"yaw": "1deg"}}],
    }
    _, second = initial_belief(_with_belief(peg, belief))
    assert second.offsets == pytest.approx({"grasp.x": 0.005, "env.yaw": np.deg2rad(1)})


def test_stratified_offsets_put_one_in_each_slice_of_the_bound():
    offsets = [o["grasp.x"] for o in stratified_offsets({"grasp.x": 0.01}, 14, seed=3)]
    slices = np.floor((np.array(offsets) + 0.01) / 0.02 * 14).astype(int)
    assert sorted(slices) == list(range(14))
    assert min(slices[:7]) < 4 and max(slices[:7]) > 9  # a prefix spreads over the bound too
    assert offsets == [o["grasp.x"] for o in stratified_offsets({"grasp.x": 0.01}, 14, seed=3)]


def _covering_radius(offsets: list[dict[str, float]], bounds: dict[str, float]) -> float:
    """How far (against the bounds) the worst-covered point of the ellipsoid is from an offset."""
    probe = np.array([[p[k] / bounds[k] for k in bounds] for p in random_offsets(bounds, 4000, 11)])
    drawn = np.array([[o[k] / bounds[k] for k in bounds] for o in offsets])
    return float(np.linalg.norm(probe[:, None] - drawn[None], axis=2).min(axis=1).max())


def test_stratified_offsets_of_several_axes_cover_the_ellipsoid_evenly():
    bounds = {"grasp.x": 0.01, "env.y": 0.02, "grasp.pitch": 0.035}
    offsets = stratified_offsets(bounds, 14, seed=3)
    assert offsets == stratified_offsets(bounds, 14, seed=3)
    unit = np.array([[o[k] / bounds[k] for k in bounds] for o in offsets])
    assert len(unit) == 14 and np.all(np.linalg.norm(unit, axis=1) <= 1.0)
    # the worst-covered point is nearer an offset than for any of 20 random draws of 14
    randoms = [_covering_radius(random_offsets(bounds, 14, s), bounds) for s in range(20)]
    assert _covering_radius(offsets, bounds) < min(randoms)
    # farthest-first: the first 4 lie far apart (the random draw's first 4 of seed 3: 0.47)
    first = np.linalg.norm(unit[:4, None] - unit[None, :4], axis=2)
    assert first[np.triu_indices(4, 1)].min() > 0.8
