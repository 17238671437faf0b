"""`bilba logs …`: inspect planning logs."""

import sys
from pathlib import Path

import click

from bilba_dist.cli.errors import user_errors
from bilba_dist.cli.outputs import make_folder, refuse_overwriting, write_output
from bilba_dist.errors import BilbaError
from bilba_dist.record import inspect
from bilba_dist.record.inspect import mode_text
from bilba_dist.record.reader import Log, read_log, reading, recover


@click.group("logs")
def logs() -> None:
    """Inspect the MCAP logs of planning jobs."""


@logs.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
@user_errors
def summary(files: tuple[Path, ...]) -> None:
    """Task, planner, seed, duration, transitions, schedules and outcome of each log."""
    header = (
        f"{'file':<40} {'task':<12} {'planner':<15} {'seed':>4} {'time s':>7} "
        f"{'trans':>6} {'sched':>5}  outcome"
    )
    for k, path in enumerate(files):
        with reading(read_log(path)) as log:
            rows = _summary_rows(log, path, len(files) == 1)
        # each file's rows only once it has read whole: a bad file prints its error alone
        click.echo("\n".join([header, *rows] if k == 0 else rows))


def _summary_rows(log: Log, path: Path, schedules: bool) -> list[str]:
    meta = log.metadata
    outcome = (log.json("/outcome") or [{}])[-1]
    if not outcome:
        status = "unfinished"
    elif outcome["success"]:
        status = "plan found"
    else:
        status = f"no plan: {outcome['reason']}"
    seconds = outcome.get("planning_time_s", float("nan"))
    transitions = len(log.messages["/transition"])
    rows = [
        f"{path.name:<40} {meta['task']['name']:<12} {meta['planner']:<15} {meta['seed']:>4} "
        f"{seconds:7.1f} {transitions:>6} {len(log.messages['/schedule']):>5}  {status}"
    ]
    if schedules:
        missing = inspect.missing_transitions(log)
        if missing:
            rows.append("  " + inspect.missing_text(missing))
        for k, s in enumerate(log.json("/schedule")):
            rows.append(f"  schedule {k}: " + " -> ".join(map(mode_text, s["schedule"])))
    return rows


@logs.command("plan")
@click.argument("file", type=click.Path(path_type=Path))
@click.option(
    "--out", type=click.Path(dir_okay=False, path_type=Path), help="Write here instead of stdout."
)
@user_errors
def plan_command(file: Path, out: Path | None) -> None:
    """The plan recorded in a log: byte for byte the planner's plan file."""
    refuse_overwriting({"--out": out}, {"the log": file})
    log = read_log(file)
    if not log.messages.get("/plan"):
        raise BilbaError(f"{file}: the log holds no plan (the job did not finish)")
    data = log.messages["/plan"][-1]
    if out is None:
        sys.stdout.buffer.write(data)
    else:
        write_output(out, data)


@logs.command("recover")
@click.argument("file", type=click.Path(path_type=Path))
@click.option(
    "--out", type=click.Path(dir_okay=False, path_type=Path), help="[default: FILE.recovered.mcap]"
)
@user_errors
def recover_command(file: Path, out: Path | None) -> None:
    """Rewrite a truncated or damaged log into a valid one holding everything readable."""
    out = out or file.with_suffix(".recovered.mcap")
    refuse_overwriting({"--out": out}, {"the log": file})
    make_folder(out)
    kept = recover(file, out)
    with reading(read_log(out)) as log:
        missing = inspect.missing_transitions(log)
    click.echo(
        f"{out}: {kept} messages recovered"
        + (f"; {inspect.missing_text(missing)}" if missing else "")
    )


@logs.command()
@click.argument("file", type=click.Path(path_type=Path))
@click.option(
    "--step", type=int, default=0, show_default=True, help="Transition index (negative: from end)."
)
@user_errors
def show(file: Path, step: int) -> None:
    """The particles, contacts and motion of one transition."""
    with reading(read_log(file)) as log:
        click.echo(inspect.show(log, step))


@logs.command()
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), help="[default: FILE.png]")
@user_errors
def plot(file: Path, out: Path | None) -> None:
    """PNG: score and particle spread per transition, and the schedules as they evolved."""
    out = out or file.with_suffix(".png")
    refuse_overwriting({"--out": out}, {"the log": file})
    make_folder(out)
    with reading(read_log(file)) as log:
        inspect.plot(log, out)
    click.echo(f"{out}")


@logs.command()
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--format", "fmt", type=click.Choice(["ndjson", "csv"]), default="ndjson")
@click.option(
    "--out", type=click.Path(dir_okay=False, path_type=Path), help="Write here instead of stdout."
)
@user_errors
def export(file: Path, fmt: str, out: Path | None) -> None:
    """Every message as JSON lines, or one CSV row per transition and particle."""
    refuse_overwriting({"--out": out}, {"the log": file})
    with reading(read_log(file)) as log:
        text = inspect.export(log, fmt)
    if out is None:
        click.echo(text, nl=False)
    else:
        write_output(out, text)
