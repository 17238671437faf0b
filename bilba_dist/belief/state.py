"""A belief in motion: every particle with its current state and contact set, and the
score ``h(b, F) = #particles in F + λ·IOU(D_bel(b), D̃_bel(b))``.

"In F" is asked of a set ``accept`` of modes: the contact sought and the modes after it in
the schedule, so a motion that carries a particle past F (into the next contact, or the
goal) counts as progress rather than failure."""

from collections.abc import Sequence
from dataclasses import dataclass, replace

import pinocchio as pin

from bilba_dist.belief.particles import Particle
from bilba_dist.geometry.contact import ContactPair, ContactSet
from bilba_dist.rollout import Motion, ParticleState, RolloutRequest, RolloutResult

#: Weight of the contact-homogeneity term; in (0, 1) so it only breaks ties in the count.
LAMBDA = 0.5

Accept = frozenset[ContactPair]


@dataclass(frozen=True)
class Belief:
    particles: tuple[Particle, ...]
    states: tuple[ParticleState, ...]
    contacts: tuple[ContactSet, ...]
    #: The check particles (robust acceptance, planning/evaluate.py) at the same point of the
    #: plan: not planned on, but a motion is accepted only if it also brings them along.
    #: None when there are none, or when a posterior's were not simulated yet.
    check: "Belief | None" = None

    def __len__(self) -> int:
        return len(self.particles)

    def after(self, results: Sequence[RolloutResult]) -> "Belief":
        """The posterior: each particle's state and contacts after its rollout (its check
        particles not yet simulated: None)."""
        return Belief(
            self.particles,
            tuple(r.state for r in results),
            tuple(r.contacts for r in results),
        )

    def under(self, motion: Motion) -> list[RolloutRequest]:
        """The rollouts of ``motion`` from every particle's state (``after`` reads them)."""
        return [
            RolloutRequest(p, s, motion) for p, s in zip(self.particles, self.states, strict=True)
        ]

    def with_check(self, check: "Belief | None") -> "Belief":
        return replace(self, check=check)

    def __getitem__(self, part: slice) -> "Belief":
        """The belief of a slice of the particles."""
        return Belief(self.particles[part], self.states[part], self.contacts[part])

    def without(self, particles: Sequence[Particle]) -> "Belief":
        """The belief of the other particles, in their order (no check particles)."""
        kept = [i for i, p in enumerate(self.particles) if p not in particles]
        return Belief(
            tuple(self.particles[i] for i in kept),
            tuple(self.states[i] for i in kept),
            tuple(self.contacts[i] for i in kept),
        )

    def __add__(self, other: "Belief") -> "Belief":
        """The belief of both's particles, these first (no check particles: ``[:n]`` splits
        them again)."""
        return Belief(
            (*self.particles, *other.particles),
            (*self.states, *other.states),
            (*self.contacts, *other.contacts),
        )

    def X_OM(self, i: int) -> pin.SE3:
        """Particle ``i``'s manipuland in its environment frame."""
        return self.particles[i].X_WO.inverse() * self.states[i].X_WM

    def count(self, accept: Accept) -> int:
        """Particles whose contact set holds one of the ``accept`` modes; none at all once
        one particle's arm has stopped (a joint at its limit): the real robot would have
        halted the whole plan there, so such a motion is no progress for any particle."""
        if self.stopped():
            return 0
        return sum(bool(c & accept) for c in self.contacts)

    def score(self, accept: Accept) -> float:
        if self.stopped():
            return 0.0
        return self.count(accept) + LAMBDA * contact_iou(self.contacts)

    def stopped(self) -> list[int]:
        """The particles whose arm stopped with a reflex (`ParticleState.stopped`)."""
        return [i for i, s in enumerate(self.states) if s.stopped is not None]


def d_bel(contacts: Sequence[ContactSet]) -> ContactSet:
    """``D_bel``: the contacts every particle has."""
    return frozenset.intersection(*contacts) if contacts else frozenset()


def d_bel_union(contacts: Sequence[ContactSet]) -> ContactSet:
    """``D̃_bel``: the contacts some particle has."""
    return frozenset.union(*contacts) if contacts else frozenset()


def contact_iou(contacts: Sequence[ContactSet]) -> float:
    """IOU of D_bel and D̃_bel: 1 when all particles share one contact set (also all free)."""
    union = d_bel_union(contacts)
    return 1.0 if not union else len(d_bel(contacts)) / len(union)
