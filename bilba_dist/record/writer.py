"""Writing one planning job's MCAP log: chunked and indexed, and crash-safe.

Indexed readers (what viewers use to seek, e.g. `@mcap/core`'s `McapIndexedReader`) find
messages only through chunk indexes, so the log is chunked. mcap's Python writer keeps a chunk
in memory until it is full or `finish()` runs, and a killed process loses it
(docs/reference-values.md: 2557 of 3000 messages survived with 64 KiB chunks); so each
recorder hook ends its chunk and flushes it (`Writer.flush`): a planner killed mid-plan loses
at most the transition in progress, and `bilba logs recover` restores the rest.
"""

import json
import platform
import time
from importlib import metadata
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.writer import CompressionType, Writer

from bilba_dist.belief.state import Belief
from bilba_dist.errors import BilbaError
from bilba_dist.files import PathArg
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.geometry.pose import pose_json, setpoint_json
from bilba_dist.planning.result import Verification, verification_json
from bilba_dist.record.foxglove import SCHEMAS as FOXGLOVE_SCHEMAS
from bilba_dist.record.foxglove import SceneMessages
from bilba_dist.record.schemas import TOPICS
from bilba_dist.rollout import Motion
from bilba_dist.task.loader import Task

PROFILE = "bilba"


def particles(belief: Belief) -> list[dict[str, Any]]:
    return [
        {
            "X_WM": pose_json(s.X_WM),
            "contacts": sorted([list(c) for c in contacts]),
            "q": [float(v) for v in s.q],
            **({"stopped": s.stopped} if s.stopped else {}),
            **({"arm_touches": list(s.arm_touches)} if s.arm_touches else {}),
        }
        for s, contacts in zip(belief.states, belief.contacts, strict=True)
    ]


def versions() -> dict[str, str]:
    found = {}
    for name in ("bilba-dist", "numpy", "scipy", "pin", "pybullet", "ray", "scikit-learn", "mcap"):
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "absent"
    found["python"] = platform.python_version()
    return found


class LogWriter:
    """One MCAP file per planning job; implements the planner's recorder hooks."""

    def __init__(
        self, path: PathArg, task: Task, planner: str, seed: int, robot: bool = True
    ) -> None:
        """``robot``: draw the Panda in the scene (its particles' joint angles are meaningful
        only on the Panda model)."""
        path = Path(path)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._file: IO[bytes] = path.open("wb")
        except OSError as exc:
            raise BilbaError(f"{path}: cannot write log: {exc.strerror or exc}") from None
        self.path = path
        # Uncompressed chunks: every MCAP reader handles them without a decompressor.
        self._writer = Writer(self._file, compression=CompressionType.NONE)
        self._writer.start(profile=PROFILE, library="bilba_dist")
        self._channels = {
            topic: self._writer.register_channel(
                topic,
                "json",
                self._writer.register_schema(
                    schema["title"], "jsonschema", json.dumps(schema).encode()
                ),
            )
            for topic, schema in {**TOPICS, **FOXGLOVE_SCHEMAS}.items()
        }
        self._scene = SceneMessages(task.manipuland, task.environment, robot)
        self._sequence = 0
        self.transitions = 0
        self._start_drawn = False
        header = {
            "task": {
                "name": task.name,
                "hash": task.hash,
                "source": task.source,
                "spec": task.spec.model_dump(mode="json"),
            },
            "planner": planner,
            "parameters": task.spec.planner.model_dump(mode="json"),
            "seed": seed,
            "versions": versions(),
            "host": platform.node(),
        }
        self._writer.add_metadata(
            "bilba",
            {"task": task.name, "task_hash": task.hash, "planner": planner, "seed": str(seed)},
        )
        self.write("/metadata", header)
        self.commit()

    def write(self, topic: str, message: dict[str, Any] | str, now: int | None = None) -> None:
        data = message if isinstance(message, str) else json.dumps(message, sort_keys=True)
        now = now or time.time_ns()
        self._sequence += 1
        self._writer.add_message(self._channels[topic], now, data.encode(), now, self._sequence)

    def commit(self) -> None:
        """End the chunk in progress and put it on disk: a kill from here loses nothing."""
        self._writer.flush()

    # The planner's recorder hooks.
    def schedule(self, attempt: int, schedule: list[ContactPair]) -> None:
        self.write("/schedule", {"attempt": attempt, "schedule": [list(m) for m in schedule]})
        self.commit()

    def pruned(self, edge: tuple[ContactPair, ContactPair], reason: str) -> None:
        self.write("/pruned", {"edge": [list(m) for m in edge], "reason": reason})
        self.commit()

    def transition(
        self,
        mode: ContactPair,
        motion: Motion,
        before: Belief,
        after: Belief,
        score: float,
        count: int,
        accepted: bool,
    ) -> None:
        if not self._start_drawn:
            self.draw(before)  # the start belief (after a restart: where the new search starts)
            self._start_drawn = True
        self.write(
            "/transition",
            {
                "index": self.transitions,
                "contact_sought": list(mode),
                "motion": {
                    "K": np.asarray(motion.K).tolist(),
                    "G_d": setpoint_json(motion.G_d),
                    "timeout_s": motion.timeout_s,
                },
                "before": particles(before),
                "after": particles(after),
                "score": score,
                "count": count,
                "accepted": accepted,
            },
        )
        self.transitions += 1
        if accepted:
            self.draw(after)
        self.commit()

    def draw(self, belief: Belief) -> None:
        """The belief as a Foxglove scene, at the start and after each accepted motion: the
        parts and the arm (again each time, so a player that seeks past the start still has
        them) and every particle's frames."""
        now = time.time_ns()
        self.write("/scene", self._scene.scene(len(belief), now), now)
        for i, particle in enumerate(belief.particles):
            self.write("/tf", self._scene.transform(f"env_{i}", particle.X_WO, now), now)
        for i, (particle, state) in enumerate(zip(belief.particles, belief.states, strict=True)):
            self.write("/tf", self._scene.transform(f"part_{i}", state.X_WM, now), now)
            for tf in self._scene.robot_transforms(i, state.q, now, particle.X_GM):
                self.write("/tf", tf, now)

    def gp_round(
        self, mode: ContactPair, training_size: int, predicted: float, simulated: float
    ) -> None:
        self.write(
            "/gp_round",
            {
                "contact_sought": list(mode),
                "training_size": training_size,
                "predicted_best": predicted,
                "simulated_best": simulated,
            },
        )
        self.commit()

    def verified(self, verification: Verification) -> None:
        self.write("/verify", verification_json(verification))
        self.commit()

    def restarted(self, points: int, particles: int, reason: str) -> None:
        """The search starts again on ``points`` particles a bounded axis (``particles`` in
        all): its start belief is drawn again at its next transition."""
        self.write("/restart", {"points": points, "particles": particles, "reason": reason})
        self._start_drawn = False
        self.commit()

    def resumed(self, contact: ContactPair, motions: int) -> None:
        """The restarted search goes on from ``contact``, which the first ``motions`` motions
        of the plan before it made for the new particles too."""
        self.write("/resume", {"contact": str(contact), "motions": motions})
        self.commit()

    def finish(self, plan_text: str, outcome: dict[str, Any]) -> None:
        """The plan (the plan file's exact text) and the outcome, then the summary section."""
        self.write("/plan", plan_text)
        self.write("/outcome", outcome)
        self.close()

    def close(self) -> None:
        """End the file with what it holds, readable as it is (a search cut short by Ctrl-C
        or by Ray dying has no plan or outcome); a second call does nothing."""
        if not self._file.closed:
            self._writer.finish()
            self._file.close()
