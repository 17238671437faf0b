"""Batch grids on a real local Ray: records, resume after an interrupted driver, timeouts,
the report, a lost node, and a batch submitted with `ray job submit`."""

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from bilba_dist.cli.main import cli, register
from bilba_dist.schedulers.batch import RECORDS, read_records, run_batch
from bilba_dist.schedulers.jobs import load_jobs
from tests.conftest import raylets_of

ROOT = Path(__file__).resolve().parents[1]
SMOKE = ROOT / "deploy" / "jobs" / "smoke.yaml"  # 4 jobs: peg pitch, 2 planners × 2 seeds
#: 4 jobs of 2-3 s each, for the tests that interrupt a batch while jobs run
SLOW_SMOKE = ROOT / "tests" / "data" / "hex-smoke.yaml"
BIN = Path(sys.executable).parent


def run(*args: str):
    register()
    return CliRunner().invoke(cli, list(args))


def wait_for_records(out: Path, n: int, timeout_s: float = 180) -> None:
    deadline = time.time() + timeout_s
    while len(read_records(out)) < n:
        assert time.time() < deadline, f"no {n} records in {timeout_s} s"
        time.sleep(0.2)


def batch_with_one_record(out: Path) -> subprocess.Popen:
    """`bilba batch` of the slow smoke grid on one CPU, running, its first job recorded."""
    driver = subprocess.Popen(
        [BIN / "bilba", "batch", SLOW_SMOKE, "--out", out, "--workers", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_for_records(out, 1)
    return driver


def motions(folder: Path, record: dict) -> list:
    return json.loads((folder / record["plan"]).read_text())["motions"]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "name: a\ntasks: [peg-in-hole]\nseed: 3\n",
            "jobs.yaml:3: seed: unknown key 'seed'; allowed:",
        ),
        ("name: a\ntasks: [peg-in-hole]\nplanners: [rrt]\n", "jobs.yaml:3: planners[0]:"),
        ("name: a\ntasks: [no-such-task]\n", "task 'no-such-task', setting 'task'"),
        (
            "name: a\ntasks: [peg-in-hole]\nuncertainty: {x: [grasp.x=1parsec]}\n",
            "task 'peg-in-hole', setting 'x'",
        ),
        (  # a part held too short for its hole (tests/test_gripper.py)
            f"name: a\ntasks: [{Path('tests/data/chamfer-tip.yaml').resolve()}]\n",
            "the gripper meets the environment before the part reaches",
        ),
    ],
)
def test_a_bad_jobs_file_is_one_line_and_exit_2_before_ray_starts(text, message, tmp_path):
    jobs = tmp_path / "jobs.yaml"
    jobs.write_text(text)
    result = run("batch", str(jobs), "--out", str(tmp_path / "out"))
    assert result.exit_code == 2, result.output
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_a_batch_without_workers_or_a_report_without_records_is_one_line_and_exit_2(tmp_path):
    result = run("batch", str(SMOKE), "--workers", "0", "--out", str(tmp_path / "out"))
    assert result.exit_code == 2 and "--workers: a batch needs at least 1" in result.stderr
    assert not (tmp_path / "out").exists()
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / RECORDS).write_text("")
    result = run("report", str(tmp_path / "empty"))
    assert result.exit_code == 2 and "no job records yet" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_batch_folder_that_cannot_be_written_is_one_line_before_any_job(tmp_path):
    (tmp_path / "file").write_text("not a folder")
    result = run("batch", str(SMOKE), "--workers", "1", "--out", str(tmp_path / "file" / "out"))
    assert result.exit_code == 2, result.output
    (line,) = result.stderr.strip().splitlines()  # no progress bar before it
    assert line.startswith("bilba: error: ") and "cannot write the batch there" in line


RECORD = {"id": "j", "task": "peg-in-hole", "setting": "x1", "planner": "bilba-fixed", "seed": 0}


