"""A sweep's results, read from its run folders: the table (CSV, Markdown), the figure of
validation error against each searched setting, and the ``train`` command of a trial.

Everything here reads files the runs wrote (``history.csv``, ``result.json``), so the
results of a sweep stopped half-way, or of trials ASHA ended early, are what is on disk.
"""

from __future__ import annotations

import csv
import io
import math
import shlex
from pathlib import Path

from sensorimotor.files import MAX_TEXT_BYTES, check_input, read_json_if_any
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.models import ModelConfig
from sensorimotor.learn.runs import SETTABLE

COLUMNS = ("best_val_error", "best_epoch", "epochs", "stopped")


def trial_row(name: str, values: dict, run: Path, ended: str, failed: bool) -> dict:
    """One trial's row: its searched values, its best validation error (None before its first
    epoch), at which epoch, its epochs, and how it stopped: the run's own reason, ``failed``,
    or ``ended`` (no result.json: ended by ASHA, or unfinished)."""
    errors = []
    history = run / "history.csv"
    if history.exists() or history.is_symlink():
        check_input(history, "training history", MAX_TEXT_BYTES)  # a FIFO: refused, not read
        try:
            with open(history, newline="") as f:
                errors = [float(r["val_error"]) for r in csv.DictReader(f)]
        except (OSError, KeyError, ValueError):
            pass
    try:
        stopped = read_json_if_any(run / "result.json", "run result")["stopped"]
    except (KeyError, TypeError):
        stopped = ended
    finite = [i for i, e in enumerate(errors) if math.isfinite(e)]  # a diverged epoch: NaN
    best = min(finite, key=errors.__getitem__) if finite else None
    return {
        "trial": name,
        **values,
        "best_val_error": None if best is None else errors[best],
        "best_epoch": best,
        "epochs": len(errors),
        "stopped": "failed" if failed else stopped,
        "run": str(run),
    }


def results_csv(rows: list[dict], keys: list[str]) -> str:
    """``sweep.csv``: one row per trial, in trial order; an empty cell where there is no value."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, ["trial", *keys, *COLUMNS, "run"], lineterminator="\n")
    writer.writeheader()
    writer.writerows([{k: ("" if v is None else v) for k, v in r.items()} for r in rows])
    return buf.getvalue()


def results_markdown(
    spec: Path, search: str, rows: list[dict], keys: list[str], best: str | None, backend: str
) -> str:
    """``sweep.md``: the trials best first, and the command that trains the best again."""
    how = "ASHA early termination on the validation error" if backend == "ray" else "every trial"
    how += " to its end" if backend != "ray" else ""
    lines = [
        f"# Sweep: {spec.name}",
        "",
        f"{len(rows)} trials, {search} search over {', '.join(keys)} ({backend} backend, {how}).",
        "Best validation error of each trial (mean squared error of the next reading).",
        "",
        "| " + " | ".join(["trial", *keys, *COLUMNS]) + " |",
        "|" + "---|" * (len(keys) + len(COLUMNS) + 1),
    ]
    for r in rows:
        cells = [r["trial"], *(_label(r[k]) for k in keys)]
        err = r["best_val_error"]
        cells += ["" if err is None else f"{err:.6f}", _label(r["best_epoch"]), str(r["epochs"])]
        lines.append("| " + " | ".join([*cells, r["stopped"]]) + " |")
    if best is not None:
        lines += ["", f"The best trial, {rows[0]['trial']}, trained again:", "", "```", best, "```"]
    return "\n".join(lines) + "\n"


def _label(value) -> str:
    if value is None:
        return ""
    if isinstance(value, str) and value.endswith(".npz"):
        return Path(value).stem  # a database: its name
    return f"{value:g}" if isinstance(value, float) else str(value)


def save_sweep_figure(rows: list[dict], space: dict, path: Path) -> list[Path]:
    """``sweep.png``: one panel per searched setting (``space``: the sweep file's), each
    trial's best validation error against the setting's value; a list's values are named on
    the axis, a range's axis is log for ``log_uniform`` (and for a list of positive numbers
    spanning 10 x); trials that did not finish (ASHA, a kill) are hollow."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    from sensorimotor.sim.plots import save_figure

    keys = list(space)
    fig, axes = plt.subplots(1, len(keys), figsize=(3.6 * len(keys), 3.2), squeeze=False)
    done = [r for r in rows if r["best_val_error"] is not None]
    errors = [r["best_val_error"] for r in done]
    for ax, key in zip(axes[0], keys, strict=True):
        values = [r[key] for r in done]
        listed = space[key] if isinstance(space[key], list) else None
        numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)
        if numeric:
            x = [float(v) for v in values]
            spread = listed and min(listed) > 0 and max(listed) >= 10 * min(listed)
            if spread or "log_uniform" in space[key]:
                ax.set_xscale("log")
                ax.xaxis.set_minor_formatter(NullFormatter())  # 2e-4, 3e-4, ... would overlap
            if listed:  # a list's values, named
                ax.set_xticks([float(v) for v in listed], [_label(v) for v in listed])
                ax.minorticks_off()
        else:
            labels = [_label(v) for v in listed or dict.fromkeys(values)]
            x = [labels.index(_label(v)) for v in values]
            ax.set_xticks(range(len(labels)), labels)
            ax.set_xlim(-0.5, len(labels) - 0.5)
        for xi, r in zip(x, done, strict=True):
            finished = r["stopped"] in ("early stopping", "max epochs", "time cap")
            ax.scatter(
                xi,
                r["best_val_error"],
                s=36,
                facecolors="C0" if finished else "none",
                edgecolors="C0",
            )
        if done:  # the best trial, ringed
            k = min(range(len(done)), key=errors.__getitem__)
            ax.scatter(x[k], errors[k], s=140, facecolors="none", edgecolors="C3", linewidths=1.5)
        ax.set_xlabel(key)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("best validation error")
    if errors and min(errors) > 0 and max(errors) >= 10 * min(errors):
        for ax in axes[0]:
            ax.set_yscale("log")
    fig.suptitle("Best validation error by setting (red ring: the best trial; hollow: ended early)")
    fig.tight_layout()
    try:
        return save_figure(fig, path)
    finally:
        plt.close(fig)


def command_line(data: str, config: dict, sizes: dict, out: str = "runs/best") -> str:
    """The ``sensorimotor train`` command that trains a trial again (``config``: a
    TrainConfig as a dict; ``sizes``: the model's, where not the paper's) into ``out``: the
    settings that differ from the paper's."""
    words = ["sensorimotor", "train", config["model"], "--data", data, "--out", out]
    words += ["--seed", str(config["seed"])]
    if config["max_epochs"] is not None:
        words += ["--max-epochs", str(config["max_epochs"])]
    if config["max_minutes"] is not None:
        words += ["--max-minutes", str(config["max_minutes"])]
    default = TrainConfig.of(config["model"])  # the kind's own settings need no --set
    for key in SETTABLE:  # a setting a trial does not record ran at its default
        value = config.get(key, getattr(default, key))
        if value != getattr(default, key):
            words += ["--set", f"{key}={value!r}"]
    paper = ModelConfig(kind=config["model"])
    for key, value in sizes.items():
        if value != getattr(paper, key):
            words += ["--set", f"{key}={value}"]
    return shlex.join(words)
