"""The command line: parse, call the library, turn every user error into one line and exit 2."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from sensorimotor.errors import InputError
from sensorimotor.sim.core import MAX_SEED
from sensorimotor.version import __version__

app = typer.Typer(
    name="sensorimotor",
    help="Representation learning by sensorimotor prediction: simulate, train, analyse, report.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
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


@app.command()
def generate(
    world: WorldArg,
    steps: Annotated[int, typer.Option(help="Number of steps (rows) to record.")] = 1_000_000,
    seed: Annotated[
        int, typer.Option(min=0, max=MAX_SEED, help="Seed of the random generator (PCG64).")
    ] = 0,
    out: Annotated[
        Path | None, typer.Option(help="Output .npz (default: WORLD_sSEED.npz).")
    ] = None,
    noise: Annotated[float, typer.Option(help="Std of Gaussian noise added to readings.")] = 0.0,
) -> None:
    """Record a database of the paper's random wall-avoiding behaviour in WORLD."""
    from sensorimotor.files import check_writable
    from sensorimotor.sim.database import check_memory, save_database
    from sensorimotor.sim.database import generate as generate_db
    from sensorimotor.sim.world import load_world

    if steps < 1:
        raise InputError(f"--steps must be at least 1, got {steps}")
    if not (noise >= 0 and noise < float("inf")):
        raise InputError(f"--noise must be a non-negative number, got {noise}")
    w = load_world(world)
    out = out or Path(f"{w.name}_s{seed}.npz")
    check_writable(out)
    check_memory(steps)
    with progress_bar() as bar:
        task = bar.add_task(f"generate {w.name}", total=steps)
        db = generate_db(
            w, steps, seed, noise_std=noise, progress=lambda n: bar.update(task, completed=n)
        )
    save_database(db, out)
    err_console.print(f"wrote {out} ({steps:,} steps of {w.name}, seed {seed})")


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
    from sensorimotor.learn.models import MODEL_KINDS

    if model not in MODEL_KINDS:
        raise InputError(f"unknown model {model!r}: use one of {', '.join(MODEL_KINDS)}")
    return model


