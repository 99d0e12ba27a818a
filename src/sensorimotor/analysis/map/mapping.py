"""``sensorimotor map``: from cells to a map, and what the map knows that the cells do not.

The representation (``raw`` or a run folder's z_s, ``analyze.representation_of``) of the
training split becomes cells (k-means, ``clusters.fit_kmeans``; with ``fit_data`` the k-means is
fitted on that database's training split: transfer) and the motor commands become actions
(``cells.action_bins``). On the training split: the cell graph (``cells.cell_graph``) and the
cloned HMM (``chmm.fit_chmm``), each clone split by the slow context (``context.slow_context``,
``contexts`` of them; 1: the plain cloned HMM). On the test split:

- **bits per step** of next-cell prediction: unigram, first-order (cell, action) Markov, the
  cell graph, the map (after Viterbi training, the split and pruning) and the map after EM
  alone (before the split);
- **localisation** (``localisation.localisation``) from the filtered (causal) map state: the
  posterior over the map's states at step t, each state labelled on the training split by the
  posterior-weighted frequency of each room (or 10 x 10 grid square) and its mean position,
  gives the most probable room and the expected position; against the cell alone (the same
  labels per cell) and chance (the most frequent room, the mean position). Room accuracy is
  given plain and balanced (the mean over rooms of each room's recall: chance is 1 / rooms, so
  a read-out that always names the biggest room scores no better than chance). Room numbers
  need a world whose file names its rooms; otherwise they are null ("n/a");
- **rooms from the graph** (``graphs.rooms_from_graph``): Louvain communities (networkx, at
  ``graphs.RESOLUTION``, set on validation maps; the run of highest modularity of
  ``graphs.RUNS``) of the map's transition graph (Viterbi counts,
  both directions, all actions) and of the cell graph; adjusted Rand index of the community of
  each test step (its most probable state) against its room;
- **planning** in the simulator (``planning.planning``): success rate of the map's planner
  and of the paper's random behaviour over ``pairs`` start/goal pairs (null with 0 pairs).

With ``test_data`` (``--test-data``) the test split is that of a fresh database of the same
world, sensors and behaviour: the map and its cells are learned on ``data``, scored on steps
it has never seen. One representation (one run) per call: the mean and sd over seeds are left
to the caller.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from sensorimotor.analysis.analyze import RAW, check_same_layout, load_inputs, representation_of
from sensorimotor.analysis.clusters import N_CLUSTERS, assign_clusters, fit_kmeans
from sensorimotor.analysis.map.baselines import baselines
from sensorimotor.analysis.map.ceilings import NO_CEILING, ceilings, true_pose_planning
from sensorimotor.analysis.map.cells import (
    ACTION_NAMES,
    N_ACTIONS,
    SMOOTHING,
    Steps,
    action_bins,
    baseline_bits,
    cell_graph,
)
from sensorimotor.analysis.map.chmm import (
    EM_ITERS,
    PSEUDOCOUNT,
    TOL,
    fit_chmm,
    log_likelihood,
)
from sensorimotor.analysis.map.context import (
    CONTEXT_TAU,
    MAX_CONTEXTS,
    N_CONTEXTS,
    fine_clones,
    slow_context,
)
from sensorimotor.analysis.map.graphs import (
    MAX_RESOLUTION,
    RESOLUTION,
    best_states,
    map_graphs,
    networkx_or_refuse,
    rooms_from_graph,
)
from sensorimotor.analysis.map.graphs import RUNS as LOUVAIN_RUNS
from sensorimotor.analysis.map.localisation import GRID, localisation
from sensorimotor.analysis.map.planning import (
    GOAL_RADIUS,
    MAX_PAIRS,
    N_PAIRS,
    Moves,
    encoder_of,
    planning,
)
from sensorimotor.errors import InputError
from sensorimotor.files import atomic_path, write_text_atomic
from sensorimotor.sim.database import Database, load_database
from sensorimotor.sim.world import World
from sensorimotor.version import __version__

N_CLONES = 20  # clones per cell (the issue's 20-cell, 20-clone map)
MAX_CLUSTERS = 200
MAX_CLONES = 200  # the grid's cells hold up to 155 place-headings each (docs/results/map/grid)
MAX_STATES = 40_000  # K C N: the random start draws A S^2 numbers (6.4e9, about 40 s, here);
# the blocks' memory is bounded apart (chmm.MAX_BLOCK_BYTES)
STARTS = ("random", "fine")  # where EM starts: chmm's random T, or context.fine_clones
OUTPUTS = (
    *("map.json", "map.graphml", "cell_graph.graphml"),
    *("place_fields.png", "map_graph.png", "plans.png"),
)


def _bounding_box(db, train: Steps, test: Steps) -> tuple[World, Steps, Steps]:
    """Where the walls are unknown (a robot's recording), a world of no walls over the box the
    poses cover, and the poses moved into it: the grid and the position error are then over
    the region the robot went through; rooms are unknown and nothing can be planned."""
    xy = np.concatenate([train.poses[:, :2], test.poses[:, :2]])
    low = xy.min(axis=0)
    size = np.maximum(xy.max(axis=0) - low, 1e-6)
    moved = [replace(s, poses=s.poses - np.array([low[0], low[1], 0.0])) for s in (train, test)]
    box = World(db.meta["world"]["name"], float(size[0]), float(size[1]), np.zeros((0, 4)))
    return box, moved[0], moved[1]


def check_settings(k: int, clones: int, contexts: int = N_CONTEXTS, start: str = STARTS[0]) -> None:
    """InputError unless 2 <= K <= MAX_CLUSTERS, 1 <= C <= MAX_CLONES, 1 <= N <= MAX_CONTEXTS,
    K C N <= MAX_STATES and ``start`` is one of STARTS."""
    if start not in STARTS:
        raise InputError(f"--start must be one of {', '.join(STARTS)}, got {start!r}")
    if not 2 <= k <= MAX_CLUSTERS:
        raise InputError(f"--clusters must lie in [2, {MAX_CLUSTERS}], got {k}")
    if not 1 <= clones <= MAX_CLONES:
        raise InputError(f"--clones must lie in [1, {MAX_CLONES}], got {clones}")
    if not 1 <= contexts <= MAX_CONTEXTS:
        raise InputError(f"--contexts must lie in [1, {MAX_CONTEXTS}], got {contexts}")
    if k * clones * contexts > MAX_STATES:
        raise InputError(
            f"--clusters {k} x --clones {clones} x --contexts {contexts} = "
            f"{k * clones * contexts:,} states; at most {MAX_STATES:,}"
        )


def _check_length(db: Database, split: str, k: int) -> None:
    n = len(db.take(split))
    if n < max(k, N_CLUSTERS, 2):
        raise InputError(
            f"{db.source}: the {split} split has {n} steps; the map needs at least "
            f"{max(k, N_CLUSTERS, 2)} (k = {k})"
        )


def cell_steps(
    run,
    db: Database,
    k: int,
    seed: int,
    fit_db: Database | None = None,
    z_train=None,
    test_db: Database | None = None,
):
    """(train Steps, test Steps, the k-means) of ``db``: k-means (k = ``k``) fitted on the
    training split of ``fit_db`` (or of ``db``), applied to ``db``'s training split and to the
    test split of ``test_db`` (or of ``db``). ``z_train``: the representation of ``db``'s
    training split, if the caller has it already."""
    test_db = db if test_db is None else test_db
    for d, split in ((db, "train"), (test_db, "test"), (fit_db, "train")):
        if d is not None:
            _check_length(d, split, k)
    if z_train is None:
        z_train = representation_of(run, db, "train")
    z_fit = z_train if fit_db is None else representation_of(run, fit_db, "train")
    kmeans = fit_kmeans(z_fit, k, seed)
    z_test = representation_of(run, test_db, "test")
    return split_steps(db, kmeans, z_train, "train"), split_steps(test_db, kmeans, z_test), kmeans


def fresh_database(path: str | Path, db: Database, k: int) -> Database:
    """The database at ``path``, refused unless it records the same world with the same
    sensors and behaviour as ``db`` (the map's places, cells and actions must mean the same)."""
    fresh = load_database(path)
    _check_length(fresh, "test", k)
    check_same_layout(db, fresh)
    for what, ok in (
        ("world", fresh.meta.get("world") == db.meta.get("world")),
        ("behaviour", fresh.behaviour == db.behaviour),
    ):
        if not ok:
            raise InputError(f"{fresh.source}: its {what} differs from {db.source}'s")
    return fresh


def split_steps(db: Database, kmeans, z: np.ndarray, split: str = "test") -> Steps:
    """One split of ``db`` as Steps, the cells of its representation ``z`` by ``kmeans``."""
    part = db.take(split)
    motors = np.asarray(part.motors, dtype=np.float64)
    poses = np.asarray(part.poses, dtype=np.float64)
    return Steps(assign_clusters(kmeans, z), action_bins(motors), motors, poses)


# --------------------------------------------------------------------------------------------
# The whole map, its files


@dataclass(frozen=True)
class MapResult:
    """What ``map_files`` computed and wrote."""

    metrics: dict  # the content of map.json
    files: list[Path]


def _strict(value):
    """``value`` with every non-finite float replaced by None (strict JSON)."""
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_strict(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _versions() -> dict:
    import numba
    import sklearn

    versions = {"sensorimotor": __version__, "numpy": np.__version__}
    versions |= {"numba": numba.__version__, "scikit-learn": sklearn.__version__}
    try:
        import networkx

        versions["networkx"] = networkx.__version__
    except ImportError:
        versions["networkx"] = None
    return versions


def map_files(
    run: str | Path,
    data: str | Path,
    out: str | Path,
    clusters: int = N_CLUSTERS,
    clones: int = N_CLONES,
    fit_data: str | Path | None = None,
    seed: int = 0,
    em_iters: int = EM_ITERS,
    pairs: int = N_PAIRS,
    progress=None,
    contexts: int = N_CONTEXTS,
    tol: float = TOL,
    start: str = "random",
    pseudocount: float = PSEUDOCOUNT,
    test_data: str | Path | None = None,
    resolution: float = RESOLUTION,
) -> MapResult:
    """Build the map of ``run``'s representation (``"raw"`` or a run folder) of ``data`` and
    write ``map.json``, the GraphML files and the figures into ``out`` (module docstring).
    ``progress(stage, i, number)``: after each EM or Viterbi iteration (its log-likelihood per
    step) and each planning pair (the map's success so far). ``start``: ``STARTS``;
    ``pseudocount``: EM's, added to every transition count; ``test_data``: a fresh database of
    the same world and robot whose test split is scored (default: ``data``'s);
    ``resolution``: Louvain's, for the communities."""
    from sensorimotor.analysis.map.plots import plot_map_graph, plot_place_fields, plot_plans
    from sensorimotor.sim.plots import save_figure

    check_settings(clusters, clones, contexts, start)
    nx = networkx_or_refuse()
    if not 0 <= pairs <= MAX_PAIRS:  # before the inputs are read
        raise InputError(f"--pairs must be from 0 to {MAX_PAIRS:,}, got {pairs}")
    if not 0.0 < pseudocount <= 1.0:
        raise InputError(f"--pseudocount must lie in (0, 1], got {pseudocount}")
    if not 0.0 < resolution <= MAX_RESOLUTION:
        raise InputError(f"--resolution must lie in (0, {MAX_RESOLUTION:g}], got {resolution}")
    run, db, fit_db, out = load_inputs(run, data, fit_data, out, OUTPUTS)
    test_db = db if test_data is None else fresh_database(test_data, db, clusters)
    z_train = representation_of(run, db, "train") if start == "fine" else None  # encoded once
    train, test, kmeans = cell_steps(run, db, clusters, seed, fit_db, z_train, test_db)
    first = fine_clones(z_train, train.cells, clones, seed) if start == "fine" else None
    if db.has_walls:
        world = db.world
    else:  # a recording: positions within the path's bounding box, no rooms, no planning
        world, train, test = _bounding_box(db, train, test)
        pairs = 0
    graph = cell_graph(train.cells, train.actions, train.motors, clusters)
    context = slow_context(train.cells, clusters, contexts, CONTEXT_TAU, seed)
    model = fit_chmm(
        *(train.cells, train.actions, clusters, clones, N_ACTIONS, seed, em_iters),
        tol=tol,
        pseudocount=pseudocount,
        context=context,
        n_contexts=contexts,
        progress=progress,
        start=first,
    )
    val = split_steps(db, kmeans, representation_of(run, db, "val"), "val")
    bits = baseline_bits(train.cells, train.actions, test.cells, test.actions, clusters)
    for name, T in (("map", model.T), ("map_em", model.T_em)):
        bits[name] = float(-log_likelihood(T, test.cells, test.actions)[1:].mean()) / math.log(2)
    loc, state_mean, occupancy = localisation(model, train, test, world)
    best = best_states(model, test)  # the place fields' and the communities' state of a step
    rooms, comm = rooms_from_graph(model, graph, test, best, world, seed, resolution)
    plans, traces = {"success": {"map": None, "random": None}, "pairs": 0}, []
    if pairs:
        encoder = encoder_of(run, db.max_range)
        on_pair = None if progress is None else lambda i, rate: progress("planning pair", i, rate)
        plans, traces = planning(
            world, db.layout, encoder, kmeans, model, state_mean, occupancy, seed, pairs,
            progress=on_pair, moves=Moves(db.behaviour),
        )  # fmt: skip
    metrics = {
        "run": RAW if run == RAW else str(run.path),
        "model": RAW if run == RAW else run.kind,
        "data": str(data),
        "fit_data": None if fit_data is None else str(fit_data),
        "test_data": None if test_data is None else str(test_data),
        "world": world.name,
        "split": "test (the model fitted on the train split of data)",
        "steps": {"train": len(train.cells), "test": len(test.cells)},
        "settings": {
            "clusters": clusters,
            "clones": clones,
            "contexts": contexts,
            "context_tau": CONTEXT_TAU,
            "actions": list(ACTION_NAMES),
            "seed": seed,
            "em_iters": em_iters,
            "em_tol": tol,
            "pseudocount": pseudocount,
            "start": start,
            "louvain_resolution": resolution,
            "louvain_runs": LOUVAIN_RUNS,
            "markov_smoothing": SMOOTHING,
            "grid": GRID,
        },
        "versions": _versions(),
        "bits_per_step": bits,
        "baselines": baselines(train, val, test, world, clusters, int(model.active.sum()), seed),
        "ceiling": ceilings(test_db, world, seed, pairs) if db.has_walls else NO_CEILING,
        "states": {
            "total": model.n_states,
            "active": int(model.active.sum()),
            "em_iterations": len(model.history["em"]),
            "viterbi_iterations": len(model.history["viterbi"]),
            "split_viterbi_iterations": len(model.history.get("split", [])),
            "train_nats_per_step": {
                "em": model.history["em"][-1],
                "viterbi": model.history["viterbi"][-1] if model.history["viterbi"] else None,
            },
        },
        "localisation": loc,
        "rooms": rooms,
        "planning": plans,
    }
    metrics = _strict(metrics)
    the_map, the_cells = map_graphs(model, graph, state_mean, occupancy, comm, world)
    seen = np.bincount(best, minlength=model.n_states).astype(np.float64)  # test occupancy
    box = not db.has_walls  # the frame is the path's bounding box, not walls
    place = plot_place_fields(
        world, test.poses, best, seen, f"{metrics['model']} on {world.name}", bounding_box=box
    )
    drawn = plot_map_graph(
        world,
        state_mean,
        model.edge_counts(),
        model.active,
        comm,
        occupancy,
        f"{metrics['model']} on {world.name}: {int(model.active.sum())} states",
        bounding_box=box,
    )
    figures = {"place_fields.png": place, "map_graph.png": drawn.figure}
    if traces:
        true_pose: list = []  # the same pairs (the planner's seed), up to the last one drawn
        true_pose_planning(world, db.layout, seed, traces[-1][0] + 1, moves=Moves(db.behaviour),
                           traces=true_pose)  # fmt: skip
        title = f"{metrics['model']} on {world.name}: the map plans (blue), the true pose (grey)"
        drawn = [t[1:] for t in traces]
        figures["plans.png"] = plot_plans(
            world, drawn, GOAL_RADIUS, title, [true_pose[t[0]] for t in traces]
        )
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for name, g in (("map.graphml", the_map), ("cell_graph.graphml", the_cells)):
        with atomic_path(out / name, ".graphml") as tmp:
            nx.write_graphml(g, tmp)
        files.append(out / name)
    for name, fig in figures.items():
        files += save_figure(fig, out / name)
    for stale in set(OUTPUTS) - {f.name for f in files} - {"map.json"}:
        (out / stale).unlink(missing_ok=True)  # an earlier map's, in this folder
    path = out / "map.json"
    write_text_atomic(path, json.dumps(metrics, indent=2, allow_nan=False) + "\n")
    files.append(path)
    return MapResult(metrics, files)


def _fmt(v, spec: str = ".3f") -> str:
    return "n/a" if v is None else format(v, spec)


def summary_lines(m: dict) -> list[str]:
    """The main numbers of a ``map.json`` as printable lines."""
    b, loc, r = m["bits_per_step"], m["localisation"], m["rooms"]
    ra, pe = loc["room_accuracy"], loc["position_error"]
    return [
        f"{m['model']} on {m['world']}: {m['settings']['clusters']} cells x "
        f"{m['settings']['clones']} clones x {m['settings'].get('contexts', 1)} contexts, "
        f"{m['states']['active']} active states",
        f"  scored on the test split of {m.get('test_data') or m['data']}",
        "  bits/step: " + ", ".join(f"{k} {_fmt(v)}" for k, v in b.items()),
        *_baseline_lines(m),
        f"  room accuracy: map {_fmt(ra['map'])}, cells {_fmt(ra['cells'])}, "
        f"chance {_fmt(ra['chance'])}",
        f"  position error: map {_fmt(pe['map'], '.2f')}, cells {_fmt(pe['cells'], '.2f')}, "
        f"chance {_fmt(pe['chance'], '.2f')}",
        f"  rooms from the graph: adjusted Rand {_fmt(r['adjusted_rand'])} (map, "
        f"{r['communities']['map']} communities), {_fmt(r['adjusted_rand_cells'])} (cells)",
        f"  planning success: map {_fmt(m['planning']['success']['map'], '.2f')}, random "
        f"{_fmt(m['planning']['success']['random'], '.2f')} ({m['planning']['pairs']} pairs)",
        *_planning_warning(m["planning"]),
    ]


def _baseline_lines(m: dict) -> list[str]:
    """The baselines' and ceilings' numbers (none in a map.json made before them)."""
    base, top = m.get("baselines", {}), m.get("ceiling", {})
    out = []
    if base:
        higher = ", ".join(f"{k} {_fmt(v)}" for k, v in base["bits_per_step"].items())
        readout = base["localisation"]["history_readout"]
        out.append(
            f"  baselines: bits/step {higher}; balanced room accuracy of the history read-out "
            f"{_fmt(readout)}"
        )
    if top:
        loc = top["localisation"]
        blind = (loc.get("no_odometry") or {}).get("balanced_room_accuracy")
        out.append(
            f"  ceilings: balanced room accuracy of MCL {_fmt(loc['balanced_room_accuracy'])} "
            f"(no odometry {_fmt(blind)}); true-pose planning "
            f"{_fmt(top['planning']['success'], '.2f')}"
        )
    return out


def _planning_warning(planning: dict) -> list[str]:
    """A warning where the map's planner reaches no more goals than the random behaviour: its
    plans then say nothing about the map (too little data or too few clones to tell places
    apart, or a representation whose cells do not)."""
    ours, chance = planning["success"]["map"], planning["success"]["random"]
    if ours is None or chance is None or ours > chance:
        return []
    return [
        f"  warning: the planner reached no more goals than the random behaviour ({ours:.2f} vs "
        f"{chance:.2f}): the map does not tell the places apart well enough to plan; try more "
        "data (a larger database or --scale paper) or more --clones"
    ]
