"""Linear probes and KNN-MSE: what a representation knows of the distance behind and the pose.

Probes are ridge regressions on standardised features, fitted on a random half of the steps
(fixed seed) and scored (R^2) on the other half; the event probe (``probe_auc``) is fitted on the
training split where one is given, and scored on the test split.
"""

from __future__ import annotations

import numpy as np
from sklearn.linear_model import Ridge
from sklearn.metrics import r2_score
from sklearn.neighbors import NearestNeighbors
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from sensorimotor.analysis.clusters import check_z, cluster_event_table
from sensorimotor.stats import balanced_accuracy

KNN_K = 5  # neighbours in KNN-MSE
KNN_MAX_POINTS = 20_000  # KNN-MSE on a fixed random subsample above this many steps
RIDGE_ALPHA = 1.0  # ridge penalty of the probes, on standardised features
MOSTLY = 0.5  # a cluster is "mostly nothing in view" above this share


def _halves(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    order = np.random.default_rng(seed).permutation(n)
    return order[: n // 2], order[n // 2 :]


def probe_r2(z: np.ndarray, target: np.ndarray, seed: int = 0, alpha: float = RIDGE_ALPHA) -> float:
    """R^2 on a held-out half of a linear (ridge) probe from ``z`` to ``target``.

    The steps are split at random (``seed``) into a fitting half and a scoring half; features are
    standardised on the fitting half. 1 means the target is a linear function of ``z``; a
    representation that knows nothing of it scores about 0 (below 0 when the probe overfits).
    NaN with fewer than 4 steps, or where the target is constant on either half (every
    prediction would score 1 or 0 there: R^2 says nothing of a target that does not vary).
    """
    z = check_z(z)
    target = np.asarray(target, dtype=np.float64)
    if len(target) != len(z):
        raise ValueError(f"target has {len(target)} rows, representation {len(z)}")
    if len(z) < 4:
        return float("nan")
    fit, score = _halves(len(z), seed)
    if np.ptp(target[fit]) == 0 or np.ptp(target[score]) == 0:
        return float("nan")
    probe = make_pipeline(StandardScaler(), Ridge(alpha=alpha)).fit(z[fit], target[fit])
    return float(r2_score(target[score], probe.predict(z[score])))


def probe_auc(
    z: np.ndarray,
    event: np.ndarray,
    seed: int = 0,
    fit: tuple[np.ndarray, np.ndarray] | None = None,
) -> float | None:
    """ROC AUC of a linear (logistic, class-balanced) probe from ``z`` to a boolean ``event``
    (a corner in view): unlike the best single cluster's F1, it does not depend on k-means
    giving the event a cluster of its own. 0.5 is chance, 1 a linear separation.

    With ``fit`` (z_fit, event_fit: the training split's), the probe is fitted there and scored
    on all of ``z``; without, fitted on a random half of ``z`` and scored on the other
    (``probe_r2``'s halves). Features are standardised on the fitting steps. None (JSON null)
    where the fitting or the scored steps lack a class.
    """
    from sklearn.linear_model import LogisticRegression
    from sklearn.metrics import roc_auc_score

    z = check_z(z)
    event = np.asarray(event, dtype=bool)
    if len(event) != len(z):
        raise ValueError(f"event has {len(event)} rows, representation {len(z)}")
    if fit is None:
        if len(z) < 4:
            return None
        a, b = _halves(len(z), seed)
        return probe_auc(z[b], event[b], fit=(z[a], event[a]))
    z_fit, event_fit = check_z(fit[0]), np.asarray(fit[1], dtype=bool)
    if len(event_fit) != len(z_fit) or z_fit.shape[1] != z.shape[1]:
        raise ValueError(f"fitting steps {z_fit.shape} and events {event_fit.shape} do not match")
    if len(np.unique(event_fit)) < 2 or len(np.unique(event)) < 2:
        return None
    probe = make_pipeline(
        StandardScaler(), LogisticRegression(class_weight="balanced", max_iter=1000)
    )
    probe.fit(z_fit, event_fit)
    return float(roc_auc_score(event, probe.decision_function(z)))


def _subsample(n: int, m: int, seed: int) -> np.ndarray:
    """Sorted indices of a fixed random subset of ``min(n, m)`` of ``range(n)``."""
    if n <= m:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, m, replace=False))


