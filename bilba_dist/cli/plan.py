"""`bilba plan TASK`: find a plan with BILBA, write the plan file, print a summary."""

import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import click

from bilba_dist.belief.start import check_task
from bilba_dist.cli.errors import EXIT_INTERRUPTED, user_errors
from bilba_dist.cli.options import (
    SEED,
    TIMEOUT_S,
    Bounded,
    split_uncertainty,
    task_argument,
    uncertainty_option,
    workers_option,
)
from bilba_dist.cli.outputs import refuse_overwriting, task_file
from bilba_dist.errors import BilbaError
from bilba_dist.planning.bilba import PLANNERS, Progress, plan
from bilba_dist.planning.diagnosis import goal_edge_warning, goal_overlap_warning
from bilba_dist.planning.result import PlanResult
from bilba_dist.planning.verify import more_particles_hint
from bilba_dist.plans.file import dumps, plan_document, write_plan, write_plan_text
from bilba_dist.record.writer import LogWriter
from bilba_dist.robot.drivers import DRIVER_NAMES
from bilba_dist.robot.gripper import too_wide
from bilba_dist.rollout import DynamicsModel
from bilba_dist.task.loader import Task, load_task, with_planner, with_preset
from bilba_dist.task.schema import PRESETS, AxisBelief, particle_count
from bilba_dist.task.timestep import verify_timestep

EXIT_NO_PLAN = 1
#: How `bilba plan` (one search or a portfolio) shows a plan that failed verification.
FAILED = "FAILED (the plan that held best; none passed)"


