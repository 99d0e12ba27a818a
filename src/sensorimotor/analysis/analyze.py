"""``sensorimotor analyze``: a representation of a database's test split, analysed and drawn.

The representation is ``raw`` (the readings divided by the range: the paper's sensory space)
or a trained run folder's ``z_s`` (``evaluate.representation``; recurrent models carry their
state from the split's start). With ``fit_data``, PCA and k-means are fitted on that database's
test split and applied to ``data``'s (transfer, paper section V.G).

Writes into ``out``: ``metrics.json``, ``pca.png`` (Fig. 4), ``clusters.png`` (Figs. 5-8; the
transferred clusters with ``fit_data``) and, with ``fit_data``, ``clusters_fit.png`` (the
clusters on the world they were fitted on).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from sensorimotor.analysis.clusters import N_CLUSTERS
from sensorimotor.analysis.probes import BURN_IN, KNN_K, PROBE_FIT_MAX, place_probes
from sensorimotor.analysis.representation import (
    RepresentationAnalysis,
    analyze_representation,
    scaled_readings,
    world_events,
)
from sensorimotor.errors import InputError
from sensorimotor.files import atomic_path, check_writable, write_json_atomic
from sensorimotor.learn.models import KINDS, paper_kinds
from sensorimotor.sim.core import read_sensors
from sensorimotor.sim.database import Database, load_database
from sensorimotor.version import __version__

RAW = "raw"  # the RUN_DIR that means "the raw readings"


def with_raw() -> tuple[str, ...]:
    """The raw readings, then the paper's kinds: each representation the paper compares."""
    return (RAW, *paper_kinds())


def short_name(name: str) -> str:
    """A representation's name in tables and legends: ``raw`` or a kind's short name."""
    return RAW if name == RAW else KINDS[name].short


SPLIT = "test"


def representation_of(
    run, db: Database, split: str = SPLIT, steps: int | None = None
) -> np.ndarray:
    """(n, D) representation of ``db``'s split, or of its first ``steps``: ``run`` is ``"raw"``,
    a run folder or a loaded ``evaluate.Run``. InputError naming the file if the split is too
    short to cluster."""
    n = len(db.take(split).sensors[:steps])
    if n < N_CLUSTERS:
        raise InputError(
            f"{db.source}: the {split} split has {n} steps; the analysis needs at least {N_CLUSTERS}"
        )
    if isinstance(run, str) and run == RAW:
        z = scaled_readings(db.take(split).sensors[:steps], db.max_range)
    else:
        from sensorimotor.learn.evaluate import encode  # torch only for a model

        z = encode(run, db, split, steps)
    distinct = len(np.unique(z[:100_000], axis=0))
    if distinct < N_CLUSTERS:  # k-means and PCA would only warn, and write NaN
        raise InputError(
            f"{db.source}: the representation of the {split} split takes {distinct} distinct "
            f"value(s), fewer than the {N_CLUSTERS} clusters of the analysis (a robot that "
            "never moves, or readings that never change?)"
        )
    return z


def probe_places(run, db: Database, z: np.ndarray | None = None) -> dict | None:
    """``probes.place_probes`` of ``run``'s representation (``"raw"``, a run folder or a loaded
    run): fitted on the first ``PROBE_FIT_MAX`` steps of ``db``'s training split, scored on its
    test split (``z``, that split's representation, when the caller has it); the room is None
    where the world names no rooms (or its walls are unknown). None where a split is too short
    for the burn-in (a short recording)."""
    fit, test = db.take("train"), db.take(SPLIT)
    if min(len(fit), len(test)) <= BURN_IN + KNN_K:
        return None
    z_fit = representation_of(run, db, "train", PROBE_FIT_MAX)
    z = representation_of(run, db, SPLIT) if z is None else z
    fit_poses = fit.poses[: len(z_fit)]
    rooms = db.world.rooms if db.has_walls else ()
    room_fit = room = None
    if rooms:
        room_fit = db.world.room_index(fit_poses[:, 0], fit_poses[:, 1])
        room = db.world.room_index(test.poses[:, 0], test.poses[:, 1])
    size = (db.world.width, db.world.height) if db.has_walls else _extent(test.poses)
    return place_probes(z_fit, fit_poses, z, test.poses, room_fit, room, size)


