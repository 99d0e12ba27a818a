"""Commands of the reinforcement-learning layer: agents that act on frozen encoders."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from sensorimotor.cli.app import (
    MAX_AGENT_STEPS,
    MAX_EPISODES,
    MAX_SEEDS,
    MAX_WORKERS,
    app,
    err_console,
    progress,
    writes,
)
from sensorimotor.cli.reproduce import AddressOpt, BackendOpt
from sensorimotor.jobs.backend import check_backend, job_runner, run_all
from sensorimotor.rl import RUNS_ENV


@app.command()
@writes(folder="out")
def rl(
    task: Annotated[str, typer.Argument(help="corner, doorway, explore or homing.")],
    world: Annotated[str, typer.Option(help="World the agents learn in.")] = "rooms1",
    features: Annotated[
        str,
        typer.Option(
            help="Comma-separated: pose, raw, s, sm, rec-s, rec-sm, rec-sma, random, pose+raw."
        ),
    ] = "pose,raw,rec-sm,random",
    seeds: Annotated[
        int, typer.Option(min=1, max=MAX_SEEDS, help="Agents per feature set: seeds 0..N-1.")
    ] = 3,
    steps: Annotated[
        int, typer.Option(min=1, max=MAX_AGENT_STEPS, help="Environment steps per agent.")
    ] = 100_000,
    out: Annotated[Path, typer.Option(help="Output folder; run again to go on.")] = Path("rl"),
    runs: Annotated[
        Path | None,
        typer.Option(
            help="Folder of trained encoder runs ({world}__{kind}__s{seed}, as `reproduce` "
            "writes in OUT/runs); needed by s, sm, rec-s, rec-sm, rec-sma, no default.",
            envvar=RUNS_ENV,
        ),
    ] = None,
    trained_on: Annotated[str | None, typer.Option(help="Encoders' world [WORLD].")] = None,
    transfer: Annotated[str, typer.Option(help="Comma-separated worlds to test in.")] = "",
    eval_every: Annotated[
        int, typer.Option(min=1, max=MAX_AGENT_STEPS, help="Steps between evaluations.")
    ] = 5_000,
    eval_episodes: Annotated[
        int, typer.Option(min=1, max=MAX_EPISODES, help="Episodes an evaluation.")
    ] = 50,
    stats_steps: Annotated[
        int,
        typer.Option(
            min=0,
            max=MAX_AGENT_STEPS,
            help="Steps of the rollout whose statistics standardise the features (0: none).",
        ),
    ] = 10_000,
    backend: BackendOpt = "local",
    address: AddressOpt = None,
    workers: Annotated[
        int | None,
        typer.Option(
            min=1,
            max=MAX_WORKERS,
            help="Agents at a time (default: one, in this process; ray: every CPU).",
        ),
    ] = None,
) -> None:
    """PPO on frozen encoders' features (the paper's planned RL test): success per feature set."""
    from sensorimotor.rl import check_extra

    check_extra()
    from sensorimotor.rl.features import parse_features
    from sensorimotor.rl.results import summary_lines
    from sensorimotor.rl.runner import RLConfig, check_inputs, run_grid

    names = parse_features(features)
    worlds = tuple(w.strip() for w in transfer.split(",") if w.strip())
    config = RLConfig(task, world, tuple(names), seeds, steps,
                      None if runs is None else str(runs), trained_on,
                      worlds, eval_every, eval_episodes, stats_steps=stats_steps)  # fmt: skip
    check_inputs(config)  # before the progress bar: an error is one line
    check_backend(backend, address, workers)
    if backend == "ray" or (workers or 1) > 1:  # agents as jobs: worker processes, Ray tasks
        with job_runner(backend, address, workers) as (run_jobs, n):

            def run_agents(jobs):
                return run_all(
                    run_jobs, n, jobs, lambda name, msg: err_console.print(f"  {name}: {msg}")
                )

            result = run_grid(config, out, run_agents=run_agents)
        err_console.print(
            "\n".join([*summary_lines(result), f"wrote {out}/rl.json, rl.png"]), markup=False
        )
        return
    order = {(f, s): i for i, (f, s) in enumerate((f, s) for f in names for s in range(seeds))}
    with progress(f"rl {task}: environment steps", len(names) * seeds * steps) as update:
        result = run_grid(
            config, out, lambda f, s, n: update(order[f, s] * steps + n, f"{f} seed {s}")
        )
    err_console.print(
        "\n".join([*summary_lines(result), f"wrote {out}/rl.json, rl.png"]), markup=False
    )
