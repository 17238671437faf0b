"""What `bilba logs show|plot|export` make of a log: text, a figure, flat files."""

import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from bilba_dist.errors import BilbaError, listed
from bilba_dist.files import clip_name
from bilba_dist.record.reader import Log


def mode_text(pair: list[str]) -> str:
    """A logged contact pair as text: ``(env, manip)``, or ``free``."""
    return "free" if pair[0] == "free" else f"({pair[0]}, {pair[1]})"


def _contacts(contacts: list[list[str]]) -> str:
    return ", ".join(mode_text(c) for c in contacts) or "free"


def missing_transitions(log: Log) -> list[int]:
    """The transition indices a recovered log lacks (each transition is numbered in order;
    a damaged chunk lost the ones between), up to its last one."""
    indices = {t["index"] for t in log.json("/transition")}
    return sorted(set(range(max(indices, default=-1) + 1)) - indices)


def missing_text(missing: list[int]) -> str:
    return f"transitions missing (lost with a damaged chunk): {listed(missing, 10)}"


def transition(log: Log, step: int) -> dict[str, Any]:
    transitions = log.json("/transition")
    if not transitions:
        raise BilbaError(f"{log.path}: the log holds no transitions")
    if not -len(transitions) <= step < len(transitions):
        last = len(transitions) - 1
        raise BilbaError(
            f"{log.path}: no step {clip_name(step, 30)}; the log holds steps 0..{last}"
        )
    return transitions[step]


def show(log: Log, step: int) -> str:
    """One transition: the contact sought, the motion, and every particle before and after."""
    t = transition(log, step)
    total = len(log.messages["/transition"])
    motion = t["motion"]
    K = np.asarray(motion["K"])
    lines = [
        f"step {t['index']} of {total}: {'ACCEPTED' if t['accepted'] else 'rejected'}, "
        f"contact sought {mode_text(t['contact_sought'])}",
        f"motion   G_d xyz [{' '.join(f'{v:+.4f}' for v in motion['G_d']['xyz'])}] m, "
        f"quat xyzw [{' '.join(f'{v:+.4f}' for v in motion['G_d']['quat_xyzw'])}], "
        f"timeout {motion['timeout_s']:g} s",
        f"         K diagonal [{' '.join(f'{v:.0f}' for v in np.diag(K))}] "
        "(rotation N·m/rad, then translation N/m)",
        f"score    {t['score']:.3f}, {t['count']} of {len(t['after'])} particles in the contact",
        f"{'particle':<9}{'before xyz [mm]':<27}{'after xyz [mm]':<27}contacts after",
    ]
    for i, (b, a) in enumerate(zip(t["before"], t["after"], strict=True)):
        before = " ".join(f"{1e3 * v:+7.1f}" for v in b["X_WM"]["xyz"])
        after = " ".join(f"{1e3 * v:+7.1f}" for v in a["X_WM"]["xyz"])
        shown = f"stopped: {a['stopped']}" if a.get("stopped") else _contacts(a["contacts"])
        if a.get("arm_touches"):
            shown += f"; the arm touches {', '.join(a['arm_touches'])}"
        lines.append(f"{i:<9}{before:<27}{after:<27}{shown}")
    return "\n".join(lines)


def spread_mm(particles: list[dict[str, Any]]) -> float:
    """Largest distance of a particle's manipuland from the particles' mean position [mm]."""
    xyz = np.array([p["X_WM"]["xyz"] for p in particles])
    return float(1e3 * np.max(np.linalg.norm(xyz - xyz.mean(axis=0), axis=1)))


def plot(log: Log, out: Path) -> None:
    """PNG: score and particle spread per transition, and the contact sought against the
    schedules Dijkstra produced as the search went on."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    transitions = log.json("/transition")
    if not transitions:
        raise BilbaError(f"{log.path}: the log holds no transitions to plot")
    steps = np.arange(len(transitions))
    accepted = np.array([t["accepted"] for t in transitions])
    scores = np.array([t["score"] for t in transitions])
    spread = np.array([spread_mm(t["after"]) for t in transitions])
    sought = [mode_text(t["contact_sought"]) for t in transitions]
    modes = list(dict.fromkeys(sought))
    # Where each new schedule starts, counted in transitions written before it.
    schedule_at, count = [], 0
    for topic, _, _ in log.records:
        if topic == "/transition":
            count += 1
        elif topic == "/schedule":
            schedule_at.append(count)

    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(9, 8), constrained_layout=True)
    meta = log.metadata
    fig.suptitle(f"{meta['task']['name']} · {meta['planner']} · seed {meta['seed']}")
    axes[0].plot(steps, scores, ".", color="0.6", label="candidate")
    axes[0].plot(steps[accepted], scores[accepted], "o", color="C3", label="accepted")
    axes[0].set_ylabel("score h(b, F)")
    axes[0].legend(loc="upper left")
    axes[1].plot(steps, spread, ".", color="0.6")
    axes[1].plot(steps[accepted], spread[accepted], "o", color="C3")
    axes[1].set_ylabel("particle spread [mm]\n(max from mean, world)")
    axes[2].plot(steps, [modes.index(m) for m in sought], ".", color="C0")
    axes[2].set_yticks(range(len(modes)), modes, fontsize=7)
    axes[2].set_ylabel("contact sought")
    axes[2].set_xlabel("transition")
    for ax in axes:
        for k, at in enumerate(schedule_at):
            label = "new schedule" if k == 0 else None
            ax.axvline(at - 0.5, color="C2", lw=0.8, ls="--", label=label)
    axes[2].legend(loc="upper left", fontsize=7)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


CSV_COLUMNS = [
    "step", "accepted", "contact_sought", "score", "count", "particle",
    "x_before", "y_before", "z_before", "x_after", "y_after", "z_after",
    "qx_after", "qy_after", "qz_after", "qw_after", "contacts_after",
]  # fmt: skip


def export(log: Log, fmt: str) -> str:
    """ndjson: every message with its topic and log time, in file order. csv: one row per
    transition and particle (positions in metres, world frame)."""
    if fmt == "ndjson":
        decoded = {topic: iter(log.json(topic)) for topic in log.messages}  # file order
        return "".join(
            json.dumps({"topic": topic, "log_time_ns": ns, "message": next(decoded[topic])}) + "\n"
            for topic, ns, _ in log.records
        )
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for t in log.json("/transition"):
        for i, (b, a) in enumerate(zip(t["before"], t["after"], strict=True)):
            writer.writerow(
                [
                    t["index"],
                    int(t["accepted"]),
                    mode_text(t["contact_sought"]),
                    t["score"],
                    t["count"],
                    i,
                    *b["X_WM"]["xyz"],
                    *a["X_WM"]["xyz"],
                    *a["X_WM"]["quat_xyzw"],
                    ";".join("|".join(c) for c in a["contacts"]),
                ]
            )
    return buffer.getvalue()
