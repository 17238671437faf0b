"""Hostile and careless input: every bad task, plan or jobs file is one line on stderr and
exit code 2, within 5 s, and nothing partial is written (no plan file, no log, no batch)."""

import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bilba_dist.errors import BilbaError
from bilba_dist.task.loader import builtin_tasks
from tests.test_task_files import run_cli

PEG = builtin_tasks()["peg-in-hole"].read_text()
BOMB = "".join(
    f"{b}: &{b} [{', '.join([f'*{a}'] * 9)}]\n" for a, b in zip("abcdefgh", "bcdefghi", strict=True)
)


def edited(old: str, new: str) -> str:
    assert old in PEG, old
    return PEG.replace(old, new, 1)


#: case -> (task file text or bytes, a fragment the one line must hold)
TASKS: dict[str, tuple[str | bytes, str]] = {
    "NaN box size": (edited("size: [0.06, 0.06, 0.15]", "size: [.nan, 0.06, 0.15]"), "size"),
    "NaN grasp": (
        edited("grasp: {xyz: [0, 0, 0.155]", "grasp: {xyz: [0, .nan, 0.155]"),
        "grasp.xyz",
    ),
    "infinite env pose": (
        edited("environment_pose: {xyz: [0.5, 0, 0]}", "environment_pose: {xyz: [.inf, 0, 0]}"),
        "environment_pose.xyz",
    ),
    "a 401-digit integer length": (
        edited(
            "environment_pose: {xyz: [0.5, 0, 0]}",
            f"environment_pose: {{xyz: [1{'0' * 400}, 0, 0]}}",
        ),
        "environment_pose.xyz[0]: expected a length, got an integer of 401 digits",
    ),
    "a 401-digit integer bound": (
        edited("grasp.pitch: 2deg", f"grasp.pitch: -1{'0' * 400}"),
        "grasp.pitch: expected an angle, got an integer of 402 digits",
    ),
    "infinite bound": (edited("grasp.pitch: 2deg", "grasp.pitch: .inf"), "finite"),
    "NaN bound": (edited("grasp.pitch: 2deg", "grasp.pitch: .nan"), "finite"),
    "infinite friction": (edited("friction: 0.45", "friction: .inf"), "friction"),
    "friction 50": (edited("friction: 0.45", "friction: 50"), "friction"),
    "time step 1e6": (
        edited("# No planner section", "planner:\n  sim_timestep_s: 1e6\n# No planner section"),
        "sim_timestep_s",
    ),
    "duplicate friction": (
        edited("friction: 0.45", "friction: 0.45\nfriction: 0.9"),
        "duplicate key 'friction'",
    ),
    "duplicate goal": (
        edited(
            "goal: {env: floor/+z", "goal: {env: wall_px/top, manip: peg/-z}\ngoal: {env: floor/+z"
        ),
        "duplicate key 'goal'",
    ),
    "alias bomb": (
        PEG
        + "extra:\n  a: &a [1, 2, 3, 4, 5, 6, 7, 8, 9]\n"
        + "".join("  " + line + "\n" for line in BOMB.splitlines()),
        "aliases expand",
    ),
    "Latin-1": (PEG.replace("Square peg", "Carré peg").encode("latin-1"), "not UTF-8"),
    "UTF-16": (PEG.encode("utf-16"), "UTF-16"),
    "deep nesting": (PEG + "extra: " + "[" * 5000 + "]" * 5000 + "\n", "nested deeper"),
    "100001 points": (edited("generator: axis ", "points: 100001\n  generator: axis "), "points"),
    "unknown generator": (
        edited("generator: axis ", "generator: gaussian "),
        "belief: write a mapping whose generator is axis (the default), extremal+random or",
    ),
    "1 km bound": (edited("grasp.pitch: 2deg", "grasp.x: 1000m"), "outside"),
    "720 degree bound": (edited("grasp.pitch: 2deg", "grasp.pitch: 720deg"), "outside"),
    "1e308 m bound": (edited("grasp.pitch: 2deg", "grasp.x: 1e308m"), "far outside ±10 cm"),
    "start inside": (
        edited("gripper: {xyz: [0.5, 0, 0.36]", "gripper: {xyz: [0.55, 0, 0.30]"),
        "inside the environment",
    ),
    "mass 1 t": (edited("name: peg\n  pieces:", "name: peg\n  mass: 1000\n  pieces:"), "mass"),
    "huge file": (PEG + "#" * (3 * 2**20) + "\n", "byte limit"),
    "5000-digit friction": (
        edited("friction: 0.45", "friction: " + "9" * 5000),
        "not valid YAML: Exceeds the limit (4300 digits)",
    ),
    "a tag its value does not fit": (
        edited("friction: 0.45", "friction: !!timestamp 0.45"),
        "not valid YAML: '0.45' is not a timestamp",
    ),
    "a list as a key": (
        edited("friction: 0.45", "friction: 0.45\n[1, 2]: 3"),
        "a key must be a name, not a list",
    ),
    "preset a list": (
        edited("# No planner section", "planner: {preset: [paper]}\n# No planner section"),
        "planner.preset",
    ),
    "angle in words": (
        edited("rpy: [180deg, 0, 0]}       # X_GM", "rpy: [half, 0, 0]}       # X_GM"),
        "cannot read 'half' as an angle",
    ),
}