def _extent(poses: np.ndarray) -> tuple[float, float]:
    """The width and height of the region the poses cover (walls unknown)."""
    span = np.ptp(np.asarray(poses)[:, :2], axis=0)
    return float(max(span[0], 1e-9)), float(max(span[1], 1e-9))


# Every file an analysis may write; those it does not write this time are removed from its folder.
OUTPUTS = (
    *(f"{name}.{ext}" for name in ("pca", "clusters", "clusters_fit") for ext in ("png", "svg")),
    "pca.npz",
    "metrics.json",
)


def truth_readings(db: Database, split: str = SPLIT) -> np.ndarray:
    """Noiseless readings of a split: the stored ones, recomputed at the poses if noise was added
    (so "nothing in view" is the truth, not a noisy guess)."""
    part = db.take(split)
    if not db.meta.get("noise_std") or not db.has_walls:
        return np.asarray(part.sensors, dtype=np.float64)
    return read_sensors(db.world, part.poses, db.layout)


def event_probe_fit(run, db: Database) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
    """What each event's linear probe (``probes.probe_auc``) is fitted on: the representation
    of ``db``'s training split (its first ``PROBE_FIT_MAX`` steps) and that split's events
    (``world_events``); None where the split is too short to analyse."""
    part = db.take("train")
    if len(part) < N_CLUSTERS:
        return None
    z_fit = representation_of(run, db, "train", PROBE_FIT_MAX)
    n = len(z_fit)
    world = db.world if db.has_walls else None
    events = world_events(world, truth_readings(db, "train")[:n], part.poses[:n], db.layout)
    return z_fit, events


def burn_in(run, steps: int) -> int:
    """Leading steps of a split an analysis leaves out: ``BURN_IN`` for a recurrent model, whose
    first states come from the zero state (on a short split they formed clusters of their
    own), when at least ``N_CLUSTERS`` steps remain; else 0."""
    recurrent = not (isinstance(run, str) and run == RAW) and run.model.config.recurrent
    return BURN_IN if recurrent and steps - BURN_IN >= N_CLUSTERS else 0


def _analyze(
    run, db: Database, seed: int, fitted: RepresentationAnalysis | None = None, fit_probes=False
):
    """``analyze_representation`` of ``run`` on ``db``'s test split after its burn-in; returns
    the analysis, the burn-in and the whole split's representation."""
    z = representation_of(run, db)
    part = db.take(SPLIT)
    start = burn_in(run, len(z))
    kmeans, pca = (fitted.kmeans, fitted.pca) if fitted else (None, None)
    if fitted is not None and z.shape[1] != fitted.kmeans.n_features_in_:
        raise InputError(
            f"{db.source}: {z.shape[1]}-d representation, the clusters were fitted on "
            f"{fitted.kmeans.n_features_in_}-d ones"
        )
    world = db.world if db.has_walls else None  # None: the stages that need walls say n/a
    probe_fit = event_probe_fit(run, db) if fit_probes else None
    result = analyze_representation(
        z[start:], truth_readings(db)[start:], part.poses[start:], world, seed, kmeans, pca,
        db.layout, name=_name(db), probe_fit=probe_fit,
    )  # fmt: skip
    return result, start, z


def _name(db: Database) -> str:
    """The world's name, or the recording's when its walls are unknown."""
    return db.meta["world"]["name"]


def _walls(db: Database):
    """The World to draw the clusters in, or None when its walls are unknown."""
    return db.world if db.has_walls else None


def check_same_layout(fit_db: Database, db: Database) -> None:
    """Refuse, in one line, two databases whose lasers differ: a representation (or a map)
    fitted on one means nothing on the other."""
    a, b = fit_db.meta.get("sensor_layout"), db.meta.get("sensor_layout")
    if a and b and a != b:
        raise InputError(f"{db.source}: sensor layout {b} differs from {fit_db.source}'s {a}")


