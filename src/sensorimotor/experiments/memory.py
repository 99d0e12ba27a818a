"""Does a memory that reads the motor commands know where the robot is?
``reproduce --experiment memory``.

The paper's recurrent encoders never see the commands in their memory, so they cannot integrate
the path. This trains Rec-SMA (``learn.models``: the memory reads the last command, and the
representation is trained to predict the readings ``ahead`` steps open loop) on each of the
reproduction's worlds, and on Rooms1 the ablations that each take one ingredient away
(``VARIANTS``). Every representation (the raw readings, the paper's four kinds, Rec-SMA and
its ablations) is then probed on a fresh database of each world, recorded with another seed
(``analysis.probes.place_probes``: the room by class-balanced logistic regression, x and y by
ridge regression, fitted on the fresh training split, scored on its test split after a burn-in
of 200 steps). The true pose through the same probes is the ceiling; the strongest of the
others is the baseline. Each number is the mean over seeds with its Student-t 95 % interval.

The thresholds are the issue's, written here before any model was trained (``THRESHOLDS``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sensorimotor.analysis.observer import PARTICLES, observe
from sensorimotor.errors import InputError
from sensorimotor.files import file_hash, read_json_if_any, write_json_atomic
from sensorimotor.jobs.cache import read_key, stage_key
from sensorimotor.jobs.workers import Job
from sensorimotor.learn.models import KINDS, REC_SM, REC_SMA, paper_kinds
from sensorimotor.learn.runs import run_name
from sensorimotor.pipeline.stages import data_job, run_matches, train_config, train_job
from sensorimotor.report.blocks import Block, h, image, p, table
from sensorimotor.stats import BEFORE, Verdict, interval, mean_sd, present
from sensorimotor.version import __version__

FRESH_SEED = 1  # the probes' databases: the reproduction's are seed 0
ROOMED = ("rooms1", "rooms2")  # the worlds that name rooms
ABLATED_ON = "rooms1"
POSE = "pose"  # the ceiling: (x, y, cos, sin) of the true pose through the same probes
OBSERVERS = {  # the ideal observer: does it read the commands, and its particles
    "observer": (True, PARTICLES),  # the count the rule's check kept (4,000 was too few)
    "observer-blind": (False, PARTICLES),
    "observer-4k": (True, 4000),
    "observer-blind-4k": (False, 4000),
}
SHOWN_OBSERVERS = ("observer", "observer-blind")  # rows of the experiment
OBSERVER_FIT = 20_000  # training-split steps the observer's probes are fitted on (its cost)
AHEAD = dict(KINDS[REC_SMA].training)["ahead"]  # the open-loop curve: every variant to Rec-SMA's K
WHERE = "issue 32 (an action-conditioned recurrent encoder), before any Rec-SMA was trained"


@dataclass(frozen=True)
class Variant:
    """Rec-SMA or one ablation of it: a setting of the same kind."""

    name: str  # its folder under OUT/memory/runs/
    label: str
    settings: tuple[tuple[str, int], ...] = ()  # TrainConfig's
    sizes: tuple[tuple[str, bool], ...] = ()  # ModelConfig's


VARIANTS = (
    Variant(REC_SMA, "Rec-SMA"),
    Variant("no-motor-memory", "no motors in the memory", sizes=(("memory_motors", False),)),
    Variant("one-step", "K = 1 (one step ahead)", settings=(("ahead", 1), ("ahead_every", 1))),
    # the paper's truncation and streams (4 streams of 20 steps make 40 times the updates of
    # 4 of 256 for the same samples: 1 k samples/s, a 2-hour quick run)
    Variant(
        "bptt-20",
        "backpropagation over 20 steps (64 streams)",
        settings=(("horizon", 20), ("batch_size", 64)),
    ),
)
MAIN = VARIANTS[0].name

THRESHOLDS = {  # set before the data (the "done when")
    "room": {"rooms1": 0.90, "rooms2": 0.85},
    "room_lower": 0.80,
    "r2": 0.8,
    "median_error": 5.0,
    "ablation_room": 0.60,
}


def _config(rep, variant: Variant, seed: int | None = None) -> dict:
    epochs = rep.scale.epochs(REC_SMA)
    return train_config(
        REC_SMA,
        rep.device,
        epochs,
        rep.scale.patience,
        seed,
        dict(variant.sizes),
        **dict(variant.settings),
    )


def probe_job(run: str, data: str, out: str, key: str) -> dict:
    """Probe one representation (a run folder, ``raw``, ``pose`` or an ideal observer of
    ``OBSERVERS``) on ``data``; with a run,
    also its one-step test error and, for a motor memory, its open-loop errors."""
    from sensorimotor.analysis.analyze import probe_places
    from sensorimotor.analysis.probes import place_probes
    from sensorimotor.learn.evaluate import (
        ahead_errors,
        baselines,
        load_run,
        model_error,
        split_tensors,
    )
    from sensorimotor.sim.database import load_database

    db = load_database(data)
    result: dict = {}
    if run == POSE or run in OBSERVERS:
        fit, test = db.take("train"), db.take("test")
        world = db.world
        if run == POSE:
            zf, z = pose_features(fit.poses), pose_features(test.poses)
        else:
            zf, z = (observer_features(db, q, *OBSERVERS[run]) for q in (fit, test))
        fit_poses = fit.poses[: len(zf)]
        rooms = [world.room_index(q[:, 0], q[:, 1]) for q in (fit_poses, test.poses)]
        size = (world.width, world.height)
        result["probes"] = place_probes(zf, fit_poses, z, test.poses, *rooms, size)
    else:
        loaded = run if run == "raw" else load_run(run)
        result["probes"] = probe_places(loaded, db)
        if run == "raw":
            result["baselines"] = baselines(db)
        else:
            s, m = split_tensors(db, "test")
            result["error"] = model_error(loaded.model, s, m)
            if loaded.model.config.motor_memory:
                result["ahead"] = ahead_errors(loaded.model, s, m, AHEAD).tolist()
    write_json_atomic(Path(out), {"key": key, "result": result})
    return result


def observer_features(db, split, commands: bool, particles: int) -> np.ndarray:
    """The ideal observer's belief (``analysis.observer``) over the first ``OBSERVER_FIT`` steps
    of a split of ``db``; ValueError for a database of another behaviour than the paper's
    when the observer draws the commands from it."""
    if not commands and db.behaviour != "paper":
        raise ValueError(
            f"{db.source}: the observer without commands knows the paper's behaviour only"
        )
    n = min(len(split), OBSERVER_FIT)
    return observe(db.world, split.sensors[:n], split.motors[:n], db.layout, commands, particles)


def pose_features(poses: np.ndarray) -> np.ndarray:
    """(N, 4) x, y, cos(heading), sin(heading): the true pose as the probes' ceiling reads it."""
    q = np.asarray(poses, dtype=np.float64)
    return np.stack([q[:, 0], q[:, 1], np.cos(q[:, 2]), np.sin(q[:, 2])], axis=1)


