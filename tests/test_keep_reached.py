"""After a pruned edge the search goes on from the contact the belief had reached
(``keep_reached``, ours) instead of starting over from the initial belief (the paper's)."""

from bilba_dist.geometry.contact import FREE, ContactPair
from bilba_dist.planning.recorder import NullRecorder
from bilba_dist.task.loader import load_task
from bilba_dist.task.schema import PlannerParams


class Events(NullRecorder):
    def __init__(self) -> None:
        self.events: list[tuple[str, ContactPair]] = []

    def schedule(self, attempt: int, schedule: list[ContactPair]) -> None:
        self.events.append(("schedule", schedule[0]))

    def pruned(self, edge: tuple[ContactPair, ContactPair], reason: str) -> None:
        self.events.append(("pruned", edge[0]))


def test_the_paper_preset_starts_over_and_the_default_does_not():
    assert load_task("peg-in-hole").spec.planner.keep_reached
    assert not PlannerParams.model_validate({"preset": "paper"}).keep_reached


def test_after_an_edge_pruned_past_free_the_next_schedule_starts_where_the_belief_was():
    """Peg env.y ±2 cm, bilba-variable, seed 0 prunes an edge out of a contact every particle
    had reached; the schedule that follows starts at that contact, not at free."""
    from bilba_dist.planning.bilba import plan
    from bilba_dist.workers.rollout_worker import RolloutWorker

    task = load_task("peg-in-hole", ["env.y=2cm"])
    worker, events = RolloutWorker(task, "panda"), Events()
    result = plan(task, worker, "bilba-variable", 0, 300, recorder=events)
    worker.close()
    assert result.success
    after = [
        (mode, events.events[k + 1])
        for k, (kind, mode) in enumerate(events.events[:-1])
        if kind == "pruned" and mode != FREE
    ]
    assert after, f"no edge pruned past free: {events.events}"
    assert all(nxt == ("schedule", mode) for mode, nxt in after), after
