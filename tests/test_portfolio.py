"""`bilba plan --portfolio N`: seeded searches side by side on a real local Ray instance; the
first plan found is written, and it is the plan its seed makes alone."""

import json
import re

import pytest
from click.testing import CliRunner

from bilba_dist.cli.main import cli, register
from bilba_dist.planning.bilba import plan
from bilba_dist.record.reader import read_log
from bilba_dist.task.loader import load_task
from bilba_dist.workers.rollout_worker import RolloutWorker


def run(*args: str):
    register()
    return CliRunner().invoke(cli, list(args))


def test_portfolio_writes_the_winning_seeds_plan_and_log(tmp_path):
    out, log = tmp_path / "plan.json", tmp_path / "log.mcap"
    result = run(
        "plan", "peg-in-hole", "-u", "grasp.pitch=2deg", "--planner", "bilba-fixed",
        "--seed", "3", "--portfolio", "2", "--workers", "2", "--out", str(out), "--log", str(log),
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    winner = int(re.search(r"plan found by seed (\d+)", result.output).group(1))
    assert winner in (3, 4)
    document = json.loads(out.read_text())
    assert document["seed"] == winner and document["success"] is True
    task = load_task("peg-in-hole", ["grasp.pitch=2deg"])
    alone = plan(task, RolloutWorker(task), "bilba-fixed", seed=winner)
    assert [m["G_d"]["xyz"] for m in document["motions"]] == [
        list(m.G_d.translation) for m in alone.motions
    ]
    assert read_log(log).metadata["seed"] == winner


def test_portfolio_searches_on_actors_of_their_own_make_the_seeds_plan(tmp_path):
    """--search-actors 1: each search's rollouts run on an actor of its own; the plan written
    is still the winner's plan alone (a seeded plan is the same on any backend)."""
    out = tmp_path / "plan.json"
    result = run(
        "plan", "peg-in-hole", "-u", "grasp.pitch=2deg", "--planner", "bilba-fixed",
        "--seed", "5", "--portfolio", "2", "--search-actors", "1", "--workers", "2",
        "--out", str(out), "--no-log",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "1 rollout actor each" in result.output
    winner = int(re.search(r"plan found by seed (\d+) .* on 1 actor\b", result.output).group(1))
    task = load_task("peg-in-hole", ["grasp.pitch=2deg"])
    alone = plan(task, RolloutWorker(task), "bilba-fixed", seed=winner)
    assert [m["G_d"]["xyz"] for m in json.loads(out.read_text())["motions"]] == [
        list(m.G_d.translation) for m in alone.motions
    ]


@pytest.mark.parametrize(
    ("args", "error"),
    [
        (["--search-actors", "2"], "--search-actors is for --portfolio N (2 or more)"),
        (
            ["--portfolio", "2", "--search-actors", "2", "--workers", "3"],
            "--portfolio 2 × --search-actors 2 needs 4 CPUs; the local Ray instance has "
            "--workers 3",
        ),
    ],
)
def test_search_actors_that_cannot_run_are_one_line(args, error):
    result = run("plan", "peg-in-hole", "--no-log", *args)
    assert result.exit_code == 2
    assert error in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_portfolio_needs_ray_workers(tmp_path):
    result = run("plan", "peg-in-hole", "--portfolio", "2", "--workers", "0", "--no-log")
    assert result.exit_code == 2
    assert "--portfolio runs its searches on Ray" in result.output


def test_portfolio_plan_file_that_cannot_be_written_is_one_line(tmp_path):
    """--out lies under a file: the searches run, then writing fails in one line, exit 2."""
    (tmp_path / "file").write_text("")
    out = tmp_path / "file" / "plan.json"
    result = run(
        "plan", "peg-in-hole", "-u", "grasp.pitch=1deg", "--portfolio", "2", "--workers", "2",
        "--no-log", "--out", str(out),
    )  # fmt: skip
    assert result.exit_code == 2, result.output
    assert f"{out}: cannot write plan file" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_log_that_cannot_be_written_is_one_line_before_planning(tmp_path):
    (tmp_path / "file").write_text("")
    log = tmp_path / "file" / "log.mcap"
    result = run("plan", "peg-in-hole", "--workers", "0", "--log", str(log))
    assert result.exit_code == 2
    assert f"{log}: cannot write log" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and result.stdout == ""


def test_cancelling_the_losers_keeps_their_worker_processes(tmp_path):
    """A loser is interrupted, not killed: the worker that ran it serves the next task (a
    forced cancel would kill it, and the next search would pay the imports again)."""
    import os
    import time

    import ray

    from bilba_dist.schedulers.portfolio import _stop
    from bilba_dist.schedulers.session import ray_session

    marker = tmp_path / "pid"

    def busy(path: str) -> None:
        with open(path, "w") as file:
            file.write(str(os.getpid()))
        end = time.monotonic() + 60
        while time.monotonic() < end:
            sum(range(1000))

    def pid() -> int:
        return os.getpid()

    with ray_session(1, None):
        ref = ray.remote(num_cpus=1)(busy).remote(str(marker))
        while not marker.exists() or not marker.read_text():
            time.sleep(0.05)
        started = time.monotonic()
        _stop(ray, [ref])
        assert time.monotonic() - started < 5  # interrupted, not waited out
        with pytest.raises(ray.exceptions.TaskCancelledError):
            ray.get(ref)
        after = ray.get(ray.remote(num_cpus=1)(pid).remote())
    assert after == int(marker.read_text())


def test_searches_on_actors_give_their_cpus_back():
    """After a portfolio with --search-actors, every CPU is free again: the winner closed
    its pool and the cancelled search took its actors with it (none left holding a CPU)."""
    import time

    import ray

    from bilba_dist.schedulers.portfolio import run_portfolio
    from bilba_dist.schedulers.session import ray_session
    from bilba_dist.task.loader import load_task

    task = load_task("peg-in-hole", ["grasp.pitch=2deg"])
    with ray_session(2, None):
        found = run_portfolio(task, "bilba-fixed", [3, 4], 60.0, actors=1)
        assert found.winner in (3, 4) and found.output["rollout_actors"] == 1
        deadline = time.monotonic() + 20
        while ray.available_resources().get("CPU", 0) < 2 and time.monotonic() < deadline:
            time.sleep(0.2)
        assert ray.available_resources().get("CPU", 0) == 2