@click.command("plan")
@task_argument
@click.option("--planner", type=click.Choice(PLANNERS), default="bilba-variable", show_default=True)
@uncertainty_option
@click.option("--seed", type=SEED, default=0, show_default=True)
@click.option(
    "--preset",
    type=click.Choice(sorted(PRESETS)),
    help="Planner settings: paper = the authors' (to reproduce the paper), default = ours; "
    "replaces the task file's values for those settings.",
)
@click.option(
    "--driver",
    type=click.Choice(DRIVER_NAMES),
    help="Plan within this Franka driver's form of stiffness and its limits (docs/drivers.md); "
    "replaces the task file's planner.driver.",
)
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Plan file to write [default: plans/TASK-PLANNER-sSEED.json].",
)
@click.option("--timeout", type=TIMEOUT_S, help="Overall planning timeout [s] (task default: 900).")
@workers_option
@click.option(
    "--model",
    type=click.Choice(["panda", "floating"]),
    default="panda",
    show_default=True,
    help="Dynamics for planning; a floating-model plan is checked on the Panda before use.",
)
@click.option(
    "--address", help="Join this Ray cluster (auto or HOST:PORT) instead of starting one."
)
@click.option(
    "--log",
    "log_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="MCAP log [default: logs/TASK-PLANNER-sSEED-TIME.mcap].",
)
@click.option("--no-log", is_flag=True, help="Write no log.")
@click.option(
    "--portfolio",
    type=Bounded(1, 1024, int),
    default=1,
    show_default=True,
    help="Run N searches (seeds SEED..SEED+N-1) side by side on Ray, one CPU each; the first "
    "plan found wins and the others are cancelled.",
)
@click.option(
    "--search-actors",
    type=Bounded(0, 1024, int),
    default=0,
    show_default=True,
    help="With --portfolio: run each search's rollouts on K Ray actors of its own (N × K "
    "CPUs in all) instead of in the search's process. On a 16-core node 2 × 8 or 4 × 4 "
    "planned first (docs/cluster.md).",
)
@click.option(
    "--allow-start-contact",
    is_flag=True,
    help="Plan even if a particle's part starts inside the environment (refused by default).",
)
@user_errors
def plan_command(
    task: str,
    planner: str,
    uncertainty: tuple[str, ...],
    seed: int,
    preset: str | None,
    driver: str | None,
    out: Path | None,
    timeout: float | None,
    workers: int,
    model: DynamicsModel,  # click.Choice of the two
    address: str | None,
    log_path: Path | None,
    no_log: bool,
    portfolio: int,
    search_actors: int,
    allow_start_contact: bool,
) -> None:
    """Plan TASK (a built-in name or a YAML path). Exit 0 only when a plan was found."""
    from tqdm import tqdm

    from bilba_dist.schedulers.session import rollout_backend
    from bilba_dist.workers.rollout_worker import RolloutWorker

    loaded = load_task(task, split_uncertainty(uncertainty))
    if preset is not None:
        loaded = with_preset(loaded, preset)
    if driver is not None:
        loaded = with_planner(loaded, driver=driver)
    check_task(loaded, allow_start_contact)  # one line before planning, not a fruitless search
    if wide := too_wide(loaded.manipuland, loaded.X_GM):
        click.echo(f"bilba: warning: {wide}", err=True)
    out = out or Path("plans") / f"{loaded.name}-{planner}-s{seed}.json"
    stamp = time.strftime("%Y%m%d-%H%M%S")
    log_path = log_path or Path("logs") / f"{loaded.name}-{planner}-s{seed}-{stamp}.mcap"
    refuse_overwriting({"--out": out, "--log": None if no_log else log_path}, task_file(task))
    if search_actors and portfolio == 1:
        raise BilbaError("--search-actors is for --portfolio N (2 or more); one plan on K "
                         "actors is --workers K")  # fmt: skip
    if portfolio > 1:
        if workers == 0:
            raise BilbaError("--portfolio runs its searches on Ray: give --workers 1 or more")
        if search_actors and address is None and portfolio * search_actors > workers:
            raise BilbaError(
                f"--portfolio {portfolio} × --search-actors {search_actors} needs "
                f"{portfolio * search_actors} CPUs; the local Ray instance has --workers {workers}"
            )
        plan_portfolio(loaded, planner, seed, portfolio, timeout, workers, address, model,
                       out, None if no_log else log_path, search_actors)  # fmt: skip
        return
    log = None if no_log else LogWriter(log_path, loaded, planner, seed, model == "panda")
    with (
        closing_log(log),
        rollout_backend(loaded, workers, address, model) as backend,
        tqdm(unit=" rollouts", file=sys.stderr, dynamic_ncols=True) as bar,
    ):

        def show(progress: Progress) -> None:
            bar.set_description_str(progress.contact or "schedule", refresh=False)
            bar.set_postfix_str(f"best score {progress.best_score:.2f}", refresh=False)
            bar.update(progress.rollouts - bar.n)

        panda = RolloutWorker(loaded, "panda") if model == "floating" else None
        result = plan(
            loaded,
            backend,
            planner,  # type: ignore[arg-type]
            seed,
            timeout,
            Progress(update=show),
            log,
            panda,
        )
    document = plan_document(result, loaded)
    write_plan(document, out)
    if log is not None:
        log.finish(dumps(document), result.outcome())
    summary(result, loaded, out)
    if log is not None:
        click.echo(f"log        {log.path} ({log.transitions} transitions)")
    if not result.success:
        sys.exit(EXIT_NO_PLAN)


@contextmanager
def closing_log(log: LogWriter | None) -> Iterator[None]:
    """Inside, a search that ends by an exception (Ctrl-C, Ray gone) leaves its log ended
    and readable with every transition so far, not a file for `bilba logs recover`; Ctrl-C
    is one line and exit code 130, as for `bilba batch`."""
    try:
        yield
    except BaseException as exc:
        if log is not None:
            log.close()
        if not isinstance(exc, KeyboardInterrupt):
            raise
        click.echo(
            "interrupted; no plan" + (f"; the log so far: {log.path}" if log else ""), err=True
        )
        sys.exit(EXIT_INTERRUPTED)


