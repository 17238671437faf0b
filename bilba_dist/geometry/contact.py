"""Contact pairs: the unit of a contact set D(q) and of a mode."""

from typing import NamedTuple


class ContactPair(NamedTuple):
    """An (environment face, manipuland face) pair, each named ``piece/face``."""

    env: str
    manip: str

    def __str__(self) -> str:
        return "free" if self == ("free", "free") else f"({self.env}, {self.manip})"


ContactSet = frozenset[ContactPair]

#: The free mode: no contact. Face names always contain "/", so this never clashes.
FREE = ContactPair("free", "free")
