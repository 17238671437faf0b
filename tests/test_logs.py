"""MCAP logs of real plans: readable with CRCs, schema-valid, the same plan, crash-safe."""

import hashlib
import io
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import jsonschema
import numpy as np
import pinocchio as pin
import pytest
from click.testing import CliRunner
from mcap.data_stream import ReadDataStream
from mcap.reader import NonSeekingReader, SeekingReader, make_reader
from mcap.records import Chunk, Message, MessageIndex
from mcap.stream_reader import breakup_chunk

import bilba_dist.record
from bilba_dist.cli.main import cli, register
from bilba_dist.record.foxglove import PRIMITIVES
from bilba_dist.record.reader import MAGIC, read_log
from bilba_dist.robot.panda import PandaModel
from tests.conftest import planner_in_progress

BIN = Path(sys.executable).parent


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


def indexed_messages(path) -> dict[str, int]:
    """Messages per topic as an indexed reader finds them: through the summary's chunk indexes
    and each chunk's message indexes only (an unchunked file has none: no messages)."""
    counts: dict[str, int] = {}
    with path.open("rb") as f:
        summary = SeekingReader(f).get_summary()
        assert summary is not None
        for chunk in summary.chunk_indexes:
            for channel_id, offset in chunk.message_index_offsets.items():
                f.seek(offset + 1 + 8)  # past the record's opcode and length
                index = MessageIndex.read(ReadDataStream(f))
                topic = summary.channels[channel_id].topic
                counts[topic] = counts.get(topic, 0) + len(index.records)
    return counts


def test_an_indexed_reader_finds_every_message(planned):
    _, log = planned
    streamed: dict[str, int] = {}
    with log.open("rb") as f:
        for _, channel, _ in NonSeekingReader(f, validate_crcs=True).iter_messages():
            streamed[channel.topic] = streamed.get(channel.topic, 0) + 1
    assert indexed_messages(log) == streamed
    assert sum(streamed.values()) > 50


#: A planner whose log hook reports each transition once it has returned: every transition
#: reported before the kill must survive it.
KILLED_PLANNER = """
import sys
from pathlib import Path
from pathlib import Path
from bilba_dist.planning.bilba import plan
from bilba_dist.record.writer import LogWriter
from bilba_dist.task.loader import load_task
from bilba_dist.workers.rollout_worker import RolloutWorker

class Reporting(LogWriter):
    def transition(self, *args, **kwargs):
        super().transition(*args, **kwargs)
        print(self.transitions, flush=True)

task = load_task("peg-in-hole", ["grasp.x=1cm"])
plan(task, RolloutWorker(task), seed=0, recorder=Reporting(Path(sys.argv[1]), task, "v", 0))
"""


