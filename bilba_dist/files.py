"""Reading a file a user names: a regular file only (a device or a pipe is refused before it
is opened: /dev/zero never ends, a FIFO blocks), at most ``limit`` bytes, and one line, not
a traceback, when it cannot be read."""

import stat
from os import PathLike
from pathlib import Path

from bilba_dist.errors import BilbaError

#: A path the Python API takes: a `str` as well as a `Path`.
PathArg = str | PathLike[str]


def read_bytes(
    path: Path, what: str, limit: int | None = None, error: type[BilbaError] = BilbaError
) -> bytes:
    """The bytes of ``path``, a ``what`` ("task file"), raising ``error`` in one line."""
    try:
        status = path.stat()
        if not stat.S_ISREG(status.st_mode):
            raise error(f"{path}: not a regular file; a {what} is expected")
        if limit is not None and status.st_size > limit:
            raise error(f"{path}: {status.st_size} bytes, over the {limit} byte limit for a {what}")
        with path.open("rb") as file:
            data = file.read() if limit is None else file.read(limit + 1)
        if limit is not None and len(data) > limit:  # a file growing while read
            raise error(f"{path}: over the {limit} byte limit for a {what}")
    except OSError as exc:
        raise error(f"{path}: cannot read {what}: {exc.strerror or exc}") from None
    return data


def clip_name(name: object, keep: int = 60) -> str:
    """A path for a one-line message: as it is, or its first ``keep`` characters and its
    length when it is long (a name too long for the file system, a path of thousands)."""
    text = str(name)
    return text if len(text) <= keep + 20 else f"{text[:keep]}… ({len(text)} characters)"