def run_of(rep, variant: Variant, world: str, seed: int) -> Path:
    """Where a variant's run lives: Rec-SMA's beside the paper's kinds in the reproduction's
    runs folder (``rep.run_dir``, where ``rl`` reads every encoder), an ablation's under
    ``OUT/memory/runs/{variant}/``."""
    if variant.name == MAIN:
        return Path(rep.run_dir(world, REC_SMA, seed))
    return Path(rep.out) / "memory" / "runs" / variant.name / run_name(world, REC_SMA, seed)


def train_jobs(rep, worlds, variants=VARIANTS) -> tuple[list[Job], dict]:
    """The training jobs of Rec-SMA on ``worlds`` and of its ablations on ``ABLATED_ON`` (those
    of ``variants``), every seed, but the runs kept; and every run's folder by (variant,
    world, seed). The one door to Rec-SMA's runs: ``--experiment homing`` trains its
    encoders through it, and a run either experiment made serves both."""
    jobs, runs = [], {}
    for variant in variants:
        for w in worlds if variant.name == MAIN else [w for w in worlds if w == ABLATED_ON]:
            data_sha = file_hash(rep.data[w])
            config = _config(rep, variant)
            for seed in range(rep.seeds):
                out = runs[(variant.name, w, seed)] = run_of(rep, variant, w, seed)
                if (out / "result.json").exists() and run_matches(
                    out, data_sha, {**config, "seed": seed}
                ):
                    continue
                out.parent.mkdir(parents=True, exist_ok=True)
                entry = (str(rep.data[w]), seed, str(out), data_sha)
                jobs.append(Job(f"train {variant.name} {out.name}", train_job, ([entry], config)))
    return jobs, runs