def assert_one_line_exit_2(result, fragment: str, elapsed: float, limit: float = 5.0) -> None:
    assert result.exit_code == 2, (result.exit_code, result.output)
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("bilba: error: ") and fragment in lines[0], lines[0]
    assert "Traceback" not in result.output
    assert elapsed < limit, elapsed


@pytest.mark.parametrize("case", TASKS)
def test_a_hostile_task_file_is_one_line_and_writes_nothing(case, tmp_path):
    text, fragment = TASKS[case]
    path = tmp_path / "task.yaml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    plan, log = tmp_path / "plan.json", tmp_path / "log.mcap"
    start = time.perf_counter()
    result = run_cli("plan", str(path), "--workers", "0", "--out", str(plan), "--log", str(log))
    assert_one_line_exit_2(result, fragment, time.perf_counter() - start)
    assert not plan.exists() and not log.exists()


def test_a_start_inside_the_environment_may_be_allowed(tmp_path):
    path = tmp_path / "task.yaml"
    path.write_text(TASKS["start inside"][0])  # type: ignore[arg-type]
    result = run_cli("graph", str(path))  # graph plans nothing: the start is not checked
    assert result.exit_code == 0
    from bilba_dist.belief.particles import initial_belief
    from bilba_dist.belief.start import check_start_free
    from bilba_dist.task.loader import load_task

    check_start_free(load_task("peg-in-hole"), initial_belief(load_task("peg-in-hole")))
    plan = tmp_path / "p.json"
    run = run_cli(
        "plan",
        str(path),
        "--workers",
        "0",
        "--no-log",
        "--out",
        str(plan),
        "--timeout",
        "0.5",
        "--allow-start-contact",
    )
    assert run.exit_code in (0, 1) and plan.exists(), run.output


@pytest.mark.parametrize("option", ["grasp.x=nan", "grasp.x=1e999m", "grasp.pitch=400deg"])
def test_a_hostile_uncertainty_option_is_one_line(option, tmp_path):
    start = time.perf_counter()
    result = run_cli(
        "plan",
        "peg-in-hole",
        "-u",
        option,
        "--workers",
        "0",
        "--out",
        str(tmp_path / "p.json"),
        "--no-log",
    )
    assert_one_line_exit_2(result, "--uncertainty", time.perf_counter() - start)
    assert not (tmp_path / "p.json").exists()


BIG = "1" + "0" * 400  # past a float's range: math.isfinite(int(BIG)) overflows


@pytest.mark.parametrize(
    "args",
    [
        ["--timeout", "nan"],
        ["--timeout", "-1"],
        ["--seed", "-1"],
        ["--seed", BIG],
        ["--timeout", BIG],
        ["--workers", BIG],
    ],
)
def test_hostile_numbers_on_the_command_line_are_refused(args, tmp_path):
    result = run_cli("plan", "peg-in-hole", *args, "--out", str(tmp_path / "p.json"))
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    assert "is not within" in result.stderr and not (tmp_path / "p.json").exists()
    assert len(result.stderr) < 300  # a 400-digit number is quoted by its length


