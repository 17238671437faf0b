"""`bilba batch JOBS.yaml` and `bilba report DIR`: grids of planning jobs on Ray."""

import sys
from pathlib import Path

import click

from bilba_dist.cli.errors import EXIT_INTERRUPTED, user_errors
from bilba_dist.cli.options import Bounded
from bilba_dist.errors import BilbaError


@click.command("batch")
@click.argument("jobs_file", metavar="JOBS.yaml", type=click.Path(path_type=Path))
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for records.jsonl, plans/ and logs/ [default: batches/NAME].",
)
@click.option("--resume", is_flag=True, help="Run only the jobs DIR has no record of.")
@click.option(
    "--workers",
    type=Bounded(0, 1024, int),
    default=2,
    show_default=True,
    help="CPUs of the local Ray instance (jobs run side by side, one CPU each).",
)
@click.option(
    "--address", help="Join this Ray cluster (auto or HOST:PORT) instead of starting one."
)
@user_errors
def batch(
    jobs_file: Path, out: Path | None, resume: bool, workers: int, address: str | None
) -> None:
    """Run every job of a grid; one JSON-lines record, plan and MCAP log per finished job."""
    from bilba_dist.schedulers.batch import progress_bar, run_batch
    from bilba_dist.schedulers.jobs import load_jobs

    if workers < 1:
        raise BilbaError("--workers: a batch needs at least 1")
    grid = load_jobs(jobs_file)
    out = out or Path("batches") / grid.name
    update, close = progress_bar(len(grid.jobs))
    try:
        counts = run_batch(grid, out, resume, workers, address, update)
    except KeyboardInterrupt:
        close()
        click.echo(
            f"interrupted; finished jobs are recorded in {out}; rerun with --resume", err=True
        )
        sys.exit(EXIT_INTERRUPTED)
    finally:
        close()  # before an error's one line
    click.echo(
        f"{out}: {counts.done} jobs run in {counts.elapsed_s:.0f} s "
        f"({counts.failed} without a plan), {counts.skipped} already recorded, "
        f"{counts.total} in the grid"
    )


@click.command("report")
@click.argument("folder", metavar="DIR", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--png", type=click.Path(dir_okay=False, path_type=Path), help="[default: DIR/report.png]"
)
@user_errors
def report(folder: Path, png: Path | None) -> None:
    """The paper-style table of a batch folder (median ± MAD time, successes) and a PNG."""
    from bilba_dist.schedulers.report import report as make_report

    text, written = make_report(folder, png)
    click.echo(text)
    click.echo(f"figure: {written}")