def run(ctx) -> dict:
    """Fresh databases, Rec-SMA and its ablations trained, every representation probed."""
    from sensorimotor.pipeline.stages import data_key

    rep = ctx.rep
    check(rep)
    d = ctx.dir
    for sub in ("data", "runs", "probes"):
        (d / sub).mkdir(parents=True, exist_ok=True)
    worlds = list(rep.worlds)
    steps = rep.scale.steps

    # 1. a fresh database of each world (another seed), and Rec-SMA and its ablations trained
    fresh = {w: d / "data" / f"{w}_s{FRESH_SEED}.npz" for w in worlds}
    jobs = []
    for w in worlds:
        key = stage_key({"fresh": data_key(w, steps), "seed": FRESH_SEED})
        if read_key(fresh[w].with_suffix(".json")) != key or not fresh[w].exists():
            jobs.append(Job(f"fresh {w}", data_job, (w, steps, FRESH_SEED, str(fresh[w]), key)))
    train, runs = train_jobs(rep, worlds)
    jobs += train
    jobs.sort(key=lambda job: not job.name.startswith("train"))  # the long ones first
    ctx.run(jobs)

    # 2. every representation probed on the fresh database of its world
    shown: dict[tuple[str, str, int], str] = {}  # (representation, world, seed) -> run or raw
    for w in worlds:
        shown[(POSE, w, 0)] = POSE
        for name in SHOWN_OBSERVERS:
            shown[(name, w, 0)] = name
        shown[("raw", w, 0)] = "raw"
        for kind in paper_kinds():
            for seed in range(rep.seeds):
                shown[(kind, w, seed)] = str(rep.run_dir(w, kind, seed))
    for (name, w, seed), out in runs.items():
        shown[(name, w, seed)] = str(out)
    hashes = {w: file_hash(fresh[w]) for w in worlds}
    files, jobs = {}, []
    for (name, w, seed), src in shown.items():
        if src in OBSERVERS:  # an observer's settings stand for its weights
            weights = f"{src} {OBSERVERS[src]}"
        elif src in (POSE, "raw"):
            weights = src
        else:
            weights = file_hash(Path(src) / "model.pt")
        key = stage_key({"run": weights, "data": hashes[w], "version": __version__})
        out = d / "probes" / f"{name}__{w}__s{seed}.json"
        files[(name, w, seed)] = out
        if read_key(out) != key:
            jobs.append(Job(f"probe {out.stem}", probe_job, (src, str(fresh[w]), str(out), key)))
    ctx.run(jobs)
    found = {k: read_json_if_any(f, "probe")["result"] for k, f in files.items()}
    numbers = _numbers(found, worlds, rep.seeds)
    numbers["figure"] = _figure(d, numbers)
    return numbers


def _cell(values: list) -> dict:
    """Mean, sd, n and the Student-t 95 % interval (None below two seeds) of ``values``."""
    v = present(values)
    if not v:
        return {"mean": None, "sd": None, "n": 0, "interval": None}
    mean, sd = mean_sd(v)
    ci = interval(v)  # None below two seeds
    return {"mean": mean, "sd": sd, "n": len(v), "interval": None if ci is None else list(ci)}


METRICS = {  # name -> how to read it from a probe result
    "room": lambda r: (r["probes"]["room"] or {}).get("balanced_accuracy"),
    "r2_x": lambda r: r["probes"]["position"]["r2"]["x"],
    "r2_y": lambda r: r["probes"]["position"]["r2"]["y"],
    "median_error": lambda r: r["probes"]["position"]["median_error"],
    "knn_mse": lambda r: r["probes"]["knn_mse"]["value"],
    "error": lambda r: r.get("error"),
}


def _numbers(found: dict, worlds: list[str], seeds: int) -> dict:
    """Per world and representation, each metric over seeds; the open-loop curves; verdicts."""
    names = [POSE, *SHOWN_OBSERVERS, "raw", *paper_kinds(), *(v.name for v in VARIANTS)]
    table_rows: dict[str, dict] = {}
    for w in worlds:
        rows = {}
        for name in names:
            results = [r for (n, ww, _), r in found.items() if n == name and ww == w]
            if results:
                rows[name] = {m: _cell([get(r) for r in results]) for m, get in METRICS.items()}
        table_rows[w] = rows
    curves = {
        v.name: np.mean(
            [r["ahead"] for (n, w, _), r in found.items() if n == v.name and w == ABLATED_ON],
            axis=0,
        ).tolist()
        for v in VARIANTS
        if any(n == v.name and w == ABLATED_ON for n, w, _ in found)
    }
    return {
        "worlds": worlds,
        "seeds": seeds,
        "rows": table_rows,
        "baselines": {w: r["baselines"] for (n, w, _), r in found.items() if n == "raw"},
        "curves": curves,
        "verdicts": [v.to_dict() for v in _verdicts(table_rows)],
    }


