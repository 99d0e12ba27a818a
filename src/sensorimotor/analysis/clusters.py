"""PCA, k-means and how clusters line up with ground-truth events.

PCA to 2-D (paper Fig. 4) and k-means with k = 20 (Figs. 5-8), scikit-learn with a fixed seed
and a fixed ``n_init`` so that the same input gives the same clusters. For an event and each
cluster c: precision ``P(event | c)``, recall ``P(c | event)`` and their F1; the best cluster by
F1 answers "did a corner cluster emerge?".
"""

from __future__ import annotations

import numpy as np
from sklearn.cluster import KMeans
from sklearn.decomposition import PCA

N_CLUSTERS = 20  # the paper's k
KMEANS_N_INIT = 4  # k-means restarts (fixed: the result must not depend on sklearn's default)


def check_z(z: np.ndarray, n: int | None = None) -> np.ndarray:
    """``z`` as a finite float64 (N, D) array (a 1-d array is one column); ValueError if not."""
    z = np.asarray(z, dtype=np.float64)
    if z.ndim == 1:
        z = z[:, None]
    if z.ndim != 2:
        raise ValueError(f"a representation must have shape (N, D), got {z.shape}")
    if n is not None and len(z) != n:
        raise ValueError(f"representation has {len(z)} rows, expected {n}")
    if not np.isfinite(z).all():
        raise ValueError("representation contains NaN or inf")
    return z


# ---------------------------------------------------------------------------------------------
# PCA and k-means


def fit_pca(z: np.ndarray, seed: int = 0) -> PCA:
    """A 2-component PCA (full SVD: deterministic) of ``z``; fewer components if D < 2."""
    z = check_z(z)
    return PCA(n_components=min(2, z.shape[1]), svd_solver="full", random_state=seed).fit(z)


def project_2d(pca: PCA, z: np.ndarray) -> np.ndarray:
    """(N, 2) coordinates in a fitted PCA's plane (a second column of zeros if D was 1)."""
    pc = pca.transform(check_z(z))
    return np.pad(pc, ((0, 0), (0, 2 - pc.shape[1]))) if pc.shape[1] < 2 else pc


def pca_2d(z: np.ndarray, seed: int = 0) -> np.ndarray:
    """(N, 2): ``z`` projected on its first two principal components."""
    return project_2d(fit_pca(z, seed), z)


def fit_kmeans(z: np.ndarray, k: int = N_CLUSTERS, seed: int = 0) -> KMeans:
    """k-means (scikit-learn, Lloyd, ``n_init = KMEANS_N_INIT``, ``random_state = seed``)."""
    z = check_z(z)
    if len(z) < k:
        raise ValueError(f"k-means with k = {k} needs at least {k} steps, got {len(z)}")
    return KMeans(n_clusters=k, n_init=KMEANS_N_INIT, random_state=seed).fit(z)


def assign_clusters(model: KMeans, z: np.ndarray) -> np.ndarray:
    """(N,) int cluster index of each step under a fitted k-means."""
    z = check_z(z)
    if z.shape[1] != model.n_features_in_:
        raise ValueError(
            f"k-means was fitted on {model.n_features_in_}-d representations, got {z.shape[1]}-d"
        )
    return model.predict(z).astype(np.int64)


# ---------------------------------------------------------------------------------------------
# Events against clusters


def cluster_event_table(labels: np.ndarray, event: np.ndarray, k: int | None = None) -> dict:
    """Per cluster c (arrays of length k): size, precision P(event|c), recall P(c|event), F1.

    An empty cluster has precision 0; with no event at all every recall is 0.
    """
    labels = np.asarray(labels, dtype=np.int64)
    event = np.asarray(event, dtype=bool)
    if labels.shape != event.shape:
        raise ValueError(f"labels {labels.shape} and event {event.shape} differ in shape")
    k = int(labels.max()) + 1 if k is None else k
    size = np.bincount(labels, minlength=k)[:k].astype(np.float64)
    hits = np.bincount(labels[event], minlength=k)[:k].astype(np.float64)
    precision = np.divide(hits, size, out=np.zeros(k), where=size > 0)
    recall = hits / event.sum() if event.any() else np.zeros(k)
    denom = precision + recall
    f1 = np.divide(2 * precision * recall, denom, out=np.zeros(k), where=denom > 0)
    return {"size": size, "precision": precision, "recall": recall, "f1": f1}


def event_scores(labels: np.ndarray, event: np.ndarray, k: int | None = None) -> dict:
    """The best single cluster for an event (by F1): its precision, recall, F1 and index.

    Also the event's base rate and count. ``cluster`` is None when the event never occurs.
    """
    event = np.asarray(event, dtype=bool)
    table = cluster_event_table(labels, event, k)
    best = int(np.argmax(table["f1"]))
    found = bool(event.any())
    return {
        "precision": float(table["precision"][best]) if found else 0.0,
        "recall": float(table["recall"][best]) if found else 0.0,
        "f1": float(table["f1"][best]) if found else 0.0,
        "cluster": best if found else None,
        "rate": float(event.mean()) if event.size else 0.0,
        "count": int(event.sum()),
    }