@pytest.mark.parametrize(
    "line",
    [
        b"\xff\xfe not UTF-8",
        b'{"a": 1}',
        b"[1, 2]",
        json.dumps(
            {**RECORD, "status": "success", "planning_time_s": "NaN", "rollouts": 3}
        ).encode(),
        json.dumps({**RECORD, "seed": True, "status": "timeout"}).encode(),
    ],
)
def test_a_damaged_or_edited_records_line_is_skipped_not_a_crash(line, tmp_path):
    """`report` and `--resume` read only lines that are records as `run_batch` writes them."""
    good = {**RECORD, "id": "k", "status": "success", "planning_time_s": 2.5, "rollouts": 76}
    (tmp_path / RECORDS).write_bytes(line + b"\n" + json.dumps(good).encode() + b"\n")
    assert read_records(tmp_path) == [good]
    result = run("report", str(tmp_path))
    assert result.exit_code == 0, result.output
    assert "2.5" in result.output and "1/1" in result.output
    (tmp_path / RECORDS).write_bytes(line + b"\n")
    result = run("report", str(tmp_path))
    assert result.exit_code == 2 and "(1 line, none a job record" in result.stderr


def test_report_counts_the_plans_that_passed_verification(tmp_path):
    """A cell's `verified` column: successes whose plan passed verification; "-" when no
    record says (verification off, or records from before it)."""
    done = {**RECORD, "status": "success", "planning_time_s": 2.0, "rollouts": 50}
    rows = [
        {**done, "id": "a", "verified": True},
        {**done, "id": "b", "verified": False},  # the best plan, verification kept failing
        {**done, "id": "c", "verified": True},
        {**RECORD, "id": "d", "status": "timeout", "planning_time_s": 9.0, "rollouts": 80},
        {**done, "id": "e", "setting": "x2"},  # no verification recorded
    ]
    (tmp_path / RECORDS).write_text("".join(json.dumps(r) + "\n" for r in rows))
    result = run("report", str(tmp_path))
    assert result.exit_code == 0, result.output
    x1, x2 = (line.split() for line in result.output.splitlines()[1:3])
    assert x1[:3] == ["peg-in-hole", "x1", "bilba-fixed"] and x1[-3:] == ["3/4", "2/3", "50"]
    assert x2[-3:] == ["1/1", "-", "50"]
    assert "verified = plans that passed verification" in result.output


def test_report_columns_fit_a_users_task_named_by_its_path(tmp_path):
    """A jobs file names a user's task by its path; a long one must not run into the
    setting's column."""
    task = "/home/someone/parts/my-own-triangular-peg.yaml"
    done = {**RECORD, "task": task, "status": "success", "planning_time_s": 2.0, "rollouts": 5}
    (tmp_path / RECORDS).write_text(json.dumps(done) + "\n")
    result = run("report", str(tmp_path))
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[1].split()[:3] == [task, "x1", "bilba-fixed"]


def test_the_paper_grids_cover_its_whole_table():
    """Table 1: 8 peg settings × 2 BILBA variants × 5 seeds, B-EST on the same 8, 4 puzzle."""
    settings = {"pitch1", "pitch2", "pitch3", "pitch4", "x1", "x2", "y1", "y2"}
    expected = {"paper": (80, settings), "paper-best": (24, settings)}
    expected["paper-puzzle"] = (40, {"pitch1", "pitch2", "x1", "y1"})
    for name, (count, names) in expected.items():
        batch = load_jobs(ROOT / "deploy" / "jobs" / f"{name}.yaml")
        assert len(batch.jobs) == count and len({j.id for j in batch.jobs}) == count
        assert {j.setting for j in batch.jobs} == names
    batch = load_jobs(ROOT / "deploy" / "jobs" / "paper.yaml")
    by_setting = {j.setting: batch.spec(j).uncertainty for j in batch.jobs}
    assert by_setting["pitch4"] == pytest.approx({"grasp.pitch": 0.0698132}, 1e-5)
    assert by_setting["y2"] == pytest.approx({"env.y": 0.02})


@pytest.fixture(scope="module")
def smoke_batch(tmp_path_factory):
    """The smoke grid, its driver interrupted (SIGINT) after the first record, a torn record
    line appended as a killed driver would leave it, then finished with --resume."""
    out = tmp_path_factory.mktemp("batch") / "hex-smoke"
    driver = batch_with_one_record(out)
    driver.send_signal(signal.SIGINT)
    _, err = driver.communicate(timeout=60)
    before = read_records(out)
    with (out / RECORDS).open("a") as f:
        f.write('{"id": "peg-in-hole-pitch-bil')  # torn: a killed driver mid-write
    resumed = run("batch", str(SLOW_SMOKE), "--out", str(out), "--resume")
    return out, driver.returncode, err, before, resumed


