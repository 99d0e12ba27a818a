"""Commands that run many jobs: reproduce the paper, sweep training settings."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from sensorimotor.cli.app import (
    MAX_SEEDS,
    MAX_WORKERS,
    app,
    err_console,
    writes,
)

BackendOpt = Annotated[str, typer.Option(help="local: worker processes here; ray: Ray tasks.")]
AddressOpt = Annotated[str | None, typer.Option(help="Ray cluster to join (default: start one).")]


@app.command()
@writes(folder="out")
def reproduce(
    scale: Annotated[
        str,
        typer.Option(
            help="smoke: 20,000-step databases, 2 epochs a model, 1 seed (under a minute; it "
            "tests the pipeline, not the paper). quick: 200,000 steps, epochs capped at 10 (S, "
            "SM), 30 (Rec-S), 80 (Rec-SM), 40 (Rec-SMA, --experiment memory), 1 seed (2-4 min "
            "on 2 CPU cores; the report names "
            "the claims it is too small for). paper: the paper's protocol, 1,000,000 steps, "
            "early stopping, 5 seeds (32-53 min on 2 CPU cores, by CPU: docs/benchmarks.md)."
        ),
    ] = "quick",
    out: Annotated[Path, typer.Option(help="Output folder (cached stages are reused).")] = Path(
        "runs/reproduce"
    ),
    seeds: Annotated[
        int | None,
        typer.Option(
            min=1,
            max=MAX_SEEDS,
            help="How many seeds per model and world, 0..N-1 (a count, unlike train's list; "
            "default: the scale's).",
        ),
    ] = None,
    device: Annotated[str, typer.Option(help="auto, cpu or cuda.")] = "cpu",
    workers: Annotated[
        int | None,
        typer.Option(
            min=1, max=MAX_WORKERS, help="Jobs at a time (default: every core, or every Ray CPU)."
        ),
    ] = None,
    worlds: Annotated[
        str,
        typer.Option(
            help="Worlds to train and analyse in, comma-separated: any of square, rooms1, rooms2 "
            "(the paper's Table I: square). Every model is tested on all three."
        ),
    ] = "square,rooms1,rooms2",
    backend: BackendOpt = "local",
    address: AddressOpt = None,
    experiment: Annotated[
        str | None,
        typer.Option(
            help="Experiments past the paper to run after its stages, comma-separated, each "
            "with its own report section: map (a map learned from the cells), gridmap (the "
            "map in its own regime: the grid behaviour, rooms and plans on fresh databases, 5 "
            "seeds at the paper's scale: about an hour on 2 workers), scaling (more "
            "rays, noise, unseen floor plans), rl (PPO agents on the Rooms1 encoders), walls "
            "(Table I over wall layouts that fit the paper's sentences), real (a real robot's "
            "log and a real campus map), memory (Rec-SMA, a memory that reads the motor "
            "commands, and its ablations: do they know the room and the position?), homing "
            "(PPO agents that must come back to a room they cannot see, in Rooms1 and Rooms2: "
            "raw, Rec-SM, Rec-SMA, the pose alone and the oracle pose+raw), behaviour (Table I's ordering, the corner cell and the memory under a smooth "
            "random motion, on Square). Default: none."
        ),
    ] = None,
) -> None:
    """Reproduce the paper: databases, the four models on the three worlds, Table I, the analysis, a report."""
    from sensorimotor.reproduce import reproduce as reproduce_all

    rep = reproduce_all(
        out,
        scale,
        seeds,
        device,
        workers,
        log=err_console.print,
        argv=sys.argv,
        worlds=[w.strip() for w in worlds.split(",") if w.strip()],
        backend=backend,
        address=address,
        experiments=None if experiment is None else [e.strip() for e in experiment.split(",")],
    )
    done = f"done in {rep.timings['total']['seconds']:.0f} s: {rep.out / 'report.html'} and {rep.out / 'report.md'}"
    holds = rep.table["paper_ordering_holds"].get("square")
    if holds:
        done += "; paper ordering on Square-trained models: " + ", ".join(
            f"{w} {'holds' if v else 'fails'}" for w, v in holds.items() if v is not None
        )
    err_console.print(done)


@app.command()
@writes(folder="out")
def sweep(
    spec: Annotated[Path, typer.Argument(help="Sweep file: data, [train], [space], [asha].")],
    out: Annotated[Path, typer.Option(help="Sweep folder: runs/trial_NNN, sweep.csv/.md/.png.")],
    backend: BackendOpt = "local",
    address: AddressOpt = None,
    workers: Annotated[
        int | None,
        typer.Option(min=1, max=MAX_WORKERS, help="Trials at a time (default: all CPUs)."),
    ] = None,
    resume: Annotated[bool, typer.Option(help="Go on with the sweep in --out.")] = False,
) -> None:
    """Search training settings (grid, or random with a seed); on Ray, ASHA ends poor trials early."""
    from sensorimotor.pipeline.sweep import run_sweep

    result = run_sweep(spec, out, backend, address, workers, resume, log=err_console.print)
    err_console.print(f"wrote {', '.join(map(str, result.files))}")
    if result.best_command is not None:  # the best trial, trained again
        print(result.best_command)