def test_killed_planner_loses_at_most_the_transition_in_progress(tmp_path):
    log = tmp_path / "killed.mcap"
    proc = subprocess.Popen(
        [sys.executable, "-c", KILLED_PLANNER, str(log)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    assert proc.stdout is not None
    reported = 0
    for line in proc.stdout:
        reported = int(line)
        if reported >= 6:
            break
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert reported >= 6, "the planner ended before six transitions"
    assert run("logs", "summary", str(log)).exit_code == 2  # truncated: no summary section
    fixed = tmp_path / "fixed.mcap"
    result = run("logs", "recover", str(log), "--out", str(fixed))
    assert result.exit_code == 0, result.output
    recovered = read_log(fixed)
    transitions = recovered.json("/transition")
    assert len(transitions) >= reported
    assert [t["index"] for t in transitions] == list(range(len(transitions)))
    assert indexed_messages(fixed)["/transition"] == len(transitions)


def test_ctrl_c_on_bilba_plan_is_one_line_and_leaves_a_readable_log(tmp_path):
    """Exit 130 as for a batch; the log is ended with every transition so far, so every
    reader takes it as it is (no `logs recover`), its outcome "unfinished"."""
    planner, log = planner_in_progress(tmp_path, workers=0)
    planner.send_signal(signal.SIGINT)
    _, err = planner.communicate(timeout=60)
    assert planner.returncode == 130 and "Traceback" not in err
    assert err.strip().splitlines()[-1] == f"interrupted; no plan; the log so far: {log}"
    assert read_log(log).json("/transition") and not (tmp_path / "p.json").exists()
    summary = run("logs", "summary", str(log))
    assert summary.exit_code == 0 and "unfinished" in summary.output


def record_starts(data: bytes, opcode: int) -> list[int]:
    """Where each top-level record of ``opcode`` starts, up to the footer (MCAP records: an
    opcode, a u64 length, the content)."""
    at, starts = len(MAGIC), []
    while data[at] != 0x02:  # the footer
        if data[at] == opcode:
            starts.append(at)
        at += 9 + int.from_bytes(data[at + 1 : at + 9], "little")
    return starts


def record_at(data: bytes, opcode: int) -> int:
    """Where the first record of ``opcode`` starts."""
    return record_starts(data, opcode)[0]


def with_huge_chunk_length(data: bytes) -> bytes:
    """``data`` with its first chunk claiming 2**62 bytes of records."""
    content = record_at(data, 0x06) + 9 + 3 * 8 + 4  # times, uncompressed size and CRC
    field = content + 4 + int.from_bytes(data[content : content + 4], "little")
    return data[:field] + (2**62).to_bytes(8, "little") + data[field + 8 :]


def with_long_index_map(data: bytes) -> bytes:
    """``data`` with its first chunk index's map of message index offsets claiming 1 MiB
    (a u32 byte length after four u64 fields), past the end of the file."""
    field = record_at(data, 0x08) + 9 + 4 * 8
    return data[:field] + (2**20).to_bytes(4, "little") + data[field + 4 :]


@pytest.mark.parametrize("damage", ["a byte of its messages", "its length", "its start"])
def test_recover_keeps_what_follows_a_damaged_chunk(damage, planned, tmp_path):
    """The writer ends a chunk at each transition: damaging one chunk loses its own messages,
    not the later ones — reading goes on after it (by its length, or, where the length is
    what broke, at the next chunk that reads with its checksum)."""
    data = planned[1].read_bytes()
    starts = record_starts(data, 0x06)
    middle = starts[len(starts) // 2]
    end = middle + 9 + int.from_bytes(data[middle + 1 : middle + 9], "little")
    chunk = Chunk.read(ReadDataStream(io.BytesIO(data[middle + 9 : end])))
    in_chunk = [r for r in breakup_chunk(chunk, validate_crc=True) if isinstance(r, Message)]
    bad = bytearray(data)
    if damage == "a byte of its messages":
        bad[end - 10] ^= 0xFF
    elif damage == "its length":
        bad[middle + 5] ^= 0x40  # 2**38 more: past the end of the file
    else:
        bad = bad[:middle] + bad[middle + 20 :]  # its first 20 bytes gone: lengths shifted
    (tmp_path / "bad.mcap").write_bytes(bytes(bad))
    result = run("logs", "recover", str(tmp_path / "bad.mcap"), "--out", str(tmp_path / "r.mcap"))
    assert result.exit_code == 0, result.output
    original, kept = read_log(planned[1]).records, read_log(tmp_path / "r.mcap").records
    lost = {(m.log_time, m.data) for m in in_chunk}
    assert in_chunk and kept == [r for r in original if (r[1], r[2]) not in lost]
    assert kept[-1] == original[-1] and len(starts) > 8  # later chunks were kept
    gone = [
        json.loads(d)["index"]
        for topic, t, d in original
        if topic == "/transition" and (t, d) in lost
    ]
    assert len(gone) == 1  # the writer ends a chunk at each transition
    said = f"transitions missing (lost with a damaged chunk): {', '.join(map(str, gone))}"
    assert (said in result.output) == bool(gone)
    assert (said in run("logs", "summary", str(tmp_path / "r.mcap")).output) == bool(gone)


def test_recover_refuses_a_log_whose_header_is_damaged(planned, tmp_path):
    """The first chunk holds the topics and /metadata: without it there is no log to write."""
    bad = bytearray(planned[1].read_bytes())
    first = record_at(bytes(bad), 0x06)
    bad[first + 9 + 300] ^= 0xFF
    (tmp_path / "bad.mcap").write_bytes(bytes(bad))
    result = run("logs", "recover", str(tmp_path / "bad.mcap"), "--out", str(tmp_path / "r.mcap"))
    assert result.exit_code == 2 and "header is damaged" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not (tmp_path / "r.mcap").exists()


@pytest.mark.parametrize(
    "case", ["missing", "empty", "text", "truncated", "huge length", "long index map"]
)
def test_bad_log_files_are_one_line_and_exit_2(case, planned, tmp_path):
    path = tmp_path / "bad.mcap"
    if case == "empty":
        path.write_bytes(b"")
    elif case == "text":
        path.write_text("hello")
    elif case == "truncated":
        data = planned[1].read_bytes()
        path.write_bytes(data[: len(data) // 2])
    elif case == "huge length":  # was a MemoryError: the reader asked for 4 EiB at once
        path.write_bytes(with_huge_chunk_length(planned[1].read_bytes()))
    elif case == "long index map":  # was struct.error
        path.write_bytes(with_long_index_map(planned[1].read_bytes()))
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
        assert result.stdout == "", (command, result.stdout)  # no table header before it
    if case != "missing":
        recovered = run("logs", "recover", str(path), "--out", str(tmp_path / "r.mcap"))
        if case in ("truncated", "huge length", "long index map"):  # the messages intact
            assert recovered.exit_code == 0 and "messages recovered" in recovered.output
            assert read_log(tmp_path / "r.mcap").json("/transition")
        else:  # nothing readable to rewrite
            assert recovered.exit_code == 2 and "bilba: error:" in recovered.stderr
            assert not (tmp_path / "r.mcap").exists()


def official_schema(name: str) -> dict:
    folder = Path(bilba_dist.record.__file__).parent / "foxglove_schemas"
    return json.loads((folder / f"{name}.json").read_text())


def test_the_shipped_foxglove_schemas_are_the_current_official_ones():
    """Unchanged from @foxglove/schemas 2.1.0 (hashes in the folder's README); that version
    requires every primitive list of a SceneEntity, the check our old subset missed."""
    folder = Path(bilba_dist.record.__file__).parent / "foxglove_schemas"
    readme = (folder / "README.md").read_text()
    for name in ("SceneUpdate", "FrameTransform"):
        digest = hashlib.sha256((folder / f"{name}.json").read_bytes()).hexdigest()
        assert f"{digest}  {name}.json" in readme
    entity = official_schema("SceneUpdate")["properties"]["entities"]["items"]
    assert set(PRIMITIVES) <= set(entity["required"])


def test_every_scene_and_tf_message_is_valid_under_the_official_foxglove_schemas(planned):
    _, log_path = planned
    validators = {
        "/scene": jsonschema.Draft7Validator(official_schema("SceneUpdate")),
        "/tf": jsonschema.Draft7Validator(official_schema("FrameTransform")),
    }
    log = read_log(log_path)
    checked = 0
    for topic, validator in validators.items():
        for message in log.json(topic):
            errors = [e.message for e in validator.iter_errors(message)]
            assert errors == [], (topic, errors[:3])
            checked += 1
    assert checked > 100


def test_foxglove_scene_draws_parts_and_arm_of_every_particle_and_follows_the_plan(planned):
    _, log_path = planned
    schemas = {}
    with log_path.open("rb") as f:
        for schema, channel, _ in make_reader(f).iter_messages(topics=["/scene", "/tf"]):
            schemas[channel.topic] = schema.name
    assert schemas == {"/scene": "foxglove.SceneUpdate", "/tf": "foxglove.FrameTransform"}
    log = read_log(log_path)
    scene = log.json("/scene")[0]
    bodies = ["link0", "link1", "link2", "link3", "link4", "link5", "link6", "link7", "hand",
              "leftfinger", "rightfinger"]  # fmt: skip
    assert sorted(e["id"] for e in scene["entities"]) == sorted(
        [f"{kind}_{i}" for kind in ("env", "part") for i in range(3)]
        + [f"panda_{i}/{body}" for body in bodies for i in range(3)]
    )
    for entity in scene["entities"]:
        (mesh,) = entity["triangles"]
        assert entity["frame_id"] == entity["id"] and entity["frame_locked"]
        assert len(mesh["indices"]) % 3 == 0 and max(mesh["indices"]) < len(mesh["points"])
    # The last transforms of each particle's frames are that particle after the last motion:
    # the part at its pose, the hand where the arm's joint angles put it.
    last = {tf["child_frame_id"]: tf for tf in log.json("/tf")}
    final = [t for t in log.json("/transition") if t["accepted"]][-1]["after"]
    panda = PandaModel()
    for i, particle in enumerate(final):
        tf = last[f"part_{i}"]
        assert [tf["translation"][k] for k in "xyz"] == particle["X_WM"]["xyz"]
        assert [tf["rotation"][k] for k in "xyzw"] == pytest.approx(particle["X_WM"]["quat_xyzw"])
        hand = last[f"panda_{i}/hand"]
        X_WG = panda.fk(np.array(particle["q"]))
        assert [hand["translation"][k] for k in "xyz"] == pytest.approx(X_WG.translation, abs=1e-9)
        quat = pin.Quaternion(X_WG.rotation)
        assert [hand["rotation"][k] for k in "xyzw"] == pytest.approx(
            [quat.x, quat.y, quat.z, quat.w], abs=1e-9
        ) or [hand["rotation"][k] for k in "xyzw"] == pytest.approx(
            [-quat.x, -quat.y, -quat.z, -quat.w], abs=1e-9
        )
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
    far = run("logs", "show", str(log), "--step", "-" + "9" * 400)
    assert (
        far.exit_code == 2 and "no step -99999" in far.stderr and "(401 characters)" in far.stderr
    )


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


def test_output_cut_short_by_a_closed_pipe_ends_quietly(planned):
    """`bilba logs export … | head -c 100`: the reader goes away; no traceback, no
    'internal error', exit 0."""
    _, log = planned
    proc = subprocess.Popen(
        [sys.executable, "-c", "from bilba_dist.cli.main import main; main()",
         "logs", "export", str(log), "--format", "ndjson"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )  # fmt: skip
    assert proc.stdout is not None and proc.stderr is not None
    assert len(proc.stdout.read(100)) == 100
    proc.stdout.close()
    assert proc.wait(timeout=60) == 0
    assert proc.stderr.read() == b""


def test_a_particle_stopped_at_a_joint_limit_is_logged_and_shown(tmp_path):
    """Our sideways insertion at grasp.x ±1 cm: some candidate motions carry joint 5 to its
    limit (a Franka's reflex). Those transitions log the particle's reason, `logs show`
    prints it, and no accepted motion has one."""
    import yaml

    from bilba_dist.record.schemas import TOPICS
    from tests.test_planner import _sideways

    task = tmp_path / "sideways.yaml"
    task.write_text(yaml.safe_dump(_sideways([0.55, 0, 0.45])))
    log = tmp_path / "sideways.mcap"
    args = ["plan", str(task), "-u", "grasp.x=1cm", "--workers", "0", "--log", str(log)]
    result = run(*args, "--out", str(tmp_path / "plan.json"))
    assert result.exit_code == 0, result.output
    transitions = read_log(log).json("/transition")
    stopped = [t for t in transitions if any("stopped" in p for p in t["after"])]
    assert stopped and not any(t["accepted"] for t in stopped)
    for t in stopped:
        jsonschema.validate(t, TOPICS["/transition"])
        assert t["count"] == 0  # a motion that stops a particle brings none in
    shown = run("logs", "show", str(log), "--step", str(stopped[0]["index"]))
    assert shown.exit_code == 0, shown.output
    assert "stopped: joint 5 reached its lower limit (-2.8973 rad)" in shown.output
