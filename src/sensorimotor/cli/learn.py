"""Commands of the learning layer: train (one seed or several), evaluate, Table I."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console

from sensorimotor.cli.app import (
    DATABASE,
    MAX_EPOCHS,
    MAX_MINUTES,
    RUN,
    ModelArg,
    _check_model,
    app,
    err_console,
    reads,
    writes,
)
from sensorimotor.errors import InputError
from sensorimotor.learn.kinds import S
from sensorimotor.sim import MAX_SEED

if TYPE_CHECKING:
    from sensorimotor.learn.models import ModelConfig

SET_HELP = (
    "A setting KEY=VALUE, repeatable: lr, batch_size, horizon, ahead, ahead_every, slow_dims "
    "and slow_weight (rec-sma), patience, min_ratio; a model size: z_sensors, z_motors, "
    "rec_hidden, lstm_size, lstm_layers, predictor_hidden, transition_hidden; or "
    "memory_motors=false (rec-sma's ablation)."
)


@app.command()
@reads(data=DATABASE)
@writes(folder="out", locked_inside=True)
def train(
    model: ModelArg,
    data: Annotated[Path, typer.Option(help="Database (.npz) from `sensorimotor generate`.")],
    out: Annotated[Path, typer.Option(help="Run folder to write (weights, config, history).")],
    seed: Annotated[
        int, typer.Option(min=0, max=MAX_SEED, help="Seed of the initial weights and data order.")
    ] = 0,
    max_epochs: Annotated[
        int | None,
        typer.Option(
            min=1, max=MAX_EPOCHS, help="Cap on epochs (default: none, early stopping alone)."
        ),
    ] = None,
    max_minutes: Annotated[
        float | None,
        typer.Option(min=0, max=MAX_MINUTES, help="Cap on training minutes (default: none)."),
    ] = None,
    device: Annotated[str, typer.Option(help="auto, cpu or cuda.")] = "cpu",
    resume: Annotated[
        bool, typer.Option(help="Continue the run in --out from its last epoch.")
    ] = False,
    seeds: Annotated[
        str | None,
        typer.Option(
            help="Train several seeds at once, stacked, e.g. 0,1,2,3,4 (rec-s, rec-sm on CUDA: "
            "one after another). --out is then a parent folder of {world}__{model}__s{seed} "
            "run folders."
        ),
    ] = None,
    settings: Annotated[list[str] | None, typer.Option("--set", help=SET_HELP)] = None,
) -> None:
    """Train one encoder by predicting the next reading (Adam, batch 64, early stopping)."""
    from sensorimotor.learn.config import TrainConfig
    from sensorimotor.learn.runs import apply_settings

    _check_model(model)
    seed_list = None if seeds is None else _parse_seeds(seeds)
    if seed_list is not None and seed != 0:
        raise InputError("--seed and --seeds: give one or the other")
    if max_epochs is not None and max_epochs < 1:
        raise InputError(f"--max-epochs must be at least 1, got {max_epochs}")
    if max_minutes is not None and not max_minutes > 0:
        raise InputError(f"--max-minutes must be positive, got {max_minutes}")
    config = TrainConfig.of(
        model, seed=seed, max_epochs=max_epochs, max_minutes=max_minutes, device=device
    )
    config, sizes = apply_settings(config, settings or [])

    if seed_list is None:
        seed_list, out_note = [seed], f"seed {seed}"
    else:
        out_note = f"seeds {','.join(map(str, seed_list))}"
    _train(model, data, out, config, seed_list, out_note, resume, seeds is None, sizes)


def _parse_seeds(text: str) -> list[int]:
    """``--seeds 0,1,2``: integers separated by commas, at least one, none twice."""
    from sensorimotor.learn.train import check_seeds

    if not text.strip():
        raise InputError("--seeds: give at least one seed, e.g. 0,1,2,3,4")
    values = []
    for item in text.split(","):
        try:
            values.append(int(item.strip()))
        except ValueError:
            raise InputError(
                f"--seeds: {item.strip()!r} is not an integer (e.g. 0,1,2,3,4)"
            ) from None
        if not 0 <= values[-1] <= MAX_SEED:
            raise InputError(f"--seeds: {values[-1]} is outside 0..{MAX_SEED}")
    return check_seeds(values)


def _engine_note(model: ModelConfig | str, device: str, single: bool) -> str:
    """How the training header says the seeds of ``model`` (a kind, or a ModelConfig of its
    sizes) train: stacked, or each with autograd (and why, where ``models.py`` was edited into
    a model the stacked passes do not compute)."""
    from sensorimotor.learn.engine import computes_models_py
    from sensorimotor.learn.train import trains_stacked

    if trains_stacked(model, device):
        return "" if single else ", stacked"
    if computes_models_py(model):
        return ", with autograd"
    kind = getattr(model, "kind", model)
    return f", with autograd: models.py's {kind} is not what the stacked passes compute"


def epoch_line(
    r, stopper, seed: int | None = None, max_minutes: float | None = None, max_epochs=None
) -> str:
    """One epoch of one run, as `train` prints it. The mark says what early stopping counted:
    ``*`` an improvement by the paper's rule (below ``min_ratio`` x the last counted error:
    patience starts again), ``+`` a new lowest error that is not one (its weights are kept,
    patience still runs down); the line ends with the error the next improvement needs."""
    from sensorimotor.learn.runs import epoch_label

    mark = "*" if r.improved else ("+" if r.best else " ")
    left = ""
    if max_minutes is not None:
        left = f"  {max(0.0, 60 * max_minutes - r.elapsed) / 60:.1f} min left under the cap"
    return (
        f"{'' if seed is None else f's{seed} '}{epoch_label(r.epoch, max_epochs)}{mark} "
        f"train {r.train_error:.5f}  val {r.val_error:.5f}  "
        f"best {stopper.lowest:.5f} (epoch {stopper.best_epoch})  "
        f"{r.samples_per_s / 1e3:,.0f} k samples/s  {r.seconds:.1f} s  "
        f"patience {stopper.patience - stopper.waited} for val < "
        f"{stopper.min_ratio * stopper.reference:.5f}{left}"
    )


def _train(model, data: Path, out: Path, config, seeds: list[int], note, resume, single, sizes):
    """`train`: one run folder (OUT itself with --seed; one per seed under OUT with --seeds),
    a line per seed and epoch, a line per finished run."""
    from sensorimotor.learn.models import KINDS
    from sensorimotor.learn.train import train, train_seeds

    started: list[bool] = []

    def on_epoch(seed, r, stopper) -> None:
        if not started:  # the header waits for the first epoch: input errors stay one line
            started.append(True)
            how = _engine_note(sizes or model, config.device, single)
            err_console.print(f"training {KINDS[model].label} on {data} ({note}{how}) -> {out}")
            err_console.print(
                f"early stopping: * an improvement (val below {config.min_ratio:g} x the last "
                f"counted one), + a new lowest that is not; stops after {config.patience} epochs "
                "without *",
                highlight=False,
            )
        line = epoch_line(
            r, stopper, None if single else seed, config.max_minutes, config.max_epochs
        )
        err_console.print(line)

    if single:
        one = train(data, out, config, resume, lambda r, st: on_epoch(seeds[0], r, st), sizes)
        results = [one]
    else:
        results = train_seeds(data, out, config, seeds, resume, on_epoch, sizes)
    for seed, result in zip(seeds, results, strict=True):
        where = "" if single else f" -> {result.run_dir}"
        err_console.print(
            f"done{'' if single else f' s{seed}'}: {result.ending}, best validation error "
            f"{result.best_val_error:.6f} at epoch {result.best_epoch}"
            f"{f' ({result.seconds:.0f} s)' if single else where}"
        )


@app.command()
@reads(run_dir=RUN, data=DATABASE)
@writes(files=("json_out",))
def evaluate(
    run_dir: Annotated[Path, typer.Argument(help="Run folder from `sensorimotor train`.")],
    data: Annotated[list[Path], typer.Option(help="Databases to test on (repeatable).")],
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Also write the results as JSON.")
    ] = None,
) -> None:
    """Test-split prediction error of a trained model on one or more databases, with baselines."""

    from rich.table import Table

    from sensorimotor.files import check_writable, write_json_atomic
    from sensorimotor.learn.evaluate import baseline_warnings, evaluate_run, load_run
    from sensorimotor.learn.models import KINDS
    from sensorimotor.sim.database import load_database

    if json_out is not None:
        check_writable(json_out)
    run = load_run(run_dir)
    dbs = [load_database(p) for p in data]
    res = evaluate_run(run, dbs)
    table = Table(
        title=f"{KINDS[run.kind].label} trained on {run.trained_on}: test error (sum over sensors)"
    )
    for col in ("test world", "model", "mean baseline", "copy-last baseline"):
        table.add_column(col, justify="right")
    for world, err in res["errors"].items():
        b = res["baselines"][world]
        table.add_row(world, f"{err:.5f}", f"{b['mean']:.5f}", f"{b['copy_last']:.5f}")
    Console().print(table)
    for line in baseline_warnings(run.path.name, res["errors"], res["baselines"]):
        err_console.print(f"[yellow]warning: {line}", highlight=False)
    if json_out is not None:
        write_json_atomic(json_out, res)


@app.command()
@reads(run_dirs=RUN, data=DATABASE)
@writes(files=("json_out",))
def table(
    run_dirs: Annotated[list[Path], typer.Argument(help="Run folders (several seeds allowed).")],
    data: Annotated[list[Path], typer.Option(help="Test databases, one per world (repeatable).")],
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Also write the table as JSON.")
    ] = None,
) -> None:
    """Table I: rows = models, columns = test worlds, mean +- sd over seeds, the paper beside."""

    from rich.table import Table

    from sensorimotor.analysis.tables import PAPER_TABLE_I, build_table, fmt_cell
    from sensorimotor.files import check_writable, write_json_atomic
    from sensorimotor.learn.evaluate import baseline_warnings, load_run
    from sensorimotor.sim.database import load_database

    if json_out is not None:
        check_writable(json_out)
    runs = [load_run(r) for r in run_dirs]
    dbs = [load_database(p) for p in data]
    result = build_table(runs, dbs)
    worlds = result["worlds"]
    for trained_on, rows in result["tables"].items():
        # the paper's number beside a cell only where the paper has one: Square-trained models
        # tested on one of its worlds
        paper = {w: trained_on == "square" and w in PAPER_TABLE_I[S] for w in worlds}
        t = Table(title=f"Table I: test error, trained on {trained_on} (mean ± sd over seeds)")
        t.add_column("model")
        for w in worlds:
            t.add_column(w, justify="right")
            if paper[w]:
                t.add_column("paper", justify="right", style="dim")
        for row in rows:
            cells = [row["name"]]
            for w in worlds:
                cells.append(fmt_cell(row["cells"].get(w)))
                if paper[w]:
                    value = PAPER_TABLE_I.get(row["model"], {}).get(w)
                    cells.append("" if value is None else f"{value:g}")
            t.add_row(*cells)
        for name in ("mean", "copy_last"):
            cells = [f"baseline: {name.replace('_', '-')}"]
            for w in worlds:
                cells += [f"{result['baselines'][w][name]:.5f}"] + ([""] if paper[w] else [])
            t.add_row(*cells, style="dim")
        holds = result["paper_ordering_holds"][trained_on]
        cells = ["Rec-SM < SM < S, Rec-S"]  # the paper's ordering, column by column
        for w in worlds:
            cells += [{True: "holds", False: "fails", None: "n/a"}[holds[w]]] + (
                [""] if paper[w] else []
            )
        t.add_row(*cells)
        Console(width=max(100, Console().width)).print(t)
        for row in rows:
            errors = {w: c["mean"] for w, c in row["cells"].items()}
            for line in baseline_warnings(row["name"], errors, result["baselines"]):
                err_console.print(f"[yellow]warning: {line}", highlight=False)
    if json_out is not None:
        write_json_atomic(json_out, result)