@pytest.mark.parametrize("workers", [BIG, "-1", "2000"])
def test_a_batch_refuses_a_hostile_worker_count(workers, tmp_path):
    jobs = tmp_path / "jobs.yaml"
    jobs.write_text("name: g\ntasks: [peg-in-hole]\nseeds: 1\ntimeout_s: 1\n")
    result = run_cli("batch", str(jobs), "--workers", workers, "--out", str(tmp_path / "out"))
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    assert "'--workers'" in result.stderr and "is not within [0, 1024]" in result.stderr
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def plan_and_log(tmp_path_factory) -> Path:
    """A folder with a real plan (p.json) and its log (l.mcap) of the default task."""
    folder = tmp_path_factory.mktemp("outputs")
    result = run_cli(
        "plan", "peg-in-hole", "--workers", "0", "--out", str(folder / "p.json"),
        "--log", str(folder / "l.mcap"),
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    return folder


@pytest.fixture(scope="module")
def plan_text(plan_and_log) -> str:
    """A real plan of the default task (in-process), as its file's text."""
    return (plan_and_log / "p.json").read_text()


def plan_cases(text: str) -> dict[str, tuple[str | bytes, str]]:
    doc = json.loads(text)
    K = doc["motions"][0]["K"]
    spec, robot = doc["task"]["spec"], doc["robot"]
    return {
        "NaN in K": (text.replace(json.dumps(K[0][0]), "NaN", 1), "NaN"),
        "Infinity": (text.replace('"timeout_s": 5.0', '"timeout_s": Infinity', 1), "Infinity"),
        "duplicate key": (text.replace('"seed": 0', '"seed": 0, "seed": 1', 1), "duplicate key"),
        "deep nesting": ('{"a": ' + "[" * 100_000 + "]" * 100_000 + "}", "not a plan file"),
        "Latin-1": (text.replace('"reason": ""', '"reason": "é"').encode("latin-1"), "not UTF-8"),
        "K not symmetric": (
            json.dumps({**doc, "motions": [{**doc["motions"][0], "K": [[1] * 6, *K[1:]]}]}),
            "symmetric",
        ),
        "G_d far away": (
            text.replace('"xyz": [', '"xyz": [1e9, ', 1).replace(
                '"xyz": [1e9, ', '"xyz": [1e9, 0, 0], "was": [', 1
            ),
            "malformed",
        ),
        "future version": (text.replace('"version": 2', '"version": 99', 1), "version 99"),
        "D not 2 sqrtm(K)": (
            json.dumps({**doc, "motions": [{**doc["motions"][0], "D": K}]}),
            "motions/0/D is not 2·sqrtm(K)",
        ),
        "task edited": (
            json.dumps({**doc, "task": {**doc["task"], "spec": {**spec, "friction": 0.9}}}),
            "does not match its hash",
        ),
        "no start joints": (
            json.dumps({**doc, "robot": {k: v for k, v in robot.items() if k != "start_joints"}}),
            "'start_joints' is a required property",
        ),
        "start joints elsewhere": (
            json.dumps({**doc, "robot": {**robot, "start_joints": [0.0] * 7}}),
            "robot/start_joints put the hand",
        ),
        "start joints 1e308": (
            json.dumps({**doc, "robot": {**robot, "start_joints": [1e308] * 7}}),
            "robot/start_joints put the hand",
        ),
        "task spec invalid": (
            json.dumps({**doc, "task": {**doc["task"], "spec": {**spec, "friction": -1}}}),
            "task.spec.friction",
        ),
        "huge file": (text + " " * (17 * 2**20), "byte limit"),
        "two pieces of one name, hash recomputed": (
            rehashed(doc, twice_named(spec)),
            "part 'hole': piece names must be unique: floor",
        ),
        "300 pieces, hash recomputed": (  # the loader's cap, held by a plan file's task too
            rehashed(doc, many_pieces(spec, 300)),
            "task.spec: 300 environment pieces × 1 manipuland pieces = 300 C-obstacles, over 256",
        ),
    }


def many_pieces(spec: dict, n: int) -> dict:
    first = spec["environment"]["pieces"][0]
    pieces = [{**first, "name": f"piece{i}"} for i in range(n)]
    return {**spec, "environment": {**spec["environment"], "pieces": pieces}}


def twice_named(spec: dict) -> dict:
    pieces = spec["environment"]["pieces"]
    renamed = [pieces[0], {**pieces[1], "name": pieces[0]["name"]}, *pieces[2:]]
    return {**spec, "environment": {**spec["environment"], "pieces": renamed}}


def rehashed(doc: dict, spec: dict) -> str:
    """A plan file whose embedded task is ``spec``, with the hash of ``spec`` (an edit the
    hash does not catch)."""
    digest = hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()
    return json.dumps({**doc, "task": {**doc["task"], "spec": spec, "hash": digest}})


def test_hostile_plan_files_are_one_line(plan_text, tmp_path):
    for case, (content, fragment) in plan_cases(plan_text).items():
        path = tmp_path / f"{case}.json"
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
        start = time.perf_counter()
        result = run_cli("validate", str(path), "--workers", "0")
        try:
            assert_one_line_exit_2(result, fragment, time.perf_counter() - start)
        except AssertionError as exc:
            raise AssertionError(f"{case}: {exc}") from None


JOBS = "name: grid\ntasks: [peg-in-hole]\nseeds: 1\ntimeout_s: 30\n"
JOB_CASES: dict[str, tuple[str | bytes, str]] = {
    "NaN timeout": (JOBS.replace("timeout_s: 30", "timeout_s: .nan"), "timeout_s"),
    "duplicate key": (JOBS + "seeds: 2\n", "duplicate key 'seeds'"),
    "alias bomb": (
        JOBS
        + "x:\n  a: &a [1, 2, 3, 4, 5, 6, 7, 8, 9]\n"
        + "".join("  " + ln + "\n" for ln in BOMB.splitlines()),
        "aliases expand",
    ),
    "Latin-1": ((JOBS + "# é\n").encode("latin-1"), "not UTF-8"),
    "bad bound": (JOBS + "uncertainty: {far: [grasp.x=5000m]}\n", "outside"),
    "a billion seeds": (JOBS.replace("seeds: 1", "seeds: 1000000000"), "seeds"),
}


@pytest.mark.parametrize("case", JOB_CASES)
def test_a_hostile_jobs_file_is_one_line_and_runs_nothing(case, tmp_path):
    content, fragment = JOB_CASES[case]
    path = tmp_path / "jobs.yaml"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    out = tmp_path / "batch"
    start = time.perf_counter()
    result = run_cli("batch", str(path), "--workers", "1", "--out", str(out))
    assert_one_line_exit_2(result, fragment, time.perf_counter() - start)
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("case", ["alias bomb", "UTF-16"])
def test_the_installed_command_refuses_fast(case, tmp_path):
    """The same through the `bilba` entry point, start-up included."""
    text, fragment = TASKS[case]
    path = tmp_path / "task.yaml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    start = time.perf_counter()
    done = subprocess.run(
        [
            str(Path(sys.executable).parent / "bilba"),
            "plan",
            str(path),
            "--workers",
            "0",
            "--out",
            str(tmp_path / "p.json"),
            "--log",
            str(tmp_path / "l.mcap"),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert time.perf_counter() - start < 5.0
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and fragment in done.stderr
    assert list(tmp_path.iterdir()) == [path]


def rewritten_log(source: Path, target: Path, topic: str, edit) -> Path:
    """``source`` with the first message on ``topic`` replaced by ``edit(its bytes)``: a
    valid MCAP file (CRCs right) whose message is not as bilba writes it."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with source.open("rb") as f, target.open("wb") as out:
        writer = Writer(out, compression=CompressionType.NONE)
        writer.start(profile="bilba", library="test")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        done = False
        for schema, channel, message in make_reader(f).iter_messages():
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id]
                )
            data = message.data
            if channel.topic == topic and not done:
                data, done = edit(data), True
            writer.add_message(channels[channel.id], message.log_time, data, message.publish_time)
        writer.finish()
    assert done, topic
    return target


def _with(key: str, value: object):
    return lambda data: json.dumps({**json.loads(data), key: value}).encode()


#: a log message edited -> (topic, the edit, a fragment of the one line)
LOG_EDITS = {
    "truncated": (
        "/transition",
        lambda d: d[: len(d) // 2],
        "message 0 on /transition is not JSON",
    ),
    "particles a number": ("/transition", _with("after", 3.5), "at after: 3.5 is not of type"),
    "task without a name": ("/metadata", _with("task", {}), "'name' is a required property"),
    "outcome a list": ("/outcome", lambda d: b"[1, 2]", "on /outcome, at the message"),
}
#: (edit, the command that reads what was edited)
LOG_CASES = [
    *((e, c) for e in ("truncated", "particles a number") for c in ("show", "csv", "plot")),
    ("truncated", "ndjson"),
    ("task without a name", "summary"),
    ("outcome a list", "summary"),
]
LOG_COMMANDS = {
    "show": ["show", "--step", "0"],
    "csv": ["export", "--format", "csv", "--out", "out.csv"],
    "ndjson": ["export", "--out", "out.ndjson"],
    "plot": ["plot", "--out", "out.png"],
    "summary": ["summary"],
}


@pytest.mark.parametrize(("edit", "command"), LOG_CASES)
def test_a_log_whose_messages_bilba_did_not_write_is_one_line(
    edit, command, plan_and_log, tmp_path, monkeypatch
):
    """A valid MCAP file (CRCs right) whose message is not JSON, or JSON of another shape:
    the readers index messages unchecked and, where one fails, name the message that does
    not match its topic's schema; before, a KeyError or TypeError was an internal error."""
    topic, change, fragment = LOG_EDITS[edit]
    log = rewritten_log(plan_and_log / "l.mcap", tmp_path / "bad.mcap", topic, change)
    monkeypatch.chdir(tmp_path)
    name, *args = LOG_COMMANDS[command]
    assert_one_line_exit_2(run_cli("logs", name, str(log), *args), fragment, 0.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.mcap"]  # no output written


def test_an_unchanged_log_reads_in_every_command(plan_and_log, tmp_path, monkeypatch):
    """The control: the same rewrite with nothing edited reads everywhere."""
    log = rewritten_log(plan_and_log / "l.mcap", tmp_path / "same.mcap", "/transition", bytes)
    monkeypatch.chdir(tmp_path)
    for name, *args in LOG_COMMANDS.values():
        result = run_cli("logs", name, str(log), *args)
        assert result.exit_code == 0, (name, result.output)


def test_a_reader_failing_on_a_log_bilba_wrote_is_a_bug_not_a_bad_log(plan_and_log):
    """Every message matches its schema: the reader's own error goes through as it is."""
    from bilba_dist.record.reader import read_log, reading

    with pytest.raises(KeyError, match="no_such_field"), reading(read_log(plan_and_log / "l.mcap")):
        raise KeyError("no_such_field")


#: command (paths relative to the folder above) -> a fragment of the one line
OVERWRITES = {
    "logs plan l.mcap --out ./l.mcap": "--out l.mcap is the log",
    "logs export l.mcap --out sub/../l.mcap": "is the log: writing it would destroy it",
    "logs plot l.mcap --out l.mcap": "--out l.mcap is the log",
    "logs recover l.mcap --out l.mcap": "--out l.mcap is the log",
    "export p.json --target franky --out p.json": "--out p.json is the plan",
    "plan peg-in-hole --workers 0 --out same.x --log same.x": "--out and --log name one file",
    "plan task.yaml --workers 0 --out task.yaml": "--out task.yaml is the task file",
    "plan task.yaml --workers 0 --out t.json --log ./task.yaml": "--log task.yaml is the task",
    "logs plan l.mcap --out p.json/x.json": "p.json is a file, not a folder",
    "graph task.yaml --dot ./task.yaml": "--dot task.yaml is the task file",
}


@pytest.mark.parametrize("command", OVERWRITES)
def test_an_output_never_overwrites_what_the_command_reads(command, plan_and_log, monkeypatch):
    """Refused in one line before any work; the files read are left byte for byte."""
    monkeypatch.chdir(plan_and_log)
    (plan_and_log / "task.yaml").write_text(PEG)
    before = {name: (plan_and_log / name).read_bytes() for name in ("p.json", "l.mcap")}
    start = time.perf_counter()
    result = run_cli(*command.split())
    assert_one_line_exit_2(result, OVERWRITES[command], time.perf_counter() - start)
    assert {name: (plan_and_log / name).read_bytes() for name in before} == before
    assert (plan_and_log / "task.yaml").read_text() == PEG
    assert not (plan_and_log / "same.x").exists() and not (plan_and_log / "t.json").exists()


def test_a_log_output_in_a_new_folder_is_written(plan_and_log, tmp_path):
    """`logs plan/export --out` make their folder, as `plan --out` does."""
    log = str(plan_and_log / "l.mcap")
    assert run_cli("logs", "plan", log, "--out", str(tmp_path / "a" / "p.json")).exit_code == 0
    assert (tmp_path / "a" / "p.json").read_bytes() == (plan_and_log / "p.json").read_bytes()
    assert run_cli("logs", "export", log, "--out", str(tmp_path / "b" / "l.ndjson")).exit_code == 0
    assert (tmp_path / "b" / "l.ndjson").read_text().count("\n") > 20


@pytest.mark.parametrize(
    ("command", "fragment"),
    [
        ("validate {} --workers 0", "not a regular file; a plan file is expected"),
        ("export {} --target franky", "not a regular file; a plan file is expected"),
        ("logs summary {}", "not a regular file; a planning log (MCAP) is expected"),
        ("batch {} --out batch", "not a regular file; a jobs file is expected"),
        ("plan {} --workers 0 --no-log", "not a regular file; a task file is expected"),
    ],
)
def test_a_pipe_or_device_given_as_a_file_is_refused_before_it_is_read(
    command, fragment, tmp_path, monkeypatch
):
    """A FIFO would block the open for ever, /dev/zero would be read until memory ran out."""
    monkeypatch.chdir(tmp_path)
    os.mkfifo("pipe")
    start = time.perf_counter()
    result = run_cli(*command.format("./pipe").split())
    assert_one_line_exit_2(result, f"pipe: {fragment}", time.perf_counter() - start)
    if os.path.exists("/dev/zero"):
        result = run_cli(*command.format("/dev/zero").split())
        assert result.exit_code == 2 and "/dev/zero: not a regular file" in result.stderr


LONG = "n" * 300  # over any file system's 255-byte name limit


@pytest.mark.parametrize(
    "command",
    [
        f"plan {LONG} --workers 0 --no-log",
        f"plan ./{LONG}.yaml --workers 0 --no-log",
        f"graph {'a/' * 3000}task.yaml",
        f"validate {LONG}.json --workers 0",
        f"export {LONG}.json --target franky",
        f"logs summary {LONG}.mcap",
        f"batch {LONG}.yaml --out batch",
        f"report {LONG}",
        f"plan peg-in-hole --workers 0 --no-log --out {LONG}.json --timeout 0",
        f"graph peg-in-hole --dot {LONG}.dot",
        f"validate {{plan}} --workers 0 --map grasp.x=1cm --map-out {LONG}",
        f"logs plot {{log}} --out {LONG}.png",
    ],
)
def test_a_file_name_too_long_is_one_line(command, plan_and_log, tmp_path, monkeypatch):
    """Python 3.11's Path.exists() raises on such a name rather than answer False; an
    output's name is checked before the work whose result it would hold."""
    monkeypatch.chdir(tmp_path)
    command = command.format(plan=plan_and_log / "p.json", log=plan_and_log / "l.mcap")
    start = time.perf_counter()
    result = run_cli(*command.split())
    assert_one_line_exit_2(result, "", time.perf_counter() - start)
    assert "internal error" not in result.stderr and not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("raised", "code", "line"),
    [
        (KeyboardInterrupt(), 130, "interrupted"),
        (BilbaError("a bad value"), 2, "bilba: error: a bad value"),
        (OSError(36, "File name too long", "n" * 300), 2, "bilba: error: nnnn"),
        (ZeroDivisionError("boom"), 3, "bilba: internal error: ZeroDivisionError: boom"),
    ],
)
def test_every_command_fails_in_one_line_with_its_exit_code(raised, code, line):
    """What `user_errors` makes of what a command raises (Ctrl-C: `validate`, `export`,
    `logs`, and a `--portfolio` plan; `batch` and `plan` say first what they kept)."""
    import click
    from click.testing import CliRunner

    from bilba_dist.cli.errors import user_errors

    @click.command()
    @user_errors
    def command() -> None:
        raise raised

    result = CliRunner().invoke(command, [])
    assert result.exit_code == code and result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith(line) and "Traceback" not in result.output
