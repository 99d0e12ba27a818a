"""The whole analysis of one representation: events, clusters, probes, one JSON-ready dict."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sklearn.cluster import KMeans
from sklearn.decomposition import PCA

from sensorimotor.analysis.clusters import (
    N_CLUSTERS,
    assign_clusters,
    check_z,
    cluster_event_table,
    event_scores,
    fit_kmeans,
    fit_pca,
    project_2d,
)
from sensorimotor.analysis.probes import memory_scores, position_scores, probe_auc
from sensorimotor.sim import events as ev
from sensorimotor.sim.core import DEFAULT_LAYOUT, SensorLayout
from sensorimotor.sim.world import World


def scaled_readings(sensors: np.ndarray, max_range: float = 10.0) -> np.ndarray:
    """The paper's sensory-space baseline: the readings divided by the range, (N, R) float32
    (the models' input scaling, ``data.scale_sensors``)."""
    from sensorimotor.sim.database import scale_sensors

    return scale_sensors(sensors, max_range)


WALL_EVENTS = ("corner", "wall_end")  # the events whose truth needs the walls


def world_events(
    world: World | None,
    sensors: np.ndarray,
    poses: np.ndarray,
    layout: SensorLayout = DEFAULT_LAYOUT,
) -> dict:
    """The ground-truth events of each step, as ``layout``'s lasers see them: ``{name: (N,)
    bool}``; wall ends only if any exist; with no ``world`` (walls unknown) "nothing" alone, the
    one the readings tell."""
    out = {}
    if world is not None:
        out["corner"] = ev.corner_in_view(world, poses, layout)
        if len(ev.free_wall_ends(world)):
            out["wall_end"] = ev.wall_end_in_view(world, poses, layout)
    out["nothing"] = ev.nothing_in_view(sensors, layout.max_range)
    return out


@dataclass(frozen=True, eq=False)
class RepresentationAnalysis:
    """What ``analyze_representation`` found: JSON-ready numbers plus what the figures need."""

    metrics: dict
    """JSON-ready numbers (see ``analyze_representation``)."""
    labels: np.ndarray = field(repr=False)
    """(N,) cluster of each step."""
    pc: np.ndarray = field(repr=False)
    """(N, 2) PCA coordinates of each step."""
    kmeans: KMeans = field(repr=False)
    pca: PCA = field(repr=False)
    events: dict = field(repr=False)
    """``{name: (N,) bool}`` ground-truth events, plus ``distance_behind`` (N,) float."""

    def cluster_titles(self) -> list[str]:
        """One panel title per cluster: ``#c share%  event precision% (lift x)``.

        The event is the cluster's strongest (highest lift); e.g. ``#3  1.4%  corner 23% (11x)``:
        cluster 3 holds 1.4 % of the steps, 23 % of them see a corner, 11 times the base rate.
        """
        titles = []
        for c in self.metrics["clusters"]:
            title = f"#{c['id']}  {c['share']:.1%}"
            name = c["strongest_event"]
            if name is not None:
                precision, lift = c["precision"][name], c["lift"][name]
                title += f"  {name.replace('_', ' ')} {precision:.0%} ({lift:.2g}x)"
            titles.append(title)
        return titles


def analyze_representation(
    z: np.ndarray,
    sensors: np.ndarray,
    poses: np.ndarray,
    world: World | None,
    seed: int = 0,
    kmeans: KMeans | None = None,
    pca: PCA | None = None,
    layout: SensorLayout = DEFAULT_LAYOUT,
    k: int = N_CLUSTERS,
    name: str | None = None,
    probe_fit: tuple[np.ndarray, dict[str, np.ndarray]] | None = None,
) -> RepresentationAnalysis:
    """Cluster and score a representation ``z`` (N, D) of steps with raw ``sensors`` (N, R, in
    units) and true ``poses`` (N, 3) in ``world``, recorded with ``layout``'s lasers (what
    counts as a corner or a wall end in view).

    With ``kmeans`` (and ``pca``) fitted elsewhere, e.g. on another world, they are only applied
    (transfer); otherwise they are fitted here with ``seed``. ``metrics`` holds:

    - ``n_steps``, ``dim``, ``seed``, ``k``, ``transfer``, ``world``, ``pca_explained_variance``;
    - ``events``: per event (corner, wall_end where the world has free ends, nothing) the best
      cluster's ``precision``, ``recall``, ``f1``, ``cluster``, the event's ``rate``, ``count``,
      ``probe_auc`` (a linear probe's, ``probes.probe_auc``) and ``probe_fit``: where the probe
      was fitted, ``"train split"`` with ``probe_fit`` (the training split's representation
      and events, ``world_events``), else ``"half of the steps"`` (a random half of ``z``);
    - ``memory``: ``memory_scores``; ``position``: ``position_scores``;
    - ``clusters``: per cluster ``id``, ``size``, ``share``, ``precision`` and ``lift``
      (precision / rate) per event, and ``strongest_event``: the event of highest lift among those
      with lift > 1 (None when none is over-represented);
    - ``walls_known`` and ``not_applicable``: with no ``world`` (a recording whose walls are
      unknown, named ``name``) the events that need walls, the distance behind and ``position``'s
      normalisation by the world's size cannot be had: the events are listed there as n/a, the
      distance behind is None, and positions are normalised by the region the poses cover.
    """
    z = check_z(z)
    poses = np.asarray(poses, dtype=np.float64)
    sensors = np.asarray(sensors, dtype=np.float64)
    if not (len(z) == len(poses) == len(sensors)):
        raise ValueError(
            f"z, sensors and poses differ in rows: {len(z)}, {len(sensors)}, {len(poses)}"
        )
    if sensors.ndim != 2 or sensors.shape[1] != len(layout.angles) or poses.shape[1:] != (3,):
        raise ValueError(
            f"sensors must be (N, {len(layout.angles)}) for the layout's rays and poses (N, 3), "
            f"got {sensors.shape} and {poses.shape}"
        )
    transfer = kmeans is not None
    pca = pca if pca is not None else fit_pca(z, seed)
    kmeans = kmeans if kmeans is not None else fit_kmeans(z, k, seed)
    k = int(kmeans.n_clusters)
    labels = assign_clusters(kmeans, z)
    pc = project_2d(pca, z)

    events = world_events(world, sensors, poses, layout)
    behind = ev.distance_behind(world, poses) if world is not None else None
    tables = {name: cluster_event_table(labels, e, k) for name, e in events.items()}
    rates = {name: float(e.mean()) for name, e in events.items()}
    size = np.bincount(labels, minlength=k)
    clusters = []
    for c in range(k):
        precision = {name: float(t["precision"][c]) for name, t in tables.items()}
        lift = {name: (precision[name] / rates[name] if rates[name] > 0 else 0.0) for name in rates}
        over = {name: v for name, v in lift.items() if v > 1.0}
        clusters.append(
            {
                "id": c,
                "size": int(size[c]),
                "share": float(size[c] / len(z)),
                "precision": precision,
                "lift": lift,
                "strongest_event": max(over, key=over.get) if over else None,
            }
        )
    metrics = {
        "world": world.name if world is not None else name,
        "walls_known": world is not None,
        "not_applicable": [] if world is not None else [*WALL_EVENTS, "distance_behind"],
        "n_steps": len(z),
        "dim": int(z.shape[1]),
        "seed": seed,
        "k": k,
        "transfer": transfer,
        "pca_explained_variance": [float(v) for v in pca.explained_variance_ratio_],
        "events": {
            name: {**event_scores(labels, e, k), **_event_probe(z, e, name, seed, probe_fit)}
            for name, e in events.items()
        },
        "memory": memory_scores(z, labels, events["nothing"], behind, seed, k),
        "position": position_scores(z, poses, seed, _region_size(world, poses)),
        "clusters": clusters,
    }
    truth = {**events} if behind is None else {**events, "distance_behind": behind}
    return RepresentationAnalysis(metrics, labels, pc, kmeans, pca, truth)


def _event_probe(z, event, name: str, seed: int, fit) -> dict:
    """``probe_auc`` of one event, fitted on the training split's steps where ``fit`` has
    them (scored on all of ``z``), else on a random half of ``z``."""
    if fit is None or name not in fit[1]:
        return {"probe_auc": probe_auc(z, event, seed), "probe_fit": "half of the steps"}
    z_fit, events_fit = fit
    auc = probe_auc(z, event, fit=(z_fit, events_fit[name]))
    return {"probe_auc": auc, "probe_fit": "train split"}


def _region_size(world: World | None, poses: np.ndarray) -> tuple[float, float]:
    """What positions are normalised by: the world's size, or the extent of the poses when the
    walls are unknown (1 along a side the poses do not spread over)."""
    if world is not None:
        return (world.width, world.height)
    span = np.ptp(np.asarray(poses, dtype=np.float64)[:, :2], axis=0)
    return tuple(float(v) if v > 0 else 1.0 for v in span)