def test_interrupted_batch_resumes_running_only_what_was_missing(smoke_batch):
    out, code, err, before, resumed = smoke_batch
    assert code == 130 and "--resume" in err
    assert 1 <= len(before) < 4
    assert resumed.exit_code == 0, resumed.output
    assert f"{4 - len(before)} jobs run" in resumed.output
    assert f"{len(before)} already recorded" in resumed.output
    records = read_records(out)
    ids = [r["id"] for r in records]
    assert sorted(ids) == sorted(j.id for j in load_jobs(SLOW_SMOKE).jobs)  # each job once
    assert all(r["status"] == "success" for r in records)
    for r in records:
        assert (out / r["log"]).stat().st_size > 0
        assert json.loads((out / r["plan"]).read_text())["seed"] == r["seed"]


def test_a_finished_batch_folder_is_not_overwritten_without_resume(smoke_batch):
    out = smoke_batch[0]
    result = run("batch", str(SLOW_SMOKE), "--out", str(out))
    assert result.exit_code == 2 and "already holds 4 job records" in result.stderr


def test_report_prints_the_table_and_writes_a_png(smoke_batch, tmp_path):
    out = smoke_batch[0]
    png = tmp_path / "r.png"
    result = run("report", str(out), "--png", str(png))
    assert result.exit_code == 0, result.output
    rows = [line for line in result.output.splitlines() if line.startswith("hex-peg")]
    assert len(rows) == 2 and all("2/2" in row and "±" in row for row in rows)
    assert png.read_bytes()[:4] == b"\x89PNG"
    missing = run("report", str(tmp_path / "nothing"))
    assert missing.exit_code == 2 and "no records.jsonl" in missing.stderr
    nested = tmp_path / "new" / "folder" / "r.png"  # its folders are made
    assert run("report", str(out), "--png", str(nested)).exit_code == 0 and nested.exists()
    (tmp_path / "file").write_text("")
    blocked = run("report", str(out), "--png", str(tmp_path / "file" / "r.png"))
    assert blocked.exit_code == 2 and "cannot write the figure" in blocked.stderr


def test_a_job_that_runs_out_of_time_is_recorded_as_a_timeout(tmp_path):
    jobs = tmp_path / "jobs.yaml"
    jobs.write_text(
        "name: t\ntasks: [peg-in-hole]\nuncertainty: {x: [grasp.x=1cm]}\ntimeout_s: 1\n"
    )
    out = tmp_path / "out"
    counts = run_batch(load_jobs(jobs), out, workers=1)
    (record,) = read_records(out)
    assert counts.failed == 1 and record["status"] == "timeout"
    assert record["reason"].startswith("timeout") and (out / record["plan"]).exists()
    table = run("report", str(out))
    assert table.exit_code == 0 and " * " in table.output.splitlines()[1] + " "