def _baseline(rows: dict, metric: str, higher: bool = True) -> str | None:
    """The strongest representation but the ceiling and Rec-SMA's variants, by ``metric``."""
    others = {n: r[metric]["mean"] for n, r in rows.items() if n in ("raw", *paper_kinds())}
    others = {n: v for n, v in others.items() if v is not None}
    if not others:
        return None
    return (max if higher else min)(others, key=others.get)


def _fmt(cell: dict | None, digits: int = 2) -> str:
    if cell is None or cell["mean"] is None:
        return "n/a"
    ci = cell["interval"]
    return f"{cell['mean']:.{digits}f}" + (
        "" if ci is None else f" [{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]"
    )


def _verdicts(rows: dict) -> list[Verdict]:
    t = THRESHOLDS
    out = []
    for w in ROOMED:
        main = rows.get(w, {}).get(MAIN)
        if main is None:
            continue
        room = main["room"]
        lower = None if room["interval"] is None else room["interval"][0]
        holds = None if room["mean"] is None else room["mean"] >= t["room"][w]
        if holds and lower is not None:
            holds = lower >= t["room_lower"]
        out.append(
            Verdict(
                claim=f"Rec-SMA's representation tells the room on a fresh {w} database",
                threshold=f"balanced accuracy >= {t['room'][w]:.2f}, interval's lower bound >= "
                f"{t['room_lower']:.2f}",
                test="class-balanced logistic probe, fitted on the fresh training split, "
                "scored on its test split after 200 steps; mean over seeds, Student-t 95 %",
                numbers=f"{_fmt(room)} (ceiling {_fmt(rows[w].get(POSE, {}).get('room'))}, "
                f"ideal observer {_fmt(rows[w].get('observer', {}).get('room'))})",
                holds=holds,
                provenance=BEFORE,
                where=WHERE,
            )
        )
        r2 = [main["r2_x"]["mean"], main["r2_y"]["mean"]]
        med = main["median_error"]["mean"]
        out.append(
            Verdict(
                claim=f"Rec-SMA's representation tells the position in {w}",
                threshold=f"x and y R^2 >= {t['r2']:.1f}, median error <= {t['median_error']:g}",
                test="ridge probe, as the room's",
                numbers=f"R^2 x {_fmt(main['r2_x'])}, y {_fmt(main['r2_y'])}; median error "
                f"{_fmt(main['median_error'], 1)}",
                holds=None
                if None in (*r2, med)
                else min(r2) >= t["r2"] and med <= t["median_error"],
                provenance=BEFORE,
                where=WHERE,
            )
        )
    ablated = rows.get(ABLATED_ON, {}).get("no-motor-memory")
    full = rows.get(ABLATED_ON, {}).get(MAIN, {}).get("room", {}).get("mean")
    if ablated is not None and ablated["room"]["mean"] is not None and full is not None:
        # a drop is the motors' doing only from a model that knows the room: not judged below
        reached = full >= t["room"][ABLATED_ON]
        out.append(
            Verdict(
                claim="Where Rec-SMA tells the room, its ablation without motors in the memory "
                "does not (the mechanism)",
                threshold=f"Rec-SMA >= {t['room'][ABLATED_ON]:.2f} and the ablation <= "
                f"{t['ablation_room']:.2f}, balanced room accuracy on {ABLATED_ON}",
                test="the same probe on the ablation's representation",
                numbers=f"ablation {_fmt(ablated['room'])}, Rec-SMA {full:.2f}; the ideal "
                "observer without the commands "
                f"{_fmt(rows[ABLATED_ON].get('observer-blind', {}).get('room'))}",
                holds=ablated["room"]["mean"] <= t["ablation_room"] if reached else None,
                provenance=BEFORE,
                where=WHERE,
            )
        )
    return out


LABELS = {
    POSE: "true pose (ceiling)",
    "observer": "ideal observer (ceiling for a memory)",
    "observer-blind": "ideal observer, no commands",
    "raw": "raw readings",
}


def _label(name: str) -> str:
    if name in LABELS:
        return LABELS[name]
    if name in KINDS:
        return KINDS[name].short
    return next(v.label for v in VARIANTS if v.name == name)


