"""Commands of the analysis layer: what the representations contain, and the map learned
from their cells."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from sensorimotor.cli.app import (
    DATABASE,
    MAX_CLONES,
    MAX_CLUSTERS,
    MAX_CONTEXTS,
    MAX_EM_ITERS,
    MAX_PAIRS,
    MAX_RESOLUTION,
    N_CONTEXTS,
    RESOLUTION,
    RUN,
    app,
    err_console,
    progress,
    reads,
    writes,
)
from sensorimotor.sim import MAX_SEED


@app.command()
@reads(run=RUN, data=DATABASE, fit_data=DATABASE)
@writes(folder="out")
def analyze(
    run: Annotated[
        str,
        typer.Argument(
            help="A run folder made by `sensorimotor train`, or `raw` for the readings / range."
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
    from sensorimotor.analysis.analyze import probe_lines

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
    if m["burn_in"]:
        print(f"  (the first {m['burn_in']} test steps, from the zero state, left out)")
    if m["fit_analysis"] is None:
        print("\n".join(probe_lines(m["probes"])))
    err_console.print("wrote " + ", ".join(str(p) for p in result.files), soft_wrap=True)


@app.command("map")
@reads(run=RUN, data=DATABASE, fit_data=DATABASE, test_data=DATABASE)
@writes(folder="out")
def map_cmd(
    run: Annotated[str, typer.Argument(help="A run folder, or `raw` for the readings / range.")],
    data: Annotated[Path, typer.Option(help="Database: the map is fitted on its train split.")],
    out: Annotated[Path, typer.Option(help="Output folder for map.json, GraphML, figures.")],
    clusters: Annotated[
        int, typer.Option(min=2, max=MAX_CLUSTERS, help="Cells: k of k-means.")
    ] = 20,
    clones: Annotated[
        int, typer.Option(min=1, max=MAX_CLONES, help="Clones per cell (K C N <= 40000).")
    ] = 20,
    contexts: Annotated[
        int,
        typer.Option(
            min=1, max=MAX_CONTEXTS, help="N: each clone split by the slow context (1: plain CSCG)."
        ),
    ] = N_CONTEXTS,
    fit_data: Annotated[
        Path | None, typer.Option(help="Fit the cells' k-means on this database (transfer).")
    ] = None,
    seed: Annotated[int, typer.Option(min=0, max=MAX_SEED, help="Seed of k-means and EM.")] = 0,
    pairs: Annotated[
        int,
        typer.Option(min=0, max=MAX_PAIRS, help="Start/goal pairs planned in the simulator."),
    ] = 300,
    em_iters: Annotated[
        int, typer.Option(min=1, max=MAX_EM_ITERS, help="EM iterations at most (n C^2 each).")
    ] = 100,
    tol: Annotated[
        float,
        typer.Option(min=0.0, max=1.0, help="EM stops when an iteration gains less (nats/step)."),
    ] = 1e-4,
    start: Annotated[
        str,
        typer.Option(help="EM's start: random, or fine (clones = clusters within each cell)."),
    ] = "random",
    pseudocount: Annotated[
        float,
        typer.Option(min=1e-9, max=1.0, help="EM's pseudocount on every transition (S a row)."),
    ] = 1e-3,
    test_data: Annotated[
        Path | None,
        typer.Option(help="Score on this fresh database's test split (same world and robot)."),
    ] = None,
    resolution: Annotated[
        float,
        typer.Option(
            min=1e-6, max=MAX_RESOLUTION, help="Louvain's resolution for the communities."
        ),
    ] = RESOLUTION,
) -> None:
    """Learn a map from a representation's cells: the cell graph and a cloned HMM (EM, Viterbi,
    each clone split by the slow context), scored on the test split (bits/step, localisation,
    rooms); see analysis/map/mapping.py."""
    from sensorimotor.analysis.map.mapping import check_settings, map_files, summary_lines

    check_settings(clusters, clones, contexts, start)
    with progress(f"mapping {run} on {data}") as update:

        def note(stage: str, i: int, number: float) -> None:
            if stage == "planning pair":
                update(message=f"planning pair {i} of {pairs}, success so far {number:.2f}")
            else:
                update(message=f"{stage} iteration {i}, {number:.4f} nats/step")

        result = map_files(
            *(run, data, out, clusters, clones, fit_data, seed),
            em_iters=em_iters,
            pairs=pairs,
            progress=note,
            contexts=contexts,
            tol=tol,
            start=start,
            pseudocount=pseudocount,
            test_data=test_data,
            resolution=resolution,
        )
    print("\n".join(summary_lines(result.metrics)))
    err_console.print("wrote " + ", ".join(str(p) for p in result.files), soft_wrap=True)
