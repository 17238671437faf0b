"""Rollout throughput of the two dynamics models, and where a step's time goes.

    .venv/bin/python benchmarks/rollouts.py [--rollouts 10] [--repeats 5] [--window 3]

One fixed motion (issue 3): the nominal peg-in-hole particle, the peg's bottom 2 cm above
the chamfer, the setpoint ramped to 5 mm below the hole bottom, "very stiff" gains.
Rollouts per second on one core for the Panda and the floating model, full-length (5 s) and
with early stop; the per-step split between our Python (controller, and labelling at the
end) and PyBullet's stepSimulation; and two processes against one. Medians of --repeats.
Prints a table, then one JSON line.
"""

import argparse
import json
import multiprocessing as mp
import os
import platform
import statistics
import time

import numpy as np
import pinocchio as pin

from bilba_dist.belief.particles import initial_belief
from bilba_dist.robot.panda import Q_CENTRE, PandaModel
from bilba_dist.rollout import Motion, ParticleState, RolloutRequest
from bilba_dist.task.loader import load_task
from bilba_dist.workers.rollout_worker import RolloutWorker
from bilba_dist.workers.settings import SimSettings

WALL_TOP, HOLE_BOTTOM, PEG_HALF, GRASP = 0.10, 0.04, 0.075, 0.155
VERY_STIFF = np.diag([100.0, 100.0, 100.0, 600.0, 600.0, 600.0])


def fixed_request() -> tuple:
    task = load_task("peg-in-hole", ["grasp.pitch=0deg"])
    (particle,) = initial_belief(task)
    R = task.X_WG0.rotation
    start = pin.SE3(R, np.array([0.5, 0.0, WALL_TOP + 0.02 + PEG_HALF + GRASP]))
    goal = pin.SE3(R, np.array([0.5, 0.0, HOLE_BOTTOM - 0.005 + PEG_HALF + GRASP]))
    q = PandaModel().ik(start, Q_CENTRE)
    state = ParticleState(X_WM=start * particle.X_GM, q=q)
    return task, RolloutRequest(particle, state, Motion(VERY_STIFF, goal))


def measure(model: str, early_stop: bool, n: int, repeats: int) -> dict[str, float]:
    task, request = fixed_request()
    worker = RolloutWorker(task, model, SimSettings(early_stop=early_stop))
    (first,) = worker.simulate([request])  # builds the world; not timed
    sim = worker.panda_sim(request.particle.X_GM) if model == "panda" else worker._floating_sim()
    rates, overheads, sims = [], [], []
    for _ in range(repeats):
        steps0, physics0 = sim.stats.steps, sim.stats.physics_s
        t0 = time.perf_counter()
        results = worker.simulate([request] * n)
        wall = time.perf_counter() - t0
        _steps, physics = sim.stats.steps - steps0, sim.stats.physics_s - physics0
        rates.append(n / wall)
        overheads.append((wall - physics) / physics)
        sims.append(statistics.mean(r.sim_time_s for r in results))
    worker.close()
    return {
        "per_s": statistics.median(rates),
        "overhead_vs_physics": statistics.median(overheads),
        "sim_time_s": statistics.median(sims),
        "goal_reached": float(task.goal in first.contacts),
        "us_per_step": 1e6 / statistics.median(rates) / (statistics.median(sims) * 240),
    }


def _process(window_s: float, barrier, out) -> None:
    task, request = fixed_request()
    worker = RolloutWorker(task, "panda", SimSettings(early_stop=True))
    worker.simulate([request])
    barrier.wait()
    t0 = done = time.perf_counter()
    count = 0
    while done - t0 < window_s:
        worker.simulate([request])
        count, done = count + 1, time.perf_counter()
    out.put(count / (done - t0))


def processes(count: int, window_s: float) -> float:
    """Rollouts per second of ``count`` processes, each with its own worker, each counting
    the rollouts it completes in the same window after a barrier (a pool's throughput: a
    process started late or finishing early does not stretch the others' clock)."""
    os.environ["OMP_NUM_THREADS"] = "1"  # as Ray gives its actors; read at the child's imports
    ctx = mp.get_context("spawn")
    barrier, out = ctx.Barrier(count), ctx.Queue()
    procs = [ctx.Process(target=_process, args=(window_s, barrier, out)) for _ in range(count)]
    for proc in procs:
        proc.start()
    rates = [out.get() for _ in procs]
    for proc in procs:
        proc.join()
    return sum(rates)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rollouts", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--window", type=float, default=3.0, help="seconds per process run")
    args = parser.parse_args()
    rows = {
        (model, early): measure(model, early, args.rollouts, args.repeats)
        for model in ("panda", "floating")
        for early in (False, True)
    }
    ratios = []
    for _ in range(args.repeats):  # one and two processes in turn, each for --window s
        one = processes(1, args.window)
        two = processes(2, args.window)
        ratios.append(two / one)
    print(
        f"machine: {platform.node()} {platform.machine()}, {os.cpu_count()} cores; "
        f"medians of {args.repeats} x {args.rollouts} rollouts"
    )
    print(
        f"{'model':<9} {'early stop':>10} {'rollouts/s':>10} {'sim s':>6} {'us/step':>8} "
        f"{'ours/physics':>12} {'goal':>5}"
    )
    for (model, early), r in rows.items():
        print(
            f"{model:<9} {early!s:>10} {r['per_s']:10.1f} {r['sim_time_s']:6.2f} "
            f"{r['us_per_step']:8.0f} {r['overhead_vs_physics']:12.2f} {int(r['goal_reached']):>5}"
        )
    print(f"two processes / one (Panda, early stop): {statistics.median(ratios):.2f}x")
    figures = {
        "panda_full_per_s_core": rows["panda", False]["per_s"],
        "panda_early_stop_per_s_core": rows["panda", True]["per_s"],
        "floating_full_per_s_core": rows["floating", False]["per_s"],
        "floating_per_s_core": rows["floating", True]["per_s"],
        "overhead_vs_physics": rows["panda", True]["overhead_vs_physics"],
        "floating_overhead_vs_physics": rows["floating", True]["overhead_vs_physics"],
        "panda_early_stop_sim_s": rows["panda", True]["sim_time_s"],
        "floating_early_stop_sim_s": rows["floating", True]["sim_time_s"],
        "two_process_speedup": statistics.median(ratios),
    }
    print(json.dumps(figures, sort_keys=True))


if __name__ == "__main__":
    main()
