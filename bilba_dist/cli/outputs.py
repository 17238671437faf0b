"""Where sub-commands write. An output never overwrites a file the command reads (the task,
the plan, the log) nor another of its outputs: that is refused in one line before any work.
An output's folder is made, as `bilba plan --out` makes its own, and a path that cannot be
written is one line, not a traceback."""

import errno
import os
from pathlib import Path

from bilba_dist.errors import BilbaError
from bilba_dist.files import clip_name


def same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file (through links, `..` or hard links)."""
    try:
        return os.path.samefile(a, b)
    except OSError:  # one does not exist (yet)
        return a.resolve() == b.resolve()


def task_file(task: str) -> dict[str, Path]:
    """TASK as an input to protect: the task file when TASK names one, else nothing."""
    return {"the task file": Path(task)} if Path(task).is_file() else {}


def refuse_overwriting(outputs: dict[str, Path | None], inputs: dict[str, Path]) -> None:
    """Raise when an output (``{option: path}``) is one of the ``inputs`` (``{what: path}``)
    or another output."""
    named = [(option, path) for option, path in outputs.items() if path is not None]
    for i, (option, path) in enumerate(named):
        _check_name(path, option)
        for what, source in inputs.items():
            if same_file(path, source):
                raise BilbaError(f"{option} {path} is {what}: writing it would destroy it")
        for other, earlier in named[:i]:
            if same_file(path, earlier):
                raise BilbaError(f"{other} and {option} name one file, {path}: give each its own")


def _check_name(path: Path, option: str = "") -> None:
    """One line, before the work, for a path the file system cannot hold (a name over its
    limit, 255 bytes on most): otherwise the work's result is lost when it is written."""
    try:
        os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ENAMETOOLONG:
            where = f"{option} " if option else ""
            raise BilbaError(f"{where}{clip_name(path)}: file name too long") from None


def make_folder(path: Path) -> None:
    """Make the folder ``path`` goes in; one line when that cannot be done or the folder
    cannot be written into (said before the work whose result goes there)."""
    _check_name(path)
    if path.parent.exists() and not path.parent.is_dir():
        raise BilbaError(f"{path}: {path.parent} is a file, not a folder")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BilbaError(f"{path}: cannot make its folder: {exc.strerror or exc}") from None
    if not os.access(path.parent, os.W_OK):
        raise BilbaError(f"{path}: cannot write into {path.parent}")


def write_output(path: Path, data: bytes | str) -> None:
    """Write ``data`` to ``path`` (its folder made); one line when that fails."""
    make_folder(path)
    try:
        if isinstance(data, bytes):
            path.write_bytes(data)
        else:
            path.write_text(data, encoding="utf-8")
    except OSError as exc:
        raise BilbaError(f"{path}: cannot write: {exc.strerror or exc}") from None
