"""How every `bilba` sub-command fails: bad input as one line and exit code 2, a bug of ours
as one line and exit code 3 (the traceback with BILBA_DEBUG=1), Ctrl-C as one line and exit
code 130."""

import errno
import os
import sys
from collections.abc import Callable
from functools import wraps
from typing import Any, TypeVar

import click

from bilba_dist.errors import BilbaError, first_line
from bilba_dist.files import clip_name

F = TypeVar("F", bound=Callable[..., Any])

#: Exit code for bad input (a malformed task, an impossible goal, a missing file).
EXIT_BAD_INPUT = 2


#: Exit code on Ctrl-C (what was finished is kept: a batch's records, a plan's log so far).
EXIT_INTERRUPTED = 130

#: Exit code for a failure of bilba itself (a bug): one line, the traceback with BILBA_DEBUG=1.
EXIT_INTERNAL = 3


def user_errors(command: F) -> F:
    """Turn a BilbaError into one line on stderr and exit code 2, never a traceback; any
    other exception is a bug of ours, also one line (exit 3) unless BILBA_DEBUG is set."""

    @wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except BrokenPipeError:  # stdout closed early (`bilba logs summary … | head`)
            sys.stderr.close()
            os._exit(0)
        except BilbaError as exc:
            click.echo(f"bilba: error: {exc}", err=True)
            sys.exit(EXIT_BAD_INPUT)
        except KeyboardInterrupt:  # `batch` and `plan` say first what they kept
            click.echo("interrupted", err=True)
            sys.exit(EXIT_INTERRUPTED)
        except (Exception, RecursionError) as exc:
            if isinstance(exc, OSError) and exc.errno == errno.ENAMETOOLONG:
                # a name the user gave, at any path check (Python 3.11's Path.exists raises)
                click.echo(f"bilba: error: {clip_name(exc.filename)}: file name too long", err=True)
                sys.exit(EXIT_BAD_INPUT)
            if os.environ.get("BILBA_DEBUG"):
                raise
            message = first_line(exc)
            click.echo(
                f"bilba: internal error: {type(exc).__name__}: {message} (a bug: please report "
                "it; BILBA_DEBUG=1 shows the traceback)",
                err=True,
            )
            sys.exit(EXIT_INTERNAL)

    return wrapper  # type: ignore[return-value]