def _figure(d: Path, numbers: dict) -> str | None:
    """Room accuracy per representation and world, and the open-loop error by steps ahead."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sensorimotor.sim.plots import save_figure

    worlds = [w for w in numbers["worlds"] if w in ROOMED]
    if not worlds:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    ax = axes[0]
    names = [n for n in numbers["rows"][worlds[0]]]
    width = 0.8 / len(worlds)
    for i, w in enumerate(worlds):
        cells = [numbers["rows"][w].get(n, {}).get("room") or {} for n in names]
        means = np.array([c.get("mean") or 0.0 for c in cells])
        spans = [c.get("interval") or [c.get("mean") or 0.0] * 2 for c in cells]
        err = np.abs(np.array(spans).T - means)  # (2, n): below and above the mean
        x = np.arange(len(names)) + (i - (len(worlds) - 1) / 2) * width
        ax.bar(x, means, width, yerr=err, capsize=2, label=w)
    ax.axhline(1 / 3, color="k", lw=0.8, ls=":", label="chance (3 rooms)")
    ax.axhline(THRESHOLDS["room"]["rooms1"], color="tab:red", lw=0.8, ls="--", label="goal")
    ax.set_xticks(np.arange(len(names)), [_label(n) for n in names], rotation=35, ha="right")
    ax.set_ylabel("room: balanced accuracy")
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=8)
    ax = axes[1]
    for name, curve in numbers["curves"].items():
        ax.plot(np.arange(1, len(curve) + 1), curve, label=_label(name))
    base = numbers["baselines"].get(ABLATED_ON)
    if base:
        ax.axhline(base["mean"], color="k", lw=0.8, ls=":", label="the mean reading")
        ax.axhline(base["copy_last"], color="k", lw=0.8, ls="--", label="copy the last (k = 1)")
    ax.set_xlabel("steps ahead, open loop (k)")
    ax.set_ylabel(f"open-loop error on {ABLATED_ON}")
    if base:
        ax.set_ylim(0, 1.5 * base["mean"])  # a model without a transition leaves the chart
    ax.legend(fontsize=7, loc="upper right")
    paths = save_figure(fig, d / "memory.png")
    plt.close(fig)
    return str(paths[0])


def section(rep, found: dict) -> list[Block]:
    """The report's section: the probes' table, the ablations, the verdicts, the figure."""
    blocks = [
        h(2, "A memory that reads the motor commands"),
        p(
            "Rec-SMA's memory reads the last motor command beside the reading, and its "
            f"representation is trained to predict the readings up to {AHEAD} steps ahead open "
            "loop. "
            "Each representation is probed on a fresh database of each world (seed "
            f"{FRESH_SEED}): probes fitted on its training split, scored on its test split after "
            "200 steps. Mean over seeds [Student-t 95 %]. The true pose is the ceiling for a "
            "code of the place; the ideal observer (a particle filter that knows the walls, "
            "the lasers and the behaviour, and reads the same stream from the same empty "
            "start) is the ceiling for a memory of the stream."
        ),
    ]
    for w in found["worlds"]:
        rows = found["rows"][w]
        best = _baseline(rows, "room") or _baseline(rows, "r2_x")
        body = [
            [
                _label(n) + (" (strongest baseline)" if n == best else ""),
                _fmt(r["room"]),
                _fmt(r["r2_x"]),
                _fmt(r["r2_y"]),
                _fmt(r["median_error"], 1),
                _fmt(r["knn_mse"], 3),
                _fmt(r["error"], 4),
            ]
            for n, r in rows.items()
        ]
        blocks.append(h(3, f"Probed on {w}"))
        blocks.append(
            table(
                [
                    "representation",
                    "room (bal. acc.)",
                    "R^2 x",
                    "R^2 y",
                    "median error",
                    "KNN-MSE",
                    "one-step error",
                ],
                body,
            )
        )
    verdicts = [Verdict.from_dict(v) for v in found["verdicts"]]
    if verdicts:
        blocks.append(
            table(
                ["claim", "threshold", "numbers", "verdict", "threshold set"],
                [[v.claim, v.threshold, str(v.numbers), v.word(), v.provenance] for v in verdicts],
            )
        )
    if found.get("figure"):
        blocks.append(image(Path(found["figure"]), "Rec-SMA: room accuracy and open-loop error"))
    if REC_SM not in found["rows"].get(ABLATED_ON, {}):
        blocks.append(p("Rec-SM's runs were not found: no baseline row."))
    return blocks


def check(rep) -> None:
    """Refuse a reproduction without a world that names rooms (nothing to probe the room in)."""
    if not any(w in ROOMED for w in rep.worlds):
        raise InputError("experiment memory: needs rooms1 or rooms2 in --worlds")
