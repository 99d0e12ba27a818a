"""The command line: parse, call the library, turn every user error into one line and exit 2."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from sensorimotor import __version__
from sensorimotor.errors import InputError

app = typer.Typer(
    name="sensorimotor",
    help="Representation learning by sensorimotor prediction: simulate, train, analyse, report.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
err_console = Console(stderr=True)

WorldArg = Annotated[
    str, typer.Argument(help="World: square, rooms1, rooms2, or the path of a .toml world file.")
]


def progress_bar(description: str, total: int) -> Progress:
    """A rich progress bar on stderr (silent when stderr is not a terminal and CI is set)."""
    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:,}/{task.total:,}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err_console,
        transient=False,
    )


@app.command()
def generate(
    world: WorldArg,
    steps: Annotated[int, typer.Option(help="Number of steps (rows) to record.")] = 1_000_000,
    seed: Annotated[int, typer.Option(help="Seed of the random generator (PCG64).")] = 0,
    out: Annotated[
        Path | None, typer.Option(help="Output .npz (default: WORLD_sSEED.npz).")
    ] = None,
    noise: Annotated[float, typer.Option(help="Std of Gaussian noise added to readings.")] = 0.0,
) -> None:
    """Record a database of the paper's random wall-avoiding behaviour in WORLD."""
    from sensorimotor.data import check_writable, save_database
    from sensorimotor.data import generate as generate_db
    from sensorimotor.world import load_world

    if steps < 1:
        raise InputError(f"--steps must be at least 1, got {steps}")
    if noise < 0 or noise != noise:
        raise InputError(f"--noise must be a non-negative number, got {noise}")
    w = load_world(world)
    out = out or Path(f"{w.name}_s{seed}.npz")
    check_writable(out)
    with progress_bar(f"generate {w.name}", steps) as bar:
        task = bar.add_task(f"generate {w.name}", total=steps)
        db = generate_db(
            w, steps, seed, noise_std=noise, progress=lambda n: bar.update(task, completed=n)
        )
    save_database(db, out)
    err_console.print(f"wrote {out} ({steps:,} steps of {w.name}, seed {seed})")


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


def main() -> None:
    """Entry point: every InputError becomes one line on stderr and exit code 2."""
    try:
        app()
    except InputError as err:
        print(f"error: {err}", file=sys.stderr)
        sys.exit(2)
