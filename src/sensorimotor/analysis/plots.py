"""Figures of a representation's analysis (paper sections V.C-V.F); the walls come from ``plots``.

- ``plot_pca``: Fig. 4, a representation projected on its first two principal components,
  coloured by the smallest of the 5 readings (how near the wall the agent perceives is).
- ``plot_clusters``: Figs. 5-8, one small map per k-means cluster: 500 of the cluster's steps
  drawn at random, each an arrow at its true position pointing along its heading.
- ``plot_transfer``: Figs. 9-10, clusters fitted on world A drawn on world B's steps.

Like ``plots``, these take data and an optional Axes/Figure, build a bare ``Figure`` only when
none is given, and never save.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from sensorimotor.sim.plots import PANEL_SIZE, panel_size, plot_world, world_aspect
from sensorimotor.sim.world import World

N_ARROWS = 500  # steps drawn per cluster (the paper's number)
ARROW_LENGTH = 0.05  # arrow length, as a fraction of the world's larger side
ARROW_COLOR = "tab:blue"
NCOLS = 5  # panels per row: k = 20 gives the paper's 4 x 5 grid
CLUSTER_PANEL = 2.3  # inches, one cluster panel


def plot_pca(
    pc: np.ndarray,
    color: np.ndarray,
    ax: Axes | None = None,
    title: str | None = "PCA of the representation",
    colorbar: bool = True,
    cmap: str = "viridis",
    label: str = "smallest reading",
    seed: int = 0,
) -> Axes:
    """Paper Fig. 4: points ``pc`` (N, 2) coloured by ``color`` (N,), e.g. the smallest reading.

    Points are drawn in a fixed random order (``seed``) so no range of colours hides another;
    one rasterised scatter (``gid="pca"``). With ``colorbar`` a colour bar labelled ``label``.
    """
    pc = np.asarray(pc, dtype=np.float64)
    color = np.asarray(color, dtype=np.float64)
    if ax is None:
        ax = Figure(figsize=(PANEL_SIZE + 0.8, PANEL_SIZE), layout="constrained").add_subplot()
    order = np.random.default_rng(seed).permutation(len(pc))
    points = ax.scatter(
        pc[order, 0],
        pc[order, 1],
        c=color[order],
        s=1.5,
        cmap=cmap,
        linewidths=0,
        rasterized=True,
        gid="pca",
    )
    ax.set_xlabel("PC 1")
    ax.set_ylabel("PC 2")
    ax.tick_params(labelsize="small")
    if title:
        ax.set_title(title)
    if colorbar:
        ax.figure.colorbar(points, ax=ax, label=label, shrink=0.9)
    return ax


def pose_extent(poses: np.ndarray) -> tuple[float, float, float, float]:
    """``(x0, x1, y0, y1)``: the region a path covers, with a margin (a square one for a path
    along a line): where the clusters are drawn when the walls are unknown."""
    xy = np.asarray(poses, dtype=np.float64)[:, :2]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pad = 0.05 * max(float((hi - lo).max()), 1e-6)
    return lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad


def plot_cluster(
    world: World | None,
    poses: np.ndarray,
    ax: Axes | None = None,
    n_arrows: int = N_ARROWS,
    seed: int = 0,
    title: str | None = None,
    color: str = ARROW_COLOR,
    extent: tuple[float, float, float, float] | None = None,
) -> Axes:
    """One cluster: up to ``n_arrows`` of ``poses`` (M, 3) at random (``seed``) as arrows at their
    true position along their heading (one quiver, ``gid="arrows"``), over the walls; with no
    ``world`` (walls unknown), in ``extent`` (``pose_extent``; default these poses') alone."""
    poses = np.asarray(poses, dtype=np.float64)
    if world is not None:
        ax = plot_world(world, ax)
        length = ARROW_LENGTH * max(world.width, world.height)  # units
    else:
        x0, x1, y0, y1 = extent if extent is not None else pose_extent(poses)
        ax = ax if ax is not None else Figure(layout="constrained").add_subplot()
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
        length = ARROW_LENGTH * max(x1 - x0, y1 - y0)
    if len(poses) > n_arrows:
        poses = poses[np.sort(np.random.default_rng(seed).choice(len(poses), n_arrows, False))]
    ax.quiver(
        poses[:, 0],
        poses[:, 1],
        np.cos(poses[:, 2]),
        np.sin(poses[:, 2]),
        angles="xy",
        scale_units="xy",
        scale=1.0 / length,
        width=0.006,
        headwidth=3.5,
        headlength=4,
        headaxislength=3.5,
        color=color,
        alpha=0.6,
        gid="arrows",
        zorder=2,
    )
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title if title is not None else "", fontsize="small")
    return ax


