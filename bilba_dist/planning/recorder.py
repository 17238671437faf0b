"""What the planner reports as it goes, for a log (`bilba_dist.record.writer.LogWriter`)."""

from typing import Protocol

from bilba_dist.belief.state import Belief
from bilba_dist.geometry.contact import ContactPair
from bilba_dist.planning.result import Verification
from bilba_dist.rollout import Motion


class Recorder(Protocol):
    def schedule(self, attempt: int, schedule: list[ContactPair]) -> None: ...

    def pruned(self, edge: tuple[ContactPair, ContactPair], reason: str) -> None: ...

    def transition(
        self,
        mode: ContactPair,
        motion: Motion,
        before: Belief,
        after: Belief,
        score: float,
        count: int,
        accepted: bool,
    ) -> None: ...

    def gp_round(
        self, mode: ContactPair, training_size: int, predicted: float, simulated: float
    ) -> None: ...

    def verified(self, verification: Verification) -> None: ...

    def restarted(self, points: int, particles: int, reason: str) -> None: ...

    def resumed(self, contact: ContactPair, motions: int) -> None: ...


class NullRecorder:
    """Records nothing (``--no-log``)."""

    def schedule(self, attempt: int, schedule: list[ContactPair]) -> None:
        pass

    def pruned(self, edge: tuple[ContactPair, ContactPair], reason: str) -> None:
        pass

    def transition(self, *args: object, **kwargs: object) -> None:
        pass

    def gp_round(self, *args: object, **kwargs: object) -> None:
        pass

    def verified(self, verification: Verification) -> None:
        pass

    def restarted(self, points: int, particles: int, reason: str) -> None:
        pass

    def resumed(self, contact: ContactPair, motions: int) -> None:
        pass