def load_inputs(run, data, fit_data, out, outputs: tuple[str, ...]):
    """What an analysis of ``run`` (``"raw"`` or a run folder) reads, loaded and checked before
    anything is written: (run, database, fit database or None, output folder); the outputs it
    would replace in ``out`` must be writable."""
    db = load_database(data)
    fit_db = load_database(fit_data) if fit_data is not None else None
    if str(run) != RAW:
        from sensorimotor.learn.evaluate import load_run

        run = load_run(run)
    else:
        run = RAW
    if fit_db is not None:
        check_same_layout(fit_db, db)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file, not an output folder")
    for target in outputs if out.is_dir() else []:  # before anything is written, not midway
        check_writable(out / target)
    return run, db, fit_db, out


def _out_dir(out: Path) -> Path:
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file, not an output folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"{out}: cannot create the output folder ({err.strerror})") from None
    return out


@dataclass(frozen=True)
class AnalyzeResult:
    """What ``analyze_files`` wrote and found."""

    metrics: dict  # the content of metrics.json
    files: list[Path]


def analyze_files(
    run: str | Path,
    data: str | Path,
    out: str | Path,
    fit_data: str | Path | None = None,
    seed: int = 0,
    svg: bool = False,
    probes: bool = True,
    event_probes: bool = False,
) -> AnalyzeResult:
    """Analyse ``run``'s representation (``"raw"`` or a run folder) of ``data``'s test split and
    write the figures (PNG, and SVG with ``svg``) and ``metrics.json`` into ``out`` (see the
    module docstring); with ``probes``, the place probes (``probe_places``) too; with
    ``event_probes``, each event's linear probe is fitted on ``data``'s training split
    (``event_probe_fit``) rather than on a random half of the test split (not in a transfer)."""
    from sensorimotor.analysis.plots import plot_clusters, plot_pca, plot_transfer
    from sensorimotor.sim.plots import save_figure

    run, db, fit_db, out = load_inputs(run, data, fit_data, out, OUTPUTS)
    source, fit_start, _ = _analyze(run, fit_db, seed) if fit_db is not None else (None, 0, None)
    result, start, z = _analyze(run, db, seed, source, event_probes and fit_db is None)
    # a transfer's probes would be those of the plain analysis of ``data``: left to it
    probes = probe_places(run, db, z) if probes and fit_db is None else None
    out = _out_dir(out)  # made only once the analysis has succeeded
    # metrics.json, written last, marks a whole analysis: a folder that a failure (a full
    # disk) leaves with this analysis' figures has no metrics of an earlier one beside them
    (out / "metrics.json").unlink(missing_ok=True)
    whole = db.take(SPLIT)
    part = replace(  # the steps analysed
        whole, sensors=whole.sensors[start:], motors=whole.motors[start:], poses=whole.poses[start:]
    )
    files = []
    pca_title = "PCA" + (f" fitted on {_name(fit_db)}" if fit_db is not None else "")
    ax = plot_pca(result.pc, part.sensors.min(axis=1), title=f"{pca_title}: {_name(db)}")
    files += save_figure(ax.figure, out / "pca.png", svg=svg)
    name = RAW if run == RAW else run.kind
    if source is None:
        fig = plot_clusters(
            _walls(db),
            part.poses,
            result.labels,
            seed,
            titles=result.cluster_titles(),
            suptitle=f"{name} on {_name(db)}: {len(part):,} test steps",
        )
    else:
        fig = plot_transfer(
            _walls(db),
            part.poses,
            result.labels,
            _name(fit_db),
            seed,
            titles=result.cluster_titles(),
            name=_name(db),
        )
        fit_fig = plot_clusters(
            _walls(fit_db),
            fit_db.take(SPLIT).poses[fit_start:],
            source.labels,
            seed,
            titles=source.cluster_titles(),
            suptitle=f"{name} on {_name(fit_db)}: {len(source.labels):,} test steps",
        )
        files += save_figure(fit_fig, out / "clusters_fit.png", svg=svg)
    files += save_figure(fig, out / "clusters.png", svg=svg)

    metrics = {
        "run": RAW if run == RAW else str(run.path),
        "model": name,
        "data": str(data),
        "fit_data": None if fit_data is None else str(fit_data),
        "split": SPLIT,
        "burn_in": start,
        "version": __version__,
        "analysis": result.metrics,
        "fit_analysis": None if source is None else source.metrics,
        "probes": probes,
    }
    arrays = out / "pca.npz"  # what a report needs to redraw Fig. 4 beside other models
    with atomic_path(arrays, ".npz") as tmp, open(tmp, "wb") as f:
        np.savez(
            f,
            pc=result.pc.astype(np.float32),
            min_reading=part.sensors.min(axis=1).astype(np.float32),
            labels=result.labels.astype(np.int16),
        )
    files.append(arrays)
    path = out / "metrics.json"
    write_json_atomic(path, metrics)
    files.append(path)
    for stale in set(OUTPUTS) - {f.name for f in files}:  # an earlier analysis' in this folder
        (out / stale).unlink(missing_ok=True)
    return AnalyzeResult(metrics, files)


