"""The command line's application, its shared options and helpers; the commands live in
the modules beside this one, one per layer of the package."""

from __future__ import annotations

import functools
import inspect
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from sensorimotor.errors import InputError
from sensorimotor.files import DATABASE as DATABASE_WHAT
from sensorimotor.files import RUN_FOLDER, check_input, check_input_dir
from sensorimotor.learn.kinds import KINDS
from sensorimotor.sim import MAX_LASER_RANGE
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


def writes(folder: str | None = None, files: tuple[str, ...] = (), locked_inside: bool = False):
    """Declare what a command writes, where it is declared (``tests/test_hostile.py`` checks
    that every command does): ``folder``, the parameter naming a folder it writes, locked
    (``files.lock_folder``: the same lock and refusal as ``train``'s run folder) before the
    command's first byte, or by the library it calls (``locked_inside``: ``train``, whose run
    folders are locked one by one); ``files``, the parameters naming single files it writes
    (atomically, never through a link or a device: ``files.atomic_path``)."""

    def decorate(fn):
        signature = inspect.signature(fn)

        @functools.wraps(fn)
        def command(*args, **kwargs):
            if folder is None or locked_inside:
                return fn(*args, **kwargs)
            from sensorimotor.files import lock_folder

            bound = signature.bind(*args, **kwargs)
            bound.apply_defaults()
            with lock_folder(Path(bound.arguments[folder]), "output folder"):
                return fn(*args, **kwargs)

        command.__writes__ = {"folder": folder, "files": files, "locked_inside": locked_inside}
        return command

    return decorate


@dataclass(frozen=True)
class Input:
    """What a command's path parameter reads: a file or a folder, named as the library's
    messages name it, and the words it takes instead of a path (``raw``)."""

    what: str
    folder: bool = False
    words: tuple[str, ...] = ()


DATABASE = Input(DATABASE_WHAT)
RUN = Input(RUN_FOLDER, folder=True, words=("raw",))  # analysis.analyze.RAW


def reads(**inputs: Input):
    """Declare what a command's path parameters read (a list parameter: each path): each is
    checked through ``files.check_input`` or ``files.check_input_dir`` before the command's
    body, so a missing or wrong input is refused in one line before its imports (torch alone
    takes seconds). The library checks them again where it opens them."""

    def decorate(fn):
        signature = inspect.signature(fn)

        @functools.wraps(fn)
        def command(*args, **kwargs):
            bound = signature.bind(*args, **kwargs)
            bound.apply_defaults()
            for name, given in inputs.items():
                value = bound.arguments[name]
                for path in value if isinstance(value, list) else [value]:
                    if path is None or str(path) in given.words:
                        continue
                    check = check_input_dir if given.folder else check_input
                    check(path, given.what)
            return fn(*args, **kwargs)

        command.__reads__ = dict(inputs)
        return command

    return decorate


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


# the bounds of the numeric options, each what a run of that size costs at most (checked as
# the options are parsed, before any work; `--help` states them)
MAX_STEPS = 100_000_000  # rows of a database: 1.2 GB of 5 rays, 100 x the paper's
MAX_RANGE = MAX_LASER_RANGE  # units a laser reads: 20 x the largest built-in world
MAX_FOV = 6.2832  # rad: a full turn (2 pi, checked exactly by the layout)
MAX_NOISE = 100.0  # std of the reading noise: 10 x the paper's range
MAX_MOTOR_NOISE = 10.0  # std of the motor noise: 10 x the longest step
MAX_RATE = 10_000.0  # Hz of a recording's rows: 250 x a fast laser's
MAX_SCALE = 1_000.0  # units a metre of a recording: millimetres
MAX_VIEW = 10_000.0  # units around the agent in a drawing
MAX_SEEDS = 100  # seeds of a grid (the paper: 5)
MAX_WORKERS = 1_024  # jobs at a time
MAX_EPOCHS = 1_000_000
MAX_MINUTES = 525_600.0  # a year
MAX_AGENT_STEPS = 100_000_000  # environment steps of one agent (PPO: days at 1,000/s)
MAX_EPISODES = 10_000  # episodes of one evaluation
MAX_PAIRS = 3_000  # start/goal pairs a map plans (analysis.map.planning.MAX_PAIRS)
MAX_CLUSTERS, MAX_CLONES, MAX_CONTEXTS = 200, 200, 16  # a map's (analysis.map.mapping)
MAX_EM_ITERS = 1_000  # a map's EM iterations: each is a pass over the training split, n C^2
N_CONTEXTS = 2  # the default --contexts: analysis.map.context.N_CONTEXTS (tests check it)
RESOLUTION, MAX_RESOLUTION = 0.05, 100.0  # Louvain's for a map (analysis.map.graphs; checked)
MAX_ROOMS = 40  # a floor plan's rooms (sim.floorplan.MAX_ROOMS: about 5 s)
MAX_SIZE = 200.0  # a floor plan's side (sim.floorplan.MAX_SIZE)
MAX_DOOR = 100.0  # a doorway's width
MAX_CLEARANCE = 100.0  # units of free width an imported map keeps (sim.rosmap.CLEARANCE: 2)

ModelArg = Annotated[str, typer.Argument(help=f"Model: one of {', '.join(KINDS)}.")]


def _check_model(model: str) -> str:
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
