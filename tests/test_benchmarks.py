"""The benchmark scripts' own argument checks (their runs are minutes long: not tested here)."""

import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def run_script(script: str, *args: str) -> subprocess.CompletedProcess:
    """benchmarks/SCRIPT with ``args``, in this interpreter, output captured."""
    return subprocess.run(
        [sys.executable, str(BENCHMARKS / script), *args],
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize(
    ("flag", "value", "shown"),
    [
        ("--sample-patience", "-1", "-1"),
        ("--race-contacts", "-1", "-1"),
        ("--near-edges", "-0.001", "-0.001"),
        ("--near-edges", "nan", "nan"),
        ("--press", "-0.02", "-0.02"),
    ],
)
def test_planning_benchmark_refuses_a_negative_setting_in_one_line(flag, value, shown):
    run = run_script("planning.py", flag, value)
    assert run.returncode == 2
    errors = [line for line in run.stderr.splitlines() if "error:" in line]
    assert errors == [f"planning.py: error: argument {flag}: must be 0 or more, got {shown}"]


def test_scaling_without_psutil_says_how_to_get_it_in_one_line():
    hide = "import sys; sys.modules['psutil'] = None; sys.path.insert(0, sys.argv[1]); "
    run = subprocess.run(
        [sys.executable, "-c", hide + "import cpu_split", str(BENCHMARKS)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 1
    assert run.stderr.strip().splitlines() == [
        "psutil is missing (it comes with the dev extra): .venv/bin/pip install -e '.[dev]'"
    ]


@pytest.mark.parametrize(
    ("serial_s", "wall_s", "actors", "bound"),
    [(0.0, 10.0, 2, 2.0), (10.0, 10.0, 2, 1.0), (1.0, 10.0, 2, 1 / 0.55), (2.0, 10.0, 4, 2.5)],
)
def test_serial_share_bounds_the_speedup_as_amdahl_says(
    serial_s, wall_s, actors, bound, monkeypatch
):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from cpu_split import serial_bound

    assert serial_bound(serial_s, wall_s, actors) == pytest.approx(bound)


def test_batch_speedup_compares_the_time_with_a_batch_in_flight(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from cpu_split import batch_speedup

    # 9 s of batches on one actor, 5 s on two; the serial second is the same on both.
    assert batch_speedup({"wall": 10.0, "serial": 1.0}, {"wall": 6.0, "serial": 1.0}) == 1.8
    assert batch_speedup({"wall": 10.0, "serial": 4.0}, {"wall": 7.0, "serial": 4.0}) == 2.0


def test_table1_puts_our_medians_beside_the_papers_with_the_ratio_to_best(tmp_path):
    """Records of a small made-up batch: medians over successes, a B-EST timeout counted at
    its timeout (the ratio then an upper bound), cells not run said so."""
    import json

    def record(planner, seed, status, time_s):
        return {"task": "peg-in-hole", "setting": "x1", "planner": planner, "seed": seed,
                "status": status, "planning_time_s": time_s, "rollouts": 10,
                "timeout_s": 600.0}  # fmt: skip

    rows = [record("bilba-variable", s, "success", t) for s, t in enumerate([2.0, 4.0, 9.0])]
    for row, verified in zip(rows, [True, False, True], strict=True):  # False: the best plan
        row["verified"] = verified  # of a search whose plans kept failing verification
    rows += [record("bilba-fixed", 0, "success", 3.0), record("bilba-fixed", 1, "timeout", 900)]
    rows += [record("b-est", 0, "success", 100.0), record("b-est", 1, "timeout", 650.0)]
    (tmp_path / "records.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    run = run_script("table1.py", str(tmp_path))
    assert run.returncode == 0, run.stderr
    line = next(x for x in run.stdout.splitlines() if x.startswith("| peg-in-hole | x1 |"))
    # B-EST: median of 100 and the 600 s timeout = 350; BILBA's faster median 3.0
    assert line == (
        "| peg-in-hole | x1 | 4.0 ± 2.0 (3/3, 2 verified) | 3.0 ± 0.0 (1/2) | 100.0 ± 0.0 (1/2) "
        f"| 20.1 / 21.1 / 187.0 | ≤ {3.0 / 350.0:.3f} |"
    )
    assert "| puzzle | x1 | not run | not run | not run |" in run.stdout
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    assert summary["cells"]["peg-in-hole/x1"]["bilba-variable"] == 4.0


def test_compact_belief_plans_on_the_extremal_particles_and_a_seeded_subset_of_the_rest():
    """b_plan(α): the 6 extremal particles of b_full and α of its 8 random ones, without
    replacement, the same for the same seed; b_plan(8) is b_full."""
    sys.path.insert(0, str(BENCHMARKS))
    try:
        from compact_belief import full_task, plan_task
    finally:
        sys.path.remove(str(BENCHMARKS))
    from bilba_dist.belief.particles import initial_belief

    def offsets(task):
        return [tuple(sorted(p.offsets.items())) for p in initial_belief(task)]

    task = full_task()
    full = offsets(task)
    assert len(full) == 14 and len(set(full)) == 14
    for alpha in (0, 3, 8):
        picked = offsets(plan_task(task, alpha, seed=1))
        assert len(picked) == 6 + alpha and len(set(picked)) == 6 + alpha
        assert picked[:6] == full[:6] and set(picked) <= set(full)
        assert picked == offsets(plan_task(task, alpha, seed=1))
    assert set(offsets(plan_task(task, 8, seed=0))) == set(full)
    assert offsets(plan_task(task, 3, seed=0)) != offsets(plan_task(task, 3, seed=1))


def test_compact_belief_refuses_an_alpha_outside_0_to_8_in_one_line():
    run = run_script("compact_belief.py", "--alphas", "9")
    assert run.returncode == 2
    errors = [line for line in run.stderr.splitlines() if "error:" in line]
    assert errors == ["compact_belief.py: error: --alphas: each must be in 0..8"]


@pytest.mark.parametrize(
    ("script", "args", "error"),
    [
        ("scaling.py", ["--actors", "1", "0"], "argument --actors: must be 1 or more, got 0"),
        ("scaling.py", ["--batch-cpus", "-2"], "argument --batch-cpus: must be 1 or more, got -2"),
        ("portfolio.py", ["--parallel", "0"], "argument --parallel: must be 1 or more, got 0"),
        (
            "portfolio.py",
            ["--ns", "1", "4", "--cpus", "2"],
            "--parallel 1 × N 4 × 1 CPUs a search needs more than 2 CPUs",
        ),
        (
            "portfolio.py",
            ["--ns", "1", "2", "--search-actors", "2", "--cpus", "3"],
            "--parallel 1 × N 2 × 2 CPUs a search needs more than 3 CPUs",
        ),
        (
            "portfolio.py",
            ["--search-actors", "-1"],
            "argument --search-actors: must be 0 or more, got -1",
        ),
        (
            "portfolio.py",
            ["--splits", "2x2", "8x1", "1x16", "--cpus", "8"],
            "--parallel 1 × N 1 × 16 CPUs a search needs more than 8 CPUs",
        ),
        (
            "portfolio.py",
            ["--splits", "4"],
            "argument --splits: must be NxC (searches x CPUs a search), got '4'",
        ),
        ("portfolio.py", ["--splits", "0x4"], "argument --splits: must be 1 or more, got 0"),
    ],
)
def test_scaling_and_portfolio_refuse_counts_they_cannot_run_in_one_line(script, args, error):
    """Checked before Ray starts: a count below 1, or more searches at once than CPUs."""
    run = run_script(script, *args)
    assert run.returncode == 2
    assert [line for line in run.stderr.splitlines() if "error:" in line] == [
        f"{script}: error: {error}"
    ]


def test_robustness_refuses_a_negative_draw_seed_in_one_line(tmp_path):
    run = run_script("robustness.py", str(tmp_path), "--draw", "-1")
    assert run.returncode == 2
    assert [line for line in run.stderr.splitlines() if "error:" in line] == [
        "robustness.py: error: argument --draw: must be 0 or more, got -1"
    ]


@pytest.mark.parametrize("value", ["nan", "0.5", "0", "-0.004"])
def test_robustness_refuses_a_time_step_outside_the_schemas_range_in_one_line(value, tmp_path):
    """Checked while parsing, before any plan is read or replayed."""
    run = run_script("robustness.py", str(tmp_path), "--timestep", value)
    assert run.returncode == 2
    assert [line for line in run.stderr.splitlines() if "error:" in line] == [
        f"robustness.py: error: argument --timestep: must be within [0.0001, 0.02] s, got {value}"
    ]


def test_expected_first_plan_is_the_minimum_of_draws(monkeypatch):
    """Order statistics against brute force: every N-tuple of draws from three times."""
    import itertools

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from portfolio import expected_min

    times = [3.0, 10.0, 30.0]
    for n in (1, 2, 3):
        tuples = list(itertools.product(times, repeat=n))
        assert expected_min(times, n) == pytest.approx(sum(map(min, tuples)) / len(tuples))


def _batch(folder: Path, task: str, rollouts: dict[tuple[str, int], int]) -> Path:
    """A made-up batch folder: one successful run of ``task`` per (setting, seed)."""
    import json

    folder.mkdir()
    rows = [
        {"task": task, "setting": setting, "planner": "bilba-variable", "seed": seed,
         "status": "success", "planning_time_s": n / 100, "rollouts": n, "verified": True}
        for (setting, seed), n in rollouts.items()
    ]  # fmt: skip
    (folder / "records.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return folder


def test_ab_pairs_runs_by_seed_and_says_how_sure_a_ratio_is(tmp_path):
    """x1: every seed halves (the interval is the value); y1: seeds swing 4x either way
    around a geometric mean of 1 (the interval straddles it); B's extra seed has no twin."""
    import json

    a = {("x1", s): n for s, n in enumerate([100, 200, 400, 800])}
    a |= {("y1", s): 100 for s in range(6)}
    b = {("x1", s): n // 2 for s, n in enumerate([100, 200, 400, 800])} | {("x1", 9): 5}
    b |= {("y1", s): n for s, n in enumerate([400, 25, 400, 25, 400, 25])}
    _batch(tmp_path / "a", "/a/peg.yaml", a), _batch(tmp_path / "b", "/b/peg-copy.yaml", b)
    apart = run_script("ab.py", str(tmp_path / "a"), str(tmp_path / "b"))
    assert apart.returncode == 1 and apart.stderr.count("\n") == 1
    assert "--ignore-task" in apart.stderr  # the tasks' paths differ: no pairs by task
    run = run_script("ab.py", str(tmp_path / "a"), str(tmp_path / "b"), "--ignore-task")
    assert run.returncode == 0, run.stderr
    assert "| x1 bilba-variable | 4 | 4/4, 4 verified → 4/4, 4 verified | 3.0 → 1.5 | " \
        "0.50 [0.50, 0.50] |" in run.stdout  # fmt: skip
    y1 = next(x for x in run.stdout.splitlines() if x.startswith("| y1 "))
    low, high = (float(v) for v in y1.split("[")[1].split("]")[0].split(", "))
    assert y1.split("|")[5].strip().startswith("1.00") and low < 1 < high
    figures = json.loads(run.stdout.strip().splitlines()[-1])
    assert figures["pairs"] == 10 and figures["rollouts"] == [2100, 750 + 1275]
    assert figures["geomean_ratio"][0] == round(0.5 ** (4 / 10), 3)  # x1's 4 halved, y1's 6 at 1


@pytest.mark.parametrize("args", [["missing"], ["a", "--seed", "-1"]])
def test_ab_refuses_a_folder_without_records_in_one_line(tmp_path, args):
    _batch(tmp_path / "a", "peg-in-hole", {("x1", 0): 10})
    run = run_script("ab.py", str(tmp_path / "a"), *(str(tmp_path / x) for x in args[:1]),
                     *args[1:])  # fmt: skip
    assert run.returncode != 0 and run.stderr.count("\n") == 1 and "Traceback" not in run.stderr