def plot_clusters(
    world: World | None,
    poses: np.ndarray,
    labels: np.ndarray,
    seed: int = 0,
    n_arrows: int = N_ARROWS,
    titles: Sequence[str] | None = None,
    fig: Figure | None = None,
    clusters: Sequence[int] | None = None,
    ncols: int = NCOLS,
    suptitle: str | None = None,
) -> Figure:
    """Paper Figs. 5-8: one map per cluster (``clusters``; default one per title, else ``0 ..
    max(labels)``, so that a cluster no step falls in, as in a transfer, still gets its panel).

    ``poses`` (N, 3) and ``labels`` (N,) are aligned; panel c draws ``n_arrows`` of cluster c's
    steps at random (``seed + c``). ``titles[c]`` titles panel c (default ``#c share%``), e.g.
    ``RepresentationAnalysis.cluster_titles()``. Panels fill ``ncols`` columns (4 x 5 for k = 20).
    With no ``world`` (walls unknown), every panel shows the region all ``poses`` cover.
    """
    poses = np.asarray(poses, dtype=np.float64)
    labels = np.asarray(labels)
    if len(poses) != len(labels):
        raise ValueError(f"poses has {len(poses)} rows, labels {len(labels)}")
    if clusters is not None:
        ids = [int(c) for c in clusters]
    else:
        ids = list(range(len(titles) if titles is not None else int(labels.max()) + 1))
    ncols = min(ncols, len(ids))
    nrows = math.ceil(len(ids) / ncols)
    extent = pose_extent(poses) if world is None else None
    if fig is None:
        aspect = (
            world_aspect([world])
            if world is not None
            else (extent[3] - extent[2]) / (extent[1] - extent[0])
        )
        width, height = panel_size(aspect, CLUSTER_PANEL, labels=0.0)  # no ticks
        size = (width * ncols, (height + 0.25) * nrows + (0.4 if suptitle else 0))
        fig = Figure(figsize=size, layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    for ax, c in zip(axes, ids, strict=False):
        members = labels == c
        title = titles[c] if titles is not None else f"#{c}  {members.mean():.1%}"
        plot_cluster(world, poses[members], ax, n_arrows, seed + c, title, extent=extent)
    for ax in axes[len(ids) :]:
        ax.set_axis_off()
    if suptitle:
        fig.suptitle(suptitle)
    return fig


def plot_transfer(
    world: World | None,
    poses: np.ndarray,
    labels: np.ndarray,
    source: str,
    seed: int = 0,
    n_arrows: int = N_ARROWS,
    titles: Sequence[str] | None = None,
    fig: Figure | None = None,
    clusters: Sequence[int] | None = None,
    name: str | None = None,
) -> Figure:
    """Paper Figs. 9-10: clusters fitted on world ``source`` drawn on ``world``'s steps.

    ``labels`` are the steps of ``world`` assigned to the source's clusters; pick the clusters
    to show with ``clusters`` (the paper shows a few). Otherwise as ``plot_clusters``; ``name``
    names the steps' world (default ``world.name``; needed when the walls are unknown).
    """
    return plot_clusters(
        world,
        poses,
        labels,
        seed,
        n_arrows,
        titles,
        fig,
        clusters,
        suptitle=f"clusters fitted on {source}, applied to {name or world.name}",
    )