@app.command()
def train(
    model: ModelArg,
    data: Annotated[Path, typer.Option(help="Database (.npz) from `sensorimotor generate`.")],
    out: Annotated[Path, typer.Option(help="Run folder to write (weights, config, history).")],
    seed: Annotated[
        int, typer.Option(min=0, max=MAX_SEED, help="Seed of the initial weights and data order.")
    ] = 0,
    max_epochs: Annotated[
        int | None, typer.Option(help="Cap on epochs (default: none, early stopping alone).")
    ] = None,
    max_minutes: Annotated[
        float | None, typer.Option(help="Cap on training minutes (default: none).")
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
) -> None:
    """Train one encoder by predicting the next reading (Adam, batch 64, early stopping)."""
    from sensorimotor.learn.runs import TrainConfig

    _check_model(model)
    seed_list = None if seeds is None else _parse_seeds(seeds)
    if seed_list is not None and seed != 0:
        raise InputError("--seed and --seeds: give one or the other")
    if max_epochs is not None and max_epochs < 1:
        raise InputError(f"--max-epochs must be at least 1, got {max_epochs}")
    if max_minutes is not None and not max_minutes > 0:
        raise InputError(f"--max-minutes must be positive, got {max_minutes}")
    config = TrainConfig(
        model=model, seed=seed, max_epochs=max_epochs, max_minutes=max_minutes, device=device
    )

    if seed_list is None:
        seed_list, out_note = [seed], f"seed {seed}"
    else:
        out_note = f"seeds {','.join(map(str, seed_list))}"
    _train(model, data, out, config, seed_list, out_note, resume, single=seeds is None)


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


def _autograd_note(model: str) -> str:
    """What the training header adds when the model trains with autograd (an edited models.py)."""
    from sensorimotor.learn.fast.stacked_engine import computes_models_py

    if computes_models_py(model):
        return ""
    return f", with autograd: models.py's {model} is not what the stacked passes compute"


def epoch_line(r, stopper, seed: int | None = None, max_minutes: float | None = None) -> str:
    """One epoch of one run, as `train` and `reproduce` print it."""
    mark = "*" if r.improved else " "
    left = ""
    if max_minutes is not None:
        left = f"  {max(0.0, 60 * max_minutes - r.elapsed) / 60:.1f} min left under the cap"
    return (
        f"{'' if seed is None else f's{seed} '}epoch {r.epoch:3d}{mark} "
        f"train {r.train_error:.5f}  val {r.val_error:.5f}  "
        f"best {stopper.lowest:.5f} (epoch {stopper.best_epoch})  "
        f"{r.samples_per_s / 1e3:,.0f} k samples/s  {r.seconds:.1f} s  "
        f"patience {stopper.patience - stopper.waited}{left}"
    )


def _train(model, data: Path, out: Path, config, seeds: list[int], note: str, resume, single):
    """`train`: one run folder (OUT itself with --seed; one per seed under OUT with --seeds),
    a line per seed and epoch, a line per finished run."""
    from sensorimotor.learn.models import MODEL_NAMES
    from sensorimotor.learn.train import train, train_seeds, trains_stacked

    started: list[bool] = []

    def on_epoch(seed, r, stopper) -> None:
        if not started:  # the header waits for the first epoch: input errors stay one line
            started.append(True)
            how = (
                ""
                if single
                else ", "
                + ("stacked" if trains_stacked(model, config.device) else "one after another")
            )
            err_console.print(
                f"training {MODEL_NAMES[model]} on {data} ({note}{how}{_autograd_note(model)}) "
                f"-> {out}"
            )
        err_console.print(epoch_line(r, stopper, None if single else seed, config.max_minutes))

    if single:
        one = train(data, out, config, resume, lambda r, st: on_epoch(seeds[0], r, st))
        results = [one]
    else:
        results = train_seeds(data, out, config, seeds, resume=resume, on_epoch=on_epoch)
    for seed, result in zip(seeds, results, strict=True):
        where = "" if single else f" -> {result.run_dir}"
        err_console.print(
            f"done{'' if single else f' s{seed}'}: {result.ending}, best validation error "
            f"{result.best_val_error:.6f} at epoch {result.best_epoch}"
            f"{f' ({result.seconds:.0f} s)' if single else where}"
        )


@app.command()
def evaluate(
    run_dir: Annotated[Path, typer.Argument(help="Run folder from `sensorimotor train`.")],
    data: Annotated[list[Path], typer.Option(help="Databases to test on (repeatable).")],
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Also write the results as JSON.")
    ] = None,
) -> None:
    """Test-split prediction error of a trained model on one or more databases, with baselines."""
    import json

    from rich.table import Table

    from sensorimotor.files import check_writable, write_text_atomic
    from sensorimotor.learn.evaluate import evaluate_run, load_run
    from sensorimotor.learn.models import MODEL_NAMES
    from sensorimotor.sim.database import load_database

    if json_out is not None:
        check_writable(json_out)
    run = load_run(run_dir)
    dbs = [load_database(p) for p in data]
    res = evaluate_run(run, dbs)
    table = Table(
        title=f"{MODEL_NAMES[run.kind]} trained on {run.trained_on}: test error (sum over sensors)"
    )
    for col in ("test world", "model", "mean baseline", "copy-last baseline"):
        table.add_column(col, justify="right")
    for world, err in res["errors"].items():
        b = res["baselines"][world]
        table.add_row(world, f"{err:.5f}", f"{b['mean']:.5f}", f"{b['copy_last']:.5f}")
    Console().print(table)
    if json_out is not None:
        write_text_atomic(json_out, json.dumps(res, indent=2))


@app.command()
def table(
    run_dirs: Annotated[list[Path], typer.Argument(help="Run folders (several seeds allowed).")],
    data: Annotated[list[Path], typer.Option(help="Test databases, one per world (repeatable).")],
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Also write the table as JSON.")
    ] = None,
) -> None:
    """Table I: rows = models, columns = test worlds, mean +- sd over seeds, the paper beside."""
    import json

    from rich.table import Table

    from sensorimotor.analysis.tables import PAPER_TABLE_I, build_table, fmt_cell
    from sensorimotor.files import check_writable, write_text_atomic
    from sensorimotor.learn.evaluate import load_run
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
        paper = {w: trained_on == "square" and w in PAPER_TABLE_I["s"] for w in worlds}
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
                    cells.append(f"{PAPER_TABLE_I[row['model']][w]:g}")
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
    if json_out is not None:
        write_text_atomic(json_out, json.dumps(result, indent=2))


def _save_plot(fig, out: Path, svg: bool) -> None:
    from sensorimotor.sim.plots import save_figure

    for path in save_figure(fig, out, svg=svg):
        err_console.print(f"wrote {path}")


def _check_png(out: Path) -> Path:
    from sensorimotor.files import check_writable

    if out.suffix.lower() != ".png":
        raise InputError(f"{out}: --out must be a .png file")
    return check_writable(out)


@plot_app.command("world")
def plot_world_cmd(
    worlds: Annotated[
        list[str],
        typer.Argument(help="Worlds, side by side: square, rooms1, rooms2, or .toml paths."),
    ],
    out: PlotOut = Path("worlds.png"),
    svg: PlotSvg = False,
) -> None:
    """Fig. 1: the walls of each WORLD, side by side."""
    from sensorimotor.report.figures import worlds_figure
    from sensorimotor.sim.world import load_world

    _check_png(out)
    _save_plot(worlds_figure([load_world(w) for w in worlds]), out, svg)