def probe_lines(probes: dict | None) -> list[str]:
    """The place probes (``probe_places``) as printable lines."""
    if probes is None:
        return ["  place probes: n/a (a split is shorter than the burn-in)"]
    room, pos, knn = probes["room"], probes["position"], probes["knn_mse"]
    return [
        f"  place probes (fitted on {probes['fit_steps']:,} training steps, scored on "
        f"{probes['scored_steps']:,} test steps after {probes['burn_in']}): room "
        + ("n/a (no rooms)" if room is None else
           f"{room['balanced_accuracy']:.3f} balanced accuracy (chance {room['chance']:.3f})")
        + f"; R^2 x {pos['r2']['x']:.3f}, y {pos['r2']['y']:.3f}; median position error "
        f"{pos['median_error']:.1f}; KNN-MSE {knn['value']:.3f} (chance {knn['chance']:.3f})"
    ]


def summary_lines(metrics: dict) -> list[str]:
    """The main numbers of one ``analyze_representation`` result, as printable lines."""
    m = metrics
    lines = [
        f"{m['world']}: {m['n_steps']:,} steps, {m['dim']}-d representation, "
        f"k = {m['k']}{' (transferred)' if m['transfer'] else ''}"
    ]
    for name in m.get("not_applicable", []):
        if name != "distance_behind":
            lines.append(f"  {name.replace('_', ' ') + ' in view':<18} n/a (walls unknown)")
    for name, e in m["events"].items():
        best = "" if e["cluster"] is None else f"best cluster #{e['cluster']}: "
        lines.append(
            f"  {name.replace('_', ' ') + ' in view':<18} {e['rate']:6.1%} of steps; {best}"
            f"precision {e['precision']:.2f}, recall {e['recall']:.2f}, F1 {e['f1']:.2f}"
            + ("" if e.get("probe_auc") is None else f"; linear probe AUC {e['probe_auc']:.2f}")
        )
    mem = m["memory"]
    r2 = mem["distance_behind_r2"]
    lines.append(
        f"  memory: {mem['nothing_clusters']} cluster(s) mostly nothing in view; distance-behind "
        f"R^2 (nothing in view) {'n/a' if r2 is None else f'{r2:.2f}'}"
        + (" (walls unknown)" if "distance_behind" in m.get("not_applicable", []) else "")
    )
    p = m["position"]
    lines.append(
        f"  position R^2: x {p['r2_x']:.2f}, y {p['r2_y']:.2f}, cos {p['r2_cos_heading']:.2f}, "
        f"sin {p['r2_sin_heading']:.2f}; KNN-MSE {p['knn_mse']:.3f} (chance "
        f"{p['knn_mse_chance']:.3f})"
    )
    return lines