def knn_mse(
    z: np.ndarray,
    positions: np.ndarray,
    world_size: tuple[float, float],
    k: int = KNN_K,
    max_points: int = KNN_MAX_POINTS,
    seed: int = 0,
) -> dict:
    """KNN-MSE (Lesort et al. 2017, state representation learning): are neighbours in ``z`` close
    in the world?

    With positions normalised by the world size, ``q_i = (x_i / width, y_i / height)`` in
    ``[0, 1]^2``, and ``N_k(i)`` the k nearest neighbours of step i in representation space
    (Euclidean, the step itself excluded)::

        KNN-MSE = mean_i  (1 / k) sum_{j in N_k(i)} |q_i - q_j|^2

    0 means representation neighbours share a place; neighbours drawn at random score
    ``chance`` (the same mean over random pairs; about 1/3 for uniform occupancy). Above
    ``max_points`` steps a fixed random subsample (``seed``) is used for both.

    Identical representations (every "nothing in view" reading of ``raw`` or S is one point)
    tie: of g identical candidates for the last r places, each counts r / g, the mean over
    all ways to break the tie. Breaking it by search order instead would pick steps close in
    time, hence in space, and score a representation that cannot tell them apart as if it did.
    """
    z = check_z(z)
    q = np.asarray(positions, dtype=np.float64)[:, :2] / np.asarray(world_size, dtype=np.float64)
    idx = _subsample(len(z), max_points, seed)
    z, q = z[idx], q[idx]
    if len(z) <= k:
        return {"knn_mse": float("nan"), "chance": float("nan"), "points": len(z), "k": k}
    err = _tied_knn_sq(z, q, k).mean() / k
    partner = np.random.default_rng(seed + 1).permutation(len(q))
    chance = ((q - q[partner]) ** 2).sum(axis=1).mean()
    return {"knn_mse": float(err), "chance": float(chance), "points": len(z), "k": k}