@plot_app.command("trajectory")
def plot_trajectory_cmd(
    data: Annotated[
        list[Path], typer.Option(help="Database (.npz); repeat for panels side by side.")
    ],
    steps: Annotated[int, typer.Option(help="Steps drawn from the start of each.")] = 10_000,
    out: PlotOut = Path("trajectories.png"),
    svg: PlotSvg = False,
) -> None:
    """Fig. 2: the agent's path over the first STEPS rows of each database, in its world."""
    from sensorimotor.report.figures import trajectories_figure
    from sensorimotor.sim.database import load_database

    if steps < 1:
        raise InputError(f"--steps must be at least 1, got {steps}")
    _check_png(out)
    _save_plot(trajectories_figure([load_database(p) for p in data], steps), out, svg)


@plot_app.command("perception")
def plot_perception_cmd(
    data: Annotated[Path, typer.Option(help="Database (.npz) to take the situations from.")],
    row: Annotated[
        list[int] | None,
        typer.Option(help="Draw these rows instead of the five situations; repeatable."),
    ] = None,
    view: Annotated[
        float, typer.Option(help="Half-width of the window around the agent (units); 0: all.")
    ] = 7.5,
    out: PlotOut = Path("perception.png"),
    svg: PlotSvg = False,
) -> None:
    """Fig. 3: what the agent perceives (5 red dots) in the paper's five situations.

    The situations (nothing, line, corner, wall at its left, wall end) are found in the
    database by pose and readings; a wall end needs a world with inner walls (rooms1).
    """
    from sensorimotor.report.figures import perception_figure, pick_situations
    from sensorimotor.sim.database import load_database

    if not (view >= 0 and math.isfinite(view)):
        raise InputError(f"--view must be a non-negative number, got {view}")
    _check_png(out)
    db = load_database(data)
    if row:
        bad = [r for r in row if not 0 <= r < len(db)]
        if bad:
            raise InputError(f"{data}: row {bad[0]} is outside the database (0..{len(db) - 1})")
        situations = {f"row {r}": r for r in row}
    else:
        situations = pick_situations(db)
        if not situations:
            raise InputError(f"{data}: none of the paper's five situations occurs in it")
    _save_plot(perception_figure(db, situations, view=view or None), out, svg)


@app.command()
def analyze(
    run: Annotated[
        str,
        typer.Argument(
            help="A run folder made by `sensorimotor train`, or `raw` for the 5 readings / 10."
        ),
    ],
    data: Annotated[Path, typer.Option(help="Database whose test split is analysed (.npz).")],
    out: Annotated[Path, typer.Option(help="Output folder for the figures and metrics.json.")],
    fit_data: Annotated[
        Path | None,
        typer.Option(
            help="Fit PCA and k-means on this database's test split and apply them to --data "
            "(transfer)."
        ),
    ] = None,
    seed: Annotated[
        int, typer.Option(min=0, max=MAX_SEED, help="Seed of k-means, the probes and the drawings.")
    ] = 0,
    svg: Annotated[bool, typer.Option(help="Also save each figure as SVG.")] = True,
) -> None:
    """Cluster a representation (k-means, k = 20), score it against ground-truth events, draw it.

    RUN is a run folder or `raw` (the readings themselves); the test split of --data is analysed;
    with --fit-data, PCA and k-means are fitted on that database and applied to --data (transfer).
    Writes pca.png, clusters.png (with --fit-data also clusters_fit.png: the clusters on the
    fitting world), their SVGs, pca.npz and metrics.json into --out, and removes those files of
    an earlier analysis there that this one does not write.
    """
    from sensorimotor.analysis import analyze_files, summary_lines

    with err_console.status(f"analysing {run} on {data}"):
        result = analyze_files(run, data, out, fit_data, seed, svg=svg)
    m = result.metrics
    if m["fit_analysis"] is not None:
        print(f"{m['model']}, fitted on {m['fit_data']}:")
        print("\n".join(summary_lines(m["fit_analysis"])))
        print(f"{m['model']}, transferred to {m['data']}:")
    else:
        print(f"{m['model']} on {m['data']}:")
    print("\n".join(summary_lines(m["analysis"])))
    err_console.print("wrote " + ", ".join(str(p) for p in result.files), soft_wrap=True)