def plan_portfolio(
    task: Task,
    planner: str,
    seed: int,
    n: int,
    timeout: float | None,
    workers: int,
    address: str | None,
    model: DynamicsModel,
    out: Path,
    log_path: Path | None,
    actors: int = 0,
) -> None:
    """``n`` seeded searches on Ray; write the first plan found (and its log)."""
    from bilba_dist.schedulers.portfolio import run_portfolio
    from bilba_dist.schedulers.session import ray_session

    seeds = list(range(seed, seed + n))
    click.echo(
        f"portfolio  {n} searches, seeds {seeds[0]}..{seeds[-1]}, on "
        f"{'the cluster at ' + address if address else f'a local Ray instance of {workers} CPUs'}"
        + (f", {actors} rollout actor{'s' if actors > 1 else ''} each" if actors else "")
    )
    started = time.perf_counter()
    with ray_session(workers, address):
        found = run_portfolio(task, planner, seeds, timeout, model, actors)
    wall = time.perf_counter() - started
    output = found.output
    write_plan_text(output["plan_text"], out)
    if log_path is not None:
        try:
            log_path.parent.mkdir(parents=True, exist_ok=True)
            log_path.write_bytes(output["log_bytes"])
        except OSError as exc:
            raise BilbaError(f"{log_path}: cannot write log: {exc.strerror or exc}") from None
    ended = ", ".join(f"seed {s} {status}" for s, status in found.finished.items())
    if found.winner is None:
        click.echo(f"outcome    NO PLAN from any search ({ended}); last: {output['reason']}")
    else:
        click.echo(
            f"outcome    plan found by seed {found.winner} in {output['planning_time_s']:.1f} s "
            f"({wall:.1f} s with Ray), {output['rollouts']} rollouts"
            + (
                f" on {output['rollout_actors']} actor{'s' if output['rollout_actors'] > 1 else ''}"
                if "rollout_actors" in output
                else " in its own process"
            )
            + (f"; before it: {ended}" if ended else "")
            + (
                f"; cancelled: seeds {', '.join(map(str, found.cancelled))}"
                if found.cancelled
                else ""
            )
        )
    if output.get("verified") is False:
        click.echo(f"verified   {FAILED}: see its plan file")
    click.echo(f"plan file  {out}")
    if log_path is not None:
        click.echo(f"log        {log_path} (the winning search's)")
    if found.winner is None:
        sys.exit(EXIT_NO_PLAN)


def summary(result: PlanResult, given: Task, out: Path) -> None:
    task = result.task or given
    bounds = ", ".join(f"{k}={v:g}" for k, v in task.spec.uncertainty.items()) or "none"
    click.echo(f"task       {task.name} ({task.hash[:12]}), uncertainty {bounds}")
    step, verify_step = task.timestep_s, verify_timestep(task.timestep_s)
    physics = f"physics at {1 / step:.4g} Hz"
    verifies = task.spec.planner.verify_particles > 0 and result.planner != "b-est"
    if verifies and verify_step != step:
        physics += f", verified at {1 / verify_step:.4g} Hz"
    click.echo(f"planner    {result.planner}, seed {result.seed}, {physics}")
    if isinstance(belief := task.spec.belief, AxisBelief) and belief != given.spec.belief:
        n = particle_count(belief, len(task.spec.bounds))
        resumed = ""
        if result.resumed is not None:
            contact, motions = result.resumed
            resumed = f"; resumed at {contact}, which its first {motions} motion(s) made for all"
        click.echo(
            f"belief     restarted on {belief.points} particles a bounded axis ({n} in all): "
            f"the first plan lost offsets between the default's{resumed}"
        )
    status = "plan found" if result.success else f"NO PLAN: {result.reason}"
    click.echo(f"outcome    {status}")
    click.echo(
        f"effort     {result.planning_time_s:.1f} s, {result.rollouts} rollouts, "
        f"{len(result.schedules)} schedules, {len(result.pruned)} edges pruned"
    )
    check = result.verification
    if check is not None and result.success:
        how = "passed" if check.passed else FAILED
        click.echo(f"verified   {how} on {check.text()} (plan {check.plans} of the search)")
        if not check.passed and (hint := more_particles_hint(task, check)):
            click.echo(f"warning: {hint.replace('PLAN', str(out))}", err=True)
    for k, m in enumerate(result.motions, 1):
        xyz = " ".join(f"{v:+.4f}" for v in m.G_d.translation)
        click.echo(f"motion {k:<3} to {m.contact}  G_d [{xyz}] m  score {m.score:.2f}")
    if result.final_belief is not None:
        for i, contacts in enumerate(result.final_belief.contacts):
            click.echo(f"particle {i}: {', '.join(sorted(map(str, contacts))) or 'free'}")
        if result.success and (edge := goal_edge_warning(task.goal, result.final_belief)):
            click.echo(f"warning: {edge}", err=True)
        if result.success and (sliver := goal_overlap_warning(task, result.final_belief)):
            click.echo(f"warning: {sliver}", err=True)
    click.echo(f"plan file  {out}")
