"""The command line: parse, call the library, turn every user error into one line and exit 2.

One module per layer of the package holds its commands (``data``, ``world``, ``learn``,
``analysis``, ``report``, ``rl``); importing them registers them on ``app.app``.
"""

from __future__ import annotations

import sys

import typer

from sensorimotor.cli import analysis, data, learn, reproduce, rl, world  # noqa: F401  (registers them)
from sensorimotor.cli.app import INTERRUPTED, app
from sensorimotor.errors import InputError


def main() -> None:
    """Entry point: every user error (a bad file, a bad option) is one line on stderr, exit 2."""
    sys.exit(run(sys.argv[1:]))


def run(argv: list[str]) -> int:
    """Run the command line on ``argv`` in this process and return its exit status: every
    user error one line on stderr and 2 (what ``main`` does; the tests call it directly)."""
    # typer carries click's exceptions (vendored in recent releases): find them by name
    base = {c.__name__: c for c in typer.BadParameter.__mro__}
    usage_error, click_exception = base["UsageError"], base["ClickException"]
    try:
        rc = app(args=list(argv), prog_name="sensorimotor", standalone_mode=False)
    except InputError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except usage_error as err:
        message = err.format_message().strip()
        if message:  # empty when no arguments were given: the help has been shown
            hint = f" (try `{err.ctx.command_path} --help`)" if err.ctx is not None else ""
            print(f"error: {message}{hint}", file=sys.stderr)
        return 2
    except click_exception as err:
        print(f"error: {err.format_message()}", file=sys.stderr)
        return err.exit_code
    except (typer.Abort, KeyboardInterrupt):
        rc = INTERRUPTED
    if rc == INTERRUPTED:  # typer turns Ctrl-C into this exit code
        print(
            "interrupted: what finished is kept and nothing is half-written; run the same command "
            "again to go on (train: add --resume)",
            file=sys.stderr,
        )
    return rc if isinstance(rc, int) else 0