def test_a_node_lost_mid_batch_still_records_every_job_once_with_the_same_plans(
    smoke_batch, tmp_path
):
    from ray.cluster_utils import Cluster

    reference = {r["id"]: motions(smoke_batch[0], r) for r in read_records(smoke_batch[0])}
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0})
    nodes = [cluster.add_node(num_cpus=1) for _ in range(2)]
    cluster.wait_for_nodes()
    out = tmp_path / "lost-node-batch"
    lost = threading.Event()

    def remove_a_node_once_the_first_job_is_in():
        wait_for_records(out, 1)
        time.sleep(1.0)  # the next two jobs are running, one of them on nodes[0]
        cluster.remove_node(nodes[0])
        lost.set()

    killer = threading.Thread(target=remove_a_node_once_the_first_job_is_in, daemon=True)
    killer.start()
    try:
        run_batch(load_jobs(SLOW_SMOKE), out, address=cluster.address)
    finally:
        cluster.shutdown()
    killer.join(5)
    assert lost.is_set()
    records = read_records(out)
    assert sorted(r["id"] for r in records) == sorted(reference)
    for r in records:
        assert r["status"] == "success" and motions(out, r) == reference[r["id"]]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_a_batch_submitted_with_ray_job_submit_completes(tmp_path):
    """`ray start --head`, then `ray job submit -- bilba batch …` (docs/reference-values.md:
    Ray 2.60 needs RAY_AUTH_MODE=token on the submitting side). `ray stop` at the end stops
    every Ray process of this user, so this test must not share the machine with another Ray."""
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ['PATH']}"}
    port, dashboard = _free_port(), _free_port()
    head = subprocess.run(
        [BIN / "ray", "start", "--head", "--num-cpus=2", f"--port={port}",
         "--dashboard-host=127.0.0.1", f"--dashboard-port={dashboard}",
         "--include-dashboard=true", "--disable-usage-stats"],
        env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    # (it failed once in CI, exit 1, its output unseen: say why next time)
    assert head.returncode == 0, head.stdout[-2000:] + head.stderr[-2000:]
    out = tmp_path / "out"
    try:
        submitted = subprocess.run(
            [BIN / "ray", "job", "submit", f"--address=http://127.0.0.1:{dashboard}", "--",
             "bilba", "batch", str(SMOKE), "--address", "auto", "--out", str(out)],
            env={**env, "RAY_AUTH_MODE": "token"}, capture_output=True, text=True, timeout=400,
        )  # fmt: skip
    finally:
        subprocess.run([BIN / "ray", "stop"], env=env, capture_output=True, timeout=120)
    assert submitted.returncode == 0, submitted.stdout[-2000:] + submitted.stderr[-2000:]
    assert "4 jobs run in" in submitted.stdout and "(0 without a plan)" in submitted.stdout
    assert len(read_records(out)) == 4


def test_a_jobs_file_preset_applies_to_every_job(tmp_path):
    jobs = tmp_path / "jobs.yaml"
    jobs.write_text(
        "name: p\ntasks: [peg-in-hole, hex-peg]\nuncertainty: {pitch: [grasp.pitch=1deg]}\n"
        "planners: [bilba-fixed]\npreset: paper\n"
    )
    batch = load_jobs(jobs)
    assert len(batch.jobs) == 2
    for job in batch.jobs:
        planner = batch.spec(job).planner
        assert (planner.preset, planner.race_contacts, planner.n_attempts) == ("paper", 0, 50)
    jobs.write_text(jobs.read_text().replace("preset: paper", "preset: fastest"))
    result = run("batch", str(jobs), "--out", str(tmp_path / "out"))
    assert result.exit_code == 2 and "preset" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_job_that_raised_is_recorded_with_its_own_exception_and_traceback():
    """A job's exception reaches the driver wrapped in Ray's RayTaskError, whose text opens
    with colour codes and the worker's pid: the record names the job's own exception and
    keeps the traceback's last lines, without colour codes."""
    import ray

    from bilba_dist.schedulers.batch import TRACEBACK_LINES, error_result

    trace = "\x1b[36mray::execute_job()\x1b[39m (pid=1, ip=192.0.2.2)\n" + "\n".join(
        f'  File "evaluate.py", line {k}, in score' for k in range(20)
    )
    wrapped = ray.exceptions.RayTaskError("execute_job", trace, IndexError("tuple index"))
    # ray.get raises it as an IndexError too (one without traceback_str): the same record
    for raised in (wrapped, wrapped.as_instanceof_cause()):
        record = error_result(raised)
        assert record["status"] == "error" and record["reason"] == "IndexError: tuple index"
        assert record["traceback"][-1] == '  File "evaluate.py", line 19, in score'
        assert len(record["traceback"]) == TRACEBACK_LINES
        assert not any("\x1b" in line for line in record["traceback"])
    long = ray.exceptions.RayTaskError("execute_job", trace, ValueError("first\nsecond"))
    assert error_result(long)["reason"] == "ValueError: first"
    lost = error_result(ray.exceptions.RayError("the node died\nmore"))
    assert lost == {"status": "error", "reason": "RayError: the node died"}


def test_a_batch_whose_ray_dies_stops_in_one_line_and_records_no_job_it_did_not_run(tmp_path):
    """`ray stop` or the OOM killer takes the local raylet: the jobs left are not errors of
    theirs, so none is recorded and --resume runs them."""
    out = tmp_path / "out"
    driver = batch_with_one_record(out)
    (raylet,) = raylets_of(driver.pid)
    raylet.kill()
    _, err = driver.communicate(timeout=120)
    records = read_records(out)
    assert driver.returncode == 2 and "Traceback" not in err
    (line,) = (x for x in err.splitlines() if x.startswith("bilba: error:"))
    assert f"raylet died after {len(records)} of 4 jobs" in line and "--resume" in line
    assert records and all(r["status"] == "success" for r in records)
    resumed = run("batch", str(SLOW_SMOKE), "--out", str(out), "--resume")
    assert resumed.exit_code == 0 and f"{4 - len(records)} jobs run" in resumed.output
    assert len(read_records(out)) == 4