def _tied_knn_sq(z: np.ndarray, q: np.ndarray, k: int) -> np.ndarray:
    """(N,) sum over each step's k nearest neighbours in ``z`` of |q_i - q_j|^2, ties between
    identical rows of ``z`` averaged (see ``knn_mse``).

    The search runs over the distinct rows (groups); a group's sums of q and |q|^2 give the
    mean |q_i - q_j|^2 from step i over the group's steps without visiting them."""
    groups, inv, counts = np.unique(z, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    sum_q = np.zeros((len(groups), q.shape[1]))
    np.add.at(sum_q, inv, q)
    norm = (q * q).sum(axis=1)  # |q_i|^2
    sum_norm = np.bincount(inv, weights=norm, minlength=len(groups))

    def sum_sq(g: np.ndarray) -> np.ndarray:  # sum over group g's steps of |q_i - q_j|^2
        return counts[g] * norm - 2 * (q * sum_q[g]).sum(axis=1) + sum_norm[g]

    # the own group first: its other steps are at distance 0 (i itself adds 0 to sum_sq)
    size = counts[inv]
    own = np.minimum(size - 1, k)
    total = own * sum_sq(inv) / np.maximum(size - 1, 1)
    left = k - own
    # then the nearest other groups, in order; k + 1 nearest groups always fill k places
    near = NearestNeighbors(n_neighbors=min(k + 1, len(groups))).fit(groups)
    order = near.kneighbors(groups, return_distance=False)  # (G, k + 1), own group included
    for rank in range(order.shape[1]):
        g = order[inv, rank]
        take = np.where(g != inv, np.minimum(left, counts[g]), 0)
        total += take * sum_sq(g) / counts[g]
        left -= take
    return total


def position_scores(
    z: np.ndarray, poses: np.ndarray, seed: int = 0, world_size: tuple[float, float] = (50, 50)
) -> dict:
    """Ridge-probe R^2 for x, y, cos(heading), sin(heading), and KNN-MSE (see ``knn_mse``)."""
    z = check_z(z, len(poses))
    poses = np.asarray(poses, dtype=np.float64)
    targets = {
        "x": poses[:, 0],
        "y": poses[:, 1],
        "cos_heading": np.cos(poses[:, 2]),
        "sin_heading": np.sin(poses[:, 2]),
    }
    r2 = {f"r2_{name}": probe_r2(z, t, seed) for name, t in targets.items()}
    out: dict = {k: None if np.isnan(v) else v for k, v in r2.items()}  # n/a: JSON null
    knn = knn_mse(z, poses, world_size, seed=seed)
    out.update(
        knn_mse=knn["knn_mse"],
        knn_mse_chance=knn["chance"],
        knn_points=knn["points"],
        knn_k=knn["k"],
    )
    return out


def memory_scores(
    z: np.ndarray,
    labels: np.ndarray,
    nothing: np.ndarray,
    behind: np.ndarray | None,
    seed: int = 0,
    k: int | None = None,
) -> dict:
    """Memory while nothing is in view: R^2 of the distance behind (None where it is unknown:
    ``behind`` None, walls unknown), and "nothing" clusters."""
    nothing = np.asarray(nothing, dtype=bool)
    table = cluster_event_table(labels, nothing, k)
    mostly = np.flatnonzero((table["precision"] > MOSTLY) & (table["size"] > 0))
    known = behind is not None and nothing.any()
    r2 = probe_r2(check_z(z)[nothing], np.asarray(behind)[nothing], seed) if known else None
    return {
        "n_nothing": int(nothing.sum()),
        "distance_behind_r2": None if r2 is None or np.isnan(r2) else r2,
        "distance_behind_mean": float(np.mean(behind[nothing])) if known else None,
        "nothing_clusters": len(mostly),
        "nothing_cluster_ids": mostly.tolist(),
    }


BURN_IN = 200  # steps a recurrent memory is given at the start of a split before it is scored
PROBE_FIT_MAX = 100_000  # training-split steps a place or event probe is fitted on (its first ones)


def place_probes(
    z_fit: np.ndarray,
    poses_fit: np.ndarray,
    z: np.ndarray,
    poses: np.ndarray,
    rooms_fit: np.ndarray | None = None,
    rooms: np.ndarray | None = None,
    world_size: tuple[float, float] = (50, 50),
    burn_in: int = BURN_IN,
) -> dict:
    """Where the robot is, read linearly from the representation: probes fitted on one split
    (``z_fit``, the training split's) and scored on another (``z``, the test split's), each
    after its first ``burn_in`` steps (a memory starts empty).

    - ``room.balanced_accuracy``: class-balanced logistic regression from z to the room
      (steps outside every room left out; None without rooms, or with fewer than two in either
      split); ``room.chance`` is 1 / rooms.
    - ``position.r2.{x,y}``: ridge regression R^2; ``position.median_error``: the median
      distance (world units) between the probed (x, y) and the true one.
    - ``knn_mse``: ``knn_mse`` of the scored steps (with its ``chance``).
    Features are standardised on the fitting split.
    """
    from sklearn.linear_model import LogisticRegression

    z_fit, z = check_z(z_fit, len(poses_fit)), check_z(z, len(poses))
    if min(len(z_fit), len(z)) <= burn_in + KNN_K:
        raise ValueError(f"too few steps to probe after a burn-in of {burn_in}")
    fit = np.arange(burn_in, len(z_fit))
    score = np.arange(burn_in, len(z))
    xf, x = z_fit[fit], z[score]
    pf, p = np.asarray(poses_fit, np.float64)[fit, :2], np.asarray(poses, np.float64)[score, :2]
    ridge = make_pipeline(StandardScaler(), Ridge(alpha=RIDGE_ALPHA)).fit(xf, pf)
    guess = ridge.predict(x)
    r2 = {axis: float(r2_score(p[:, i], guess[:, i])) for i, axis in enumerate("xy")}
    room = None
    if rooms_fit is not None and rooms is not None:
        rf, rs = np.asarray(rooms_fit)[fit], np.asarray(rooms)[score]
        inf, ins = rf >= 0, rs >= 0
        if len(np.unique(rf[inf])) >= 2 and len(np.unique(rs[ins])) >= 2:
            clf = make_pipeline(
                StandardScaler(), LogisticRegression(class_weight="balanced", max_iter=1000)
            )
            clf.fit(xf[inf], rf[inf])
            acc = balanced_accuracy(rs[ins], clf.predict(x[ins]))
            room = {"balanced_accuracy": acc, "chance": 1 / len(np.unique(rf[inf]))}
    knn = knn_mse(x, p, world_size)
    return {
        "burn_in": burn_in,
        "fit_steps": len(fit),
        "scored_steps": len(score),
        "room": room,
        "position": {
            "r2": r2,
            "median_error": float(np.median(np.linalg.norm(guess - p, axis=1))),
        },
        "knn_mse": {"value": knn["knn_mse"], "chance": knn["chance"]},
    }