@app.command("map")
def map_cmd(
    run: Annotated[str, typer.Argument(help="A run folder, or `raw` for the 5 readings / 10.")],
    data: Annotated[Path, typer.Option(help="Database: the map is fitted on its train split.")],
    out: Annotated[Path, typer.Option(help="Output folder for map.json, GraphML, figures.")],
    clusters: Annotated[int, typer.Option(help="Cells: k of k-means (2..200).")] = 20,
    clones: Annotated[int, typer.Option(help="Clones per cell (1..100, K C <= 2000).")] = 20,
    fit_data: Annotated[
        Path | None, typer.Option(help="Fit the cells' k-means on this database (transfer).")
    ] = None,
    seed: Annotated[int, typer.Option(min=0, max=MAX_SEED, help="Seed of k-means and EM.")] = 0,
    pairs: Annotated[int, typer.Option(help="Start/goal pairs planned in the simulator.")] = 100,
) -> None:
    """Learn a map from a representation's cells: the cell graph and a cloned HMM (EM, Viterbi),
    scored on the test split (bits/step, localisation, rooms); see analysis/mapping.py."""
    from sensorimotor.analysis.mapping import check_settings, map_files, summary_lines

    check_settings(clusters, clones)
    with err_console.status(f"mapping {run} on {data}") as status:
        note = lambda stage, i, ll: status.update(f"mapping: {stage} {i}, {ll:.4f} nats/step")  # noqa: E731
        result = map_files(
            run, data, out, clusters, clones, fit_data, seed, pairs=pairs, progress=note
        )
    print("\n".join(summary_lines(result.metrics)))
    err_console.print("wrote " + ", ".join(str(p) for p in result.files), soft_wrap=True)


@app.command()
def reproduce(
    scale: Annotated[
        str,
        typer.Option(
            help="smoke: 20,000-step databases, 2 epochs a model, 1 seed (about a minute; it "
            "tests the pipeline, not the paper). quick: 200,000 steps, epochs capped at 10 (S, "
            "SM), 30 (Rec-S), 80 (Rec-SM), 1 seed (a few minutes). paper: the paper's protocol, "
            "1,000,000 steps, early stopping, 5 seeds (35-50 min on 2 CPU cores, by CPU)."
        ),
    ] = "quick",
    out: Annotated[Path, typer.Option(help="Output folder (cached stages are reused).")] = Path(
        "runs/reproduce"
    ),
    seeds: Annotated[
        int | None,
        typer.Option(
            help="How many seeds per model and world, 0..N-1 (a count, unlike train's list; "
            "default: the scale's)."
        ),
    ] = None,
    device: Annotated[str, typer.Option(help="auto, cpu or cuda.")] = "cpu",
    workers: Annotated[
        int | None, typer.Option(help="Parallel worker processes (default: the number of cores).")
    ] = None,
    worlds: Annotated[
        str,
        typer.Option(
            help="Worlds to train and analyse in, comma-separated: any of square, rooms1, rooms2 "
            "(the paper's Table I: square). Every model is tested on all three."
        ),
    ] = "square,rooms1,rooms2",
) -> None:
    """Reproduce the paper: databases, the four models on the three worlds, Table I, the analysis, a report."""
    from sensorimotor.report.reproduce import reproduce as reproduce_all
    from sensorimotor.report.workers import default_workers

    rep = reproduce_all(
        out,
        scale,
        seeds,
        device,
        workers if workers is not None else default_workers(),
        log=err_console.print,
        argv=sys.argv,
        worlds=[w.strip() for w in worlds.split(",") if w.strip()],
    )
    done = f"done in {rep.timings['total']['seconds']:.0f} s: {rep.out / 'report.html'} and {rep.out / 'report.md'}"
    holds = rep.table["paper_ordering_holds"].get("square")
    if holds:
        done += "; paper ordering on Square-trained models: " + ", ".join(
            f"{w} {'holds' if v else 'fails'}" for w, v in holds.items() if v is not None
        )
    err_console.print(done)


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


def main() -> None:
    """Entry point: every user error (a bad file, a bad option) is one line on stderr, exit 2."""
    # typer carries click's exceptions (vendored in recent releases): find them by name
    base = {c.__name__: c for c in typer.BadParameter.__mro__}
    usage_error, click_exception = base["UsageError"], base["ClickException"]
    try:
        rc = app(standalone_mode=False)
    except InputError as err:
        print(f"error: {err}", file=sys.stderr)
        sys.exit(2)
    except usage_error as err:
        message = err.format_message().strip()
        if message:  # empty when no arguments were given: the help has been shown
            hint = f" (try `{err.ctx.command_path} --help`)" if err.ctx is not None else ""
            print(f"error: {message}{hint}", file=sys.stderr)
        sys.exit(2)
    except click_exception as err:
        print(f"error: {err.format_message()}", file=sys.stderr)
        sys.exit(err.exit_code)
    except (typer.Abort, KeyboardInterrupt):
        rc = INTERRUPTED
    if rc == INTERRUPTED:  # typer turns Ctrl-C into this exit code
        print(
            "interrupted: what finished is kept and nothing is half-written; run the same command "
            "again to go on (train: add --resume)",
            file=sys.stderr,
        )
    sys.exit(rc if isinstance(rc, int) else 0)
