"""Numbers behind the paper's claims about a sensory representation (sections V.C-V.F).

Everything here works on any representation ``z`` (N, D) whose rows are aligned with a database
split's rows: a model's ``z_s``, or the raw readings scaled into [0, 1] (the paper's "sensory
space" baseline). Nothing here knows about models.

- **PCA** to 2-D (the paper's Fig. 4), **k-means** with k = 20 (Figs. 5-8); scikit-learn with a
  fixed seed and a fixed ``n_init``, so the same input gives the same clusters.
- **Event scores**: for a ground-truth event (``events.py``: corner / free wall end / nothing in
  view) and each cluster c, precision ``P(event | c)``, recall ``P(c | event)`` and their F1; the
  best cluster by F1 answers "did a corner cluster emerge?" (V.E: with motors yes, raw no).
- **Memory** (V.E): among steps with nothing in view, a ridge probe's R^2 for the distance to the
  wall behind (what only a memory can know), and how many clusters are mostly (> 50 %) nothing
  in view (one for memoryless models, several for the Recurrent-SM-encoder).
- **Position** (V.F says there is no global position): ridge-probe R^2 for x, y, cos and sin of
  the heading, and KNN-MSE (defined in ``knn_mse``).

Probes are fitted on a random half of the steps (fixed seed) and scored on the other half.
"""

from sensorimotor.analysis.analyze import RAW, analyze_files, representation_of, summary_lines
from sensorimotor.analysis.clusters import (
    KMEANS_N_INIT,
    N_CLUSTERS,
    assign_clusters,
    cluster_event_table,
    event_scores,
    fit_kmeans,
    fit_pca,
    pca_2d,
    project_2d,
)
from sensorimotor.analysis.probes import (
    KNN_K,
    KNN_MAX_POINTS,
    MOSTLY,
    RIDGE_ALPHA,
    knn_mse,
    memory_scores,
    position_scores,
    probe_r2,
)
from sensorimotor.analysis.representation import (
    RepresentationAnalysis,
    analyze_representation,
    scaled_readings,
    world_events,
)

# Raised whenever a metric's definition changes, so that ``reproduce`` redoes kept analyses.
# 2: KNN-MSE averages ties between identical representations (was: broken by search order).
# 3: corners and wall ends in view by the database's own lasers (was: always the paper's).
# 4: each event's linear-probe AUC beside its best cluster (events.NAME.probe_auc).
# 5: a recurrent model's first BURN_IN test steps (from the zero state) are left out (burn_in).
METRICS_VERSION = 5

__all__ = [
    "KMEANS_N_INIT",
    "KNN_K",
    "KNN_MAX_POINTS",
    "METRICS_VERSION",
    "MOSTLY",
    "N_CLUSTERS",
    "RAW",
    "RIDGE_ALPHA",
    "RepresentationAnalysis",
    "analyze_files",
    "analyze_representation",
    "assign_clusters",
    "cluster_event_table",
    "event_scores",
    "fit_kmeans",
    "fit_pca",
    "knn_mse",
    "memory_scores",
    "pca_2d",
    "position_scores",
    "probe_r2",
    "project_2d",
    "representation_of",
    "scaled_readings",
    "summary_lines",
    "world_events",
]
