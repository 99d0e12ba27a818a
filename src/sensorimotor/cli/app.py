"""The command line's application, its shared options and helpers; the commands live in
the modules beside this one, one per layer of the package."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from sensorimotor.errors import InputError
from sensorimotor.version import __version__

app = typer.Typer(
    name="sensorimotor",
    help="Representation learning by sensorimotor prediction: simulate, train, analyse, report.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help text is plain: "[train]" is a TOML table, not Rich markup
)
err_console = Console(stderr=True, soft_wrap=True)

WorldArg = Annotated[
    str, typer.Argument(help="World: square, rooms1, rooms2, or the path of a .toml world file.")
]


def progress_bar() -> Progress:
    """A rich progress bar on stderr."""
    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:,}/{task.total:,}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err_console,
        transient=False,
    )


LOG_EVERY = 10.0  # seconds: the most often a progress line goes into a log (a file, CI, nohup)


@contextmanager
def progress(description: str, total: int | None = None) -> Iterator[Callable[..., None]]:
    """The command line's one progress display for long work. In a terminal: a bar with its
    total and time left (without a total, a spinner showing the latest message). Into a log
    (stderr not a terminal): the first update, then a line at most every ``LOG_EVERY`` seconds,
    and the last. Yields ``update(done=None, message="")``."""
    if err_console.is_terminal:
        if total is None:
            with err_console.status(description) as status:
                yield lambda done=None, message="": status.update(f"{description}: {message}")
            return
        with progress_bar() as bar:
            task = bar.add_task(description, total=total)

            def update(done: int | None = None, message: str = "") -> None:
                text = f"{description}: {message}" if message else description
                bar.update(task, description=text, **({} if done is None else {"completed": done}))

            yield update
        return
    state = {"last": -LOG_EVERY, "line": None}

    def update(done: int | None = None, message: str = "") -> None:
        of = "" if done is None else f" {done:,}" + ("" if total is None else f" of {total:,}")
        state["line"] = f"{description}{of}" + (f": {message}" if message else "")
        now = time.monotonic()
        if now - state["last"] >= LOG_EVERY:
            err_console.print(state["line"], highlight=False, markup=False)
            state["last"], state["line"] = now, None

    yield update
    if state["line"] is not None:
        err_console.print(state["line"], highlight=False, markup=False)


plot_app = typer.Typer(
    help="Draw the paper's simulator figures as PNG: world (Fig. 1), trajectory (Fig. 2), "
    "perception (Fig. 3).",
    no_args_is_help=True,
)
app.add_typer(plot_app, name="plot")
PlotOut = Annotated[Path, typer.Option(help="Output .png (written atomically).")]
PlotSvg = Annotated[bool, typer.Option(help="Also write an .svg beside the .png.")]


ModelArg = Annotated[str, typer.Argument(help="Model: s, sm, rec-s or rec-sm.")]


def _check_model(model: str) -> str:
    from sensorimotor.learn.models import KINDS

    if model not in KINDS:
        raise InputError(f"unknown model {model!r}: use one of {', '.join(KINDS)}")
    return model


def version_callback(value: bool) -> None:
    if value:
        print(f"sensorimotor {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=version_callback, is_eager=True, help="Show the version."
        ),
    ] = False,
) -> None:
    """Representation learning by sensorimotor prediction (Kulak & Garcia Ortiz), reproduced."""


INTERRUPTED = 130  # the shell's code for a process ended by SIGINT
