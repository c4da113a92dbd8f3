"""Anchor concepts: K-means per action over anchor poses (paper §3.1.2).

Anchors are clustered as root-relative poses (the root joint subtracted), so a concept is a body
pose wherever the body stands. The cluster centres are the anchor concepts.

Number of clusters: 8 per action by default. Measured on HumanAct12 anchors at λ = 200
(``motion-refiner bench concepts`` prints the table): the RMS joint distance to the nearest centre
falls steeply up to 6-8 clusters and by under 5 % per extra pair after that, the silhouette has no
clear peak (0.13-0.52 across actions and k = 2..16), and 8 keeps at least 20 anchors per cluster
for the smallest action (sit, 162 anchors).
"""
from __future__ import annotations

import os

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.cluster import KMeans

from refiner.core.serialization import check_metadata, load_state, pack_metadata, save_state
from refiner.core.validation import check_is_fitted, check_joints, check_random_state

__all__ = ["AnchorConcepts", "root_relative"]

_NOT_FITTED = "This %(name)s is not fitted yet; call fit() or load() first."


def root_relative(poses, root: int = 0) -> np.ndarray:
    """Poses ``(..., J, 3)`` with the root joint subtracted from every joint."""
    poses = np.asarray(poses)
    return poses - poses[..., root : root + 1, :]


class AnchorConcepts(BaseEstimator):
    """Per-action K-means over anchor poses; the centres are the anchor concepts.

    Parameters
    ----------
    n_clusters : int, default=8
        Concepts per action (fewer for an action with fewer distinct anchors).
    n_init : int, default=4
        K-means restarts.
    random_state : int or None, default=0

    Attributes
    ----------
    centers_ : list of ndarray, one per action, each of shape (K_a, J, 3), float32
        Root-relative concept poses in metres.
    n_actions_ : int
    n_joints_ : int
    counts_ : list of ndarray of int
        Anchors assigned to each concept during fit.
    """

    def __init__(self, n_clusters: int = 8, *, n_init: int = 4, random_state: int | None = 0):
        self.n_clusters = n_clusters
        self.n_init = n_init
        self.random_state = random_state

    def fit(self, poses, actions, *, n_actions: int | None = None) -> "AnchorConcepts":
        """Cluster anchor poses action by action.

        Parameters
        ----------
        poses : array-like of shape (N, J, 3)
            Anchor poses in metres (any translation; the root is subtracted here).
        actions : array-like of int, shape (N,)
        n_actions : int, optional
            Size of the label set; default ``max(actions) + 1``. Every action needs an anchor.
        """
        if not isinstance(self.n_clusters, (int, np.integer)) or self.n_clusters < 1:
            raise ValueError(f"`n_clusters` must be a positive int; got {self.n_clusters!r}.")
        x = check_joints(poses, name="poses", min_frames=1)
        actions = np.asarray(actions)
        if actions.shape != (len(x),) or not np.issubdtype(actions.dtype, np.integer) or (actions < 0).any():
            raise ValueError(f"`actions` must be {len(x)} non-negative ints; got shape {actions.shape}.")
        n_actions = int(actions.max()) + 1 if n_actions is None else int(n_actions)
        rng = check_random_state(self.random_state)
        feats = root_relative(x)
        centers, counts = [], []
        for a in range(n_actions):
            group = feats[actions == a]
            if len(group) == 0:
                raise ValueError(f"action {a} has no anchors to cluster.")
            k = int(min(self.n_clusters, len(np.unique(group.reshape(len(group), -1), axis=0))))
            km = KMeans(k, n_init=self.n_init, random_state=int(rng.integers(2**31))).fit(group.reshape(len(group), -1))
            centers.append(km.cluster_centers_.reshape(k, *x.shape[1:]).astype(np.float32))
            counts.append(np.bincount(km.labels_, minlength=k).astype(np.int64))
        self.centers_ = centers
        self.counts_ = counts
        self.n_actions_ = n_actions
        self.n_joints_ = x.shape[1]
        return self

    def predict(self, poses, actions) -> np.ndarray:
        """Index of the nearest concept of each pose's action, ``(N,)`` int."""
        return self._nearest(poses, actions)[0]

    def distance(self, poses, actions) -> np.ndarray:
        """MPJPE (metres) from each root-relative pose to its nearest concept, ``(N,)``."""
        return self._nearest(poses, actions)[1]

    def _nearest(self, poses, actions) -> tuple[np.ndarray, np.ndarray]:
        """Index of, and MPJPE to, the nearest concept of each pose's action."""
        check_is_fitted(self, msg=_NOT_FITTED)
        x = root_relative(check_joints(poses, name="poses", min_frames=1))
        actions = self._check_actions(actions, len(x))
        index, distance = np.empty(len(x), dtype=np.int64), np.empty(len(x), dtype=np.float64)
        for a in np.unique(actions):
            sel = actions == a
            d = np.linalg.norm(x[sel][:, None] - self.centers_[a][None], axis=-1).mean(-1)  # (n, K) MPJPE
            index[sel], distance[sel] = d.argmin(1), d.min(1)
        return index, distance

    def concept(self, action: int, index: int) -> np.ndarray:
        """The root-relative pose ``(J, 3)`` of one concept."""
        check_is_fitted(self, msg=_NOT_FITTED)
        return self.centers_[action][index].copy()

    @property
    def n_concepts_(self) -> list[int]:
        return [len(c) for c in self.centers_]

    def save(self, path: str | os.PathLike) -> None:
        """Write the concepts to one ``.safetensors`` file."""
        check_is_fitted(self, msg=_NOT_FITTED)
        tensors = {f"centers.{a}": c for a, c in enumerate(self.centers_)}
        tensors.update({f"counts.{a}": c for a, c in enumerate(self.counts_)})
        save_state(path, tensors, pack_metadata(self, n_actions_=self.n_actions_, n_joints_=self.n_joints_))

    @classmethod
    def load(cls, path: str | os.PathLike) -> "AnchorConcepts":
        tensors, metadata = load_state(path)
        params, fitted = check_metadata(path, metadata, cls)
        obj = cls(**params)
        obj.n_actions_ = int(fitted["n_actions_"])
        obj.n_joints_ = int(fitted["n_joints_"])
        obj.centers_ = [tensors[f"centers.{a}"] for a in range(obj.n_actions_)]
        obj.counts_ = [tensors[f"counts.{a}"] for a in range(obj.n_actions_)]
        return obj

    def _check_actions(self, actions, n: int) -> np.ndarray:
        actions = np.asarray(actions)
        if actions.ndim == 0:
            actions = np.full(n, int(actions))
        if actions.shape != (n,) or not np.issubdtype(actions.dtype, np.integer):
            raise ValueError(f"`actions` must be {n} ints; got shape {actions.shape}.")
        if ((actions < 0) | (actions >= self.n_actions_)).any():
            raise ValueError(f"`actions` must be in 0..{self.n_actions_ - 1}; got {sorted(set(actions.tolist()))}.")
        return actions
