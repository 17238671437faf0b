"""MCAP logs of real plans: readable with CRCs, schema-valid, the same plan, crash-safe."""

import json
import os
import signal
import subprocess
import sys
import time

import jsonschema
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from bilba_dist.cli.main import cli, register
from bilba_dist.record.reader import read_log


def run(*args: str):
    register()
    return CliRunner().invoke(cli, list(args))


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plan")
    plan, log = folder / "plan.json", folder / "log.mcap"
    result = run(
        "plan",
        "peg-in-hole",
        "--workers",
        "0",
        "--seed",
        "1",
        "--out",
        str(plan),
        "--log",
        str(log),
    )
    assert result.exit_code == 0, result.output
    return plan, log


def test_log_reads_back_with_crc_checks_and_every_message_fits_its_schema(planned):
    _, log = planned
    counts: dict[str, int] = {}
    with log.open("rb") as f:
        for schema, channel, message in make_reader(f, validate_crcs=True).iter_messages():
            assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
            jsonschema.validate(json.loads(message.data), json.loads(schema.data))
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert counts["/metadata"] == 1 and counts["/plan"] == 1 and counts["/outcome"] == 1
    assert counts["/schedule"] >= 1 and counts["/transition"] >= 1


def test_accepted_transitions_are_the_plan(planned):
    plan, log = planned
    motions = json.loads(plan.read_text())["motions"]
    accepted = [t for t in read_log(log).json("/transition") if t["accepted"]]
    assert [t["motion"]["G_d"] for t in accepted] == [m["G_d"] for m in motions]
    assert all(len(t["before"]) == len(t["after"]) == 3 for t in accepted)


def test_logs_plan_is_the_plan_file_byte_for_byte(planned, tmp_path):
    plan, log = planned
    out = tmp_path / "from_log.json"
    assert run("logs", "plan", str(log), "--out", str(out)).exit_code == 0
    assert out.read_bytes() == plan.read_bytes()


def test_summary_names_task_planner_and_outcome(planned):
    _, log = planned
    result = run("logs", "summary", str(log))
    assert result.exit_code == 0
    assert "peg-in-hole" in result.output and "bilba-variable" in result.output
    assert "plan found" in result.output and "schedule 0: free ->" in result.output


def test_killed_planner_leaves_a_readable_log_and_recover_makes_it_whole(tmp_path):
    log = tmp_path / "killed.mcap"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "from bilba_dist.cli.main import main; main()",
            "plan",
            "peg-in-hole",
            "-u",
            "grasp.x=1cm",
            "--workers",
            "0",
            "--log",
            str(log),
            "--out",
            str(tmp_path / "p.json"),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.time() + 120
    while time.time() < deadline and (not log.exists() or log.stat().st_size < 80_000):
        time.sleep(0.2)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert run("logs", "summary", str(log)).exit_code == 2  # truncated: no summary section
    fixed = tmp_path / "fixed.mcap"
    result = run("logs", "recover", str(log), "--out", str(fixed))
    assert result.exit_code == 0, result.output
    recovered = read_log(fixed)
    transitions = recovered.json("/transition")
    assert len(transitions) >= 3
    assert [t["index"] for t in transitions] == list(range(len(transitions)))


@pytest.mark.parametrize("case", ["missing", "empty", "text", "truncated"])
def test_bad_log_files_are_one_line_and_exit_2(case, planned, tmp_path):
    path = tmp_path / "bad.mcap"
    if case == "empty":
        path.write_bytes(b"")
    elif case == "text":
        path.write_text("hello")
    elif case == "truncated":
        data = planned[1].read_bytes()
        path.write_bytes(data[: len(data) // 2])
    for command in (
        ["logs", "summary"],
        ["logs", "plan"],
        ["logs", "show"],
        ["logs", "plot"],
        ["logs", "export"],
    ):
        result = run(*command, str(path))
        assert result.exit_code == 2, (case, result.output)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in result.stderr


def test_foxglove_scene_draws_every_particle_and_its_frames_follow_the_plan(planned):
    _, log_path = planned
    schemas = {}
    with log_path.open("rb") as f:
        for schema, channel, _ in make_reader(f).iter_messages(topics=["/scene", "/tf"]):
            schemas[channel.topic] = schema.name
    assert schemas == {"/scene": "foxglove.SceneUpdate", "/tf": "foxglove.FrameTransform"}
    log = read_log(log_path)
    scene = log.json("/scene")[0]
    assert sorted(e["id"] for e in scene["entities"]) == [
        "env/0", "env/1", "env/2", "part/0", "part/1", "part/2",
    ]  # fmt: skip
    for entity in scene["entities"]:
        (mesh,) = entity["triangles"]
        assert entity["frame_id"] == entity["id"].replace("/", "_") and entity["frame_locked"]
        assert len(mesh["indices"]) % 3 == 0 and max(mesh["indices"]) < len(mesh["points"])
    # The last transform of each manipuland frame is that particle after the last motion.
    last = {tf["child_frame_id"]: tf for tf in log.json("/tf")}
    final = [t for t in log.json("/transition") if t["accepted"]][-1]["after"]
    for i, particle in enumerate(final):
        tf = last[f"part_{i}"]
        assert [tf["translation"][k] for k in "xyz"] == particle["X_WM"]["xyz"]
        assert [tf["rotation"][k] for k in "xyzw"] == pytest.approx(particle["X_WM"]["quat_xyzw"])
    assert all(tf["parent_frame_id"] == "world" for tf in last.values())


def test_logs_show_prints_one_transition_and_rejects_a_missing_step(planned):
    _, log = planned
    transitions = read_log(log).json("/transition")
    result = run("logs", "show", str(log), "--step", "-1")
    assert result.exit_code == 0, result.output
    assert f"step {len(transitions) - 1} of {len(transitions)}: ACCEPTED" in result.output
    assert result.output.count("(floor/+z, peg/-z)") >= 4  # sought, and all 3 particles
    missing = run("logs", "show", str(log), "--step", str(len(transitions)))
    assert missing.exit_code == 2 and f"0..{len(transitions) - 1}" in missing.stderr


def test_logs_plot_writes_a_png(planned, tmp_path):
    _, log = planned
    out = tmp_path / "fig.png"
    result = run("logs", "plot", str(log), "--out", str(out))
    assert result.exit_code == 0, result.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000


def test_logs_export_ndjson_holds_every_message_and_csv_every_particle(planned, tmp_path):
    import csv

    _, log_path = planned
    log = read_log(log_path)
    ndjson = run("logs", "export", str(log_path), "--format", "ndjson")
    assert ndjson.exit_code == 0
    lines = [json.loads(line) for line in ndjson.output.splitlines()]
    assert len(lines) == sum(len(v) for v in log.messages.values())
    assert [m["message"] for m in lines if m["topic"] == "/outcome"] == log.json("/outcome")
    out = tmp_path / "t.csv"
    assert run("logs", "export", str(log_path), "--format", "csv", "--out", str(out)).exit_code == 0
    rows = list(csv.DictReader(out.open()))
    transitions = log.json("/transition")
    assert len(rows) == 3 * len(transitions)
    last = rows[-1]
    assert float(last["z_after"]) == transitions[-1]["after"][2]["X_WM"]["xyz"][2]
    assert "floor/+z|peg/-z" in last["contacts_after"].split(";")
