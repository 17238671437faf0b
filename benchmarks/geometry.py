"""Time to build the C-obs slice and the mode graph, per task, on one core.

    .venv/bin/python benchmarks/geometry.py [--repeats 7] [--tasks peg-in-hole puzzle ...]

Tasks: the built-ins, `round-peg` (examples/round-peg: meshed, its plate split into 16
pieces), `round` (generality.py's 32-sided peg in a hole of 32 wall pieces), or a task file.
Each repeat builds from scratch (no slice cache) for the nominal particle of the task's own
belief, and separately times the whole `belief_graph` call (all it takes to get a schedule).
Prints a table of medians and ends with one JSON line (times in keys ending `_s`).
Target (issue 2): slice + graph under 1 s per task on one core (the built-ins).
"""

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from generality import SHAPES, write_task  # benchmarks/generality.py

from bilba_dist.belief.particles import initial_belief
from bilba_dist.cspace.slice import CObsSlice
from bilba_dist.modes.graph import build_mode_graph
from bilba_dist.modes.schedule import SliceCache, belief_graph, graph_params
from bilba_dist.task.loader import Task, load_task

ROOT = Path(__file__).resolve().parents[1]
TASKS = ["peg-in-hole", "puzzle", "round-peg", "round"]


def task_for(name: str, folder: Path) -> Task:
    """A built-in or a task file by name; `round-peg`: the example; a generality.py shape."""
    if name == "round-peg":
        return load_task(ROOT / "examples" / "round-peg" / "round-peg.yaml")
    if name in SHAPES:
        return load_task(write_task(folder, name, {}))
    return load_task(name)


def measure(task: Task, repeats: int) -> dict[str, float]:
    particles = initial_belief(task)
    poses = [p.X_OM(task.X_WG0) for p in particles]
    positions = np.array([X.translation for X in poses])
    slice_s, graph_s, schedule_s = [], [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        cslice = CObsSlice.build(task.environment, task.manipuland, poses[0].rotation)
        _ = cslice.vertex_modes
        t1 = time.perf_counter()
        graph = build_mode_graph(cslice, positions, task.goal, graph_params(task))
        graph.schedule()
        t2 = time.perf_counter()
        belief_graph(task, particles, task.X_WG0, SliceCache(task))
        t3 = time.perf_counter()
        slice_s.append(t1 - t0)
        graph_s.append(t2 - t1)
        schedule_s.append(t3 - t2)
    return {
        "slice_s": statistics.median(slice_s),
        "graph_s": statistics.median(graph_s),
        "total_s": statistics.median(s + g for s, g in zip(slice_s, graph_s, strict=True)),
        "schedule_s": statistics.median(schedule_s),
        "polytopes": len(cslice.polytopes),
        "facets": sum(len(p.b) for p in cslice.polytopes),
        "vertices": len(cslice.vertices),
        "modes": len(graph.modes),
        "edges": graph.graph.number_of_edges(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--tasks", nargs="+", default=TASKS)
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    folder = Path(tempfile.mkdtemp(prefix="bilba_geometry_"))
    results = {name: measure(task_for(name, folder), args.repeats) for name in args.tasks}
    print(
        f"machine: {platform.node()} {platform.machine()}, {os.cpu_count()} cores; "
        f"medians of {args.repeats} runs, one core"
    )
    header = (
        f"{'task':<12} {'slice s':>8} {'graph s':>8} {'total s':>8} {'belief s':>9} "
        f"{'polys':>5} {'facets':>6} {'verts':>5} {'modes':>5} {'edges':>5}"
    )
    print(header)
    for name, r in results.items():
        print(
            f"{name:<12} {r['slice_s']:8.3f} {r['graph_s']:8.3f} {r['total_s']:8.3f} "
            f"{r['schedule_s']:9.3f} {r['polytopes']:5d} {r['facets']:6d} {r['vertices']:5d} "
            f"{r['modes']:5d} {r['edges']:5d}"
        )
    figures = {
        f"{name.replace('-', '_')}_{key}": value
        for name, r in results.items()
        for key, value in r.items()
    }
    print(json.dumps(figures, sort_keys=True))


if __name__ == "__main__":
    main()
