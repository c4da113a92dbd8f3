"""Distribution metrics of the Action2Motion protocol (FID, A-FID, accuracy, diversity, multimodality).

Definitions follow ``generator_formats.md`` §8.4 (Action2Motion's ``final_evaluation.py`` and
``fid.py``, copied faithfully by ACTOR and MLD) and the paper's appendix B.2. All of them but
:func:`mpjpe` work on the 30-d features and logits of an
:class:`~refiner.evaluation.action_recognizer.ActionRecognizer`, so they are unitless. Randomness always
comes from an explicit ``random_state``; the global RNGs are never touched. The replicated protocol that
combines them, :func:`~refiner.evaluation.protocol.evaluate`, is :mod:`refiner.evaluation.protocol`
(``Evaluation`` and ``evaluate`` are found here as well).
"""
from __future__ import annotations

import numpy as np
import scipy.linalg

from refiner.core.motion import Motion
from refiner.core.validation import check_random_state, to_numpy

__all__ = [
    "frechet_distance",
    "fid",
    "action_fid",
    "accuracy",
    "confusion_matrix",
    "diversity",
    "multimodality",
    "mpjpe",
    "confidence_interval",
]

#: Names that live in :mod:`refiner.evaluation.protocol` (which imports this module) and are found here too.
_PROTOCOL = ("Evaluation", "evaluate")


def __getattr__(name: str):
    # imported on first use: the protocol module imports this one
    if name in _PROTOCOL:
        from refiner.evaluation import protocol

        return getattr(protocol, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _features(x, name: str) -> np.ndarray:
    arr = to_numpy(x, name=name).astype(np.float64)
    if arr.ndim != 2:
        raise ValueError(f"`{name}` must have shape (N, D); got {tuple(arr.shape)}.")
    if len(arr) < 2:
        raise ValueError(f"`{name}` needs at least 2 rows to estimate a covariance; got {len(arr)}.")
    if not np.isfinite(arr).all():
        raise ValueError(f"`{name}` contains NaN or Inf values.")
    return arr


def _labels(y, n: int, name: str) -> np.ndarray:
    arr = to_numpy(y, name=name)
    if arr.shape != (n,):
        raise ValueError(f"`{name}` must have shape ({n},); got {tuple(arr.shape)}.")
    if not np.all(arr == np.round(arr)):
        raise ValueError(f"`{name}` must hold integer class indices.")
    return arr.astype(np.int64)


def positive_int(value, name: str) -> int:
    """``value`` as an int when it is a positive integer; else a ValueError naming ``name``."""
    if not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"`{name}` must be a positive int; got {value!r}.")
    return int(value)


def frechet_distance(mu1, sigma1, mu2, sigma2, *, eps: float = 1e-6) -> float:
    """Fréchet distance between two Gaussians, with Action2Motion's numerical rules.

    ``d² = ||mu1 - mu2||² + tr(sigma1 + sigma2 - 2 sqrtm(sigma1 @ sigma2))`` with
    ``scipy.linalg.sqrtm``. If the square root is not finite, it is recomputed with ``eps * I`` added
    to both covariances. Imaginary parts (from numerical error) are dropped when every diagonal
    entry's imaginary part is at most 1e-3 in absolute value.

    Parameters
    ----------
    mu1, mu2 : array-like of shape (D,)
    sigma1, sigma2 : array-like of shape (D, D)
    eps : float, default=1e-6

    Returns
    -------
    float
        In squared feature units.

    Raises
    ------
    ValueError
        Mismatched shapes, or a square root whose imaginary diagonal exceeds 1e-3.
    """
    mu1, mu2 = np.atleast_1d(np.asarray(mu1, np.float64)), np.atleast_1d(np.asarray(mu2, np.float64))
    sigma1, sigma2 = np.atleast_2d(np.asarray(sigma1, np.float64)), np.atleast_2d(np.asarray(sigma2, np.float64))
    d = mu1.shape[0]
    if mu1.shape != (d,) or mu2.shape != (d,) or sigma1.shape != (d, d) or sigma2.shape != (d, d):
        raise ValueError(f"means must be (D,) and covariances (D, D) with one D; got {mu1.shape}, {sigma1.shape}, "
                         f"{mu2.shape}, {sigma2.shape}.")
    diff = mu1 - mu2
    covmean = scipy.linalg.sqrtm(sigma1 @ sigma2)
    if not np.isfinite(covmean).all():
        offset = np.eye(d) * eps
        covmean = scipy.linalg.sqrtm((sigma1 + offset) @ (sigma2 + offset))
    if np.iscomplexobj(covmean):
        worst = float(np.max(np.abs(np.diagonal(covmean).imag)))
        if worst > 1e-3:
            raise ValueError(f"sqrtm(sigma1 @ sigma2) has an imaginary component of {worst:.3g} on its diagonal; "
                             "the covariances are too ill-conditioned (too few samples?).")
        covmean = covmean.real
    return float(diff @ diff + np.trace(sigma1) + np.trace(sigma2) - 2.0 * np.trace(covmean))


def fid(features_a, features_b) -> float:
    """Fréchet distance between two feature sets (the "FID" of action-conditioned motion generation).

    Parameters
    ----------
    features_a, features_b : array-like of shape (N, D) and (M, D)
        Recogniser features, e.g. generated and real clips. N, M >= 2.

    Returns
    -------
    float
        :func:`frechet_distance` of the sample means and unbiased covariances
        (``np.cov(rowvar=False)``, N - 1). 0 for identical sets.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.random.default_rng(0).normal(size=(500, 3))
    >>> round(fid(f, f + [1.0, 0.0, 0.0]), 6)
    1.0
    """
    a, b = _features(features_a, "features_a"), _features(features_b, "features_b")
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"feature sets must share D; got {a.shape[1]} and {b.shape[1]}.")
    return frechet_distance(a.mean(0), np.cov(a, rowvar=False), b.mean(0), np.cov(b, rowvar=False))


def action_fid(
    features, labels, real_features, real_labels, *, n_per_action: int | None = 200, random_state=None
) -> dict[int, float]:
    """Per-action FID (A-FID, paper appendix B.2): FID within every action present in both sets.

    Parameters
    ----------
    features, real_features : array-like of shape (N, D) and (M, D)
    labels, real_labels : array-like of int, shape (N,) and (M,)
    n_per_action : int or None, default=200
        Samples per action on each side, drawn without replacement; an action with fewer samples
        uses all of them. None uses all samples.
    random_state : None, int or numpy Generator

    Returns
    -------
    dict of int to float
        Action index -> FID; actions with fewer than 2 samples on a side are left out.
    """
    f, r = _features(features, "features"), _features(real_features, "real_features")
    y, yr = _labels(labels, len(f), "labels"), _labels(real_labels, len(r), "real_labels")
    rng = check_random_state(random_state)
    out = {}
    for a in np.intersect1d(y, yr):
        sides = []
        for feats, lab in ((f, y), (r, yr)):
            idx = np.flatnonzero(lab == a)
            if n_per_action is not None and len(idx) > n_per_action:
                idx = rng.choice(idx, n_per_action, replace=False)
            sides.append(feats[idx])
        if min(len(s) for s in sides) >= 2:
            out[int(a)] = fid(*sides)
    return out


def confusion_matrix(predictions, labels, n_classes: int) -> np.ndarray:
    """``C[true, predicted]`` counts, ``(n_classes, n_classes)`` int64."""
    pred = _labels(predictions, np.shape(predictions)[0], "predictions")
    y = _labels(labels, len(pred), "labels")
    if pred.size and (min(pred.min(), y.min()) < 0 or max(pred.max(), y.max()) >= n_classes):
        raise ValueError(f"class indices must be in 0..{n_classes - 1}.")
    cm = np.zeros((n_classes, n_classes), dtype=np.int64)
    np.add.at(cm, (y, pred), 1)
    return cm


def accuracy(predictions, labels) -> float:
    """Action-recognition accuracy: the fraction of clips whose predicted class equals their label.

    Parameters
    ----------
    predictions : array-like of shape (N,) int, or (N, C) logits (argmax taken)
    labels : array-like of shape (N,) int

    Returns
    -------
    float in [0, 1]
        ``trace(confusion) / N`` as Action2Motion.
    """
    pred = to_numpy(predictions, name="predictions")
    if pred.ndim == 2:
        pred = pred.argmax(1)
    if pred.ndim != 1 or len(pred) == 0:
        raise ValueError(f"`predictions` must have shape (N,) or (N, C) with N > 0; got {tuple(pred.shape)}.")
    y = _labels(labels, len(pred), "labels")
    return float(np.mean(pred.astype(np.int64) == y))


def diversity(features, *, n_pairs: int = 200, random_state=None) -> float:
    """Diversity: mean distance between the features of random pairs of clips (S_d = 200).

    Both index vectors are drawn independently and uniformly with replacement over all clips, so a
    pair may repeat a clip (Action2Motion ``final_evaluation.py``).

    Parameters
    ----------
    features : array-like of shape (N, D)
    n_pairs : int, default=200
        S_d.
    random_state : None, int or numpy Generator

    Returns
    -------
    float
        Mean Euclidean distance, in feature units.
    """
    f = _features(features, "features")
    n_pairs = positive_int(n_pairs, "n_pairs")
    rng = check_random_state(random_state)
    first = rng.integers(0, len(f), n_pairs)
    second = rng.integers(0, len(f), n_pairs)
    return float(np.linalg.norm(f[first] - f[second], axis=1).mean())


def multimodality(features, labels, *, n_per_label: int = 20, random_state=None) -> float:
    """Multimodality: mean feature distance between random pairs of clips of the same action (S_m = 20).

    Exactly Action2Motion's sampler: every label present gets a quota of ``n_per_label``; repeatedly a
    random clip ``i`` is drawn; if its label still has quota, clips ``j`` are drawn uniformly until one
    has the same label (``j`` may equal ``i``), ``||f_i - f_j||`` is added and the quota decremented.

    Parameters
    ----------
    features : array-like of shape (N, D)
    labels : array-like of int, shape (N,)
    n_per_label : int, default=20
        S_m.
    random_state : None, int or numpy Generator

    Returns
    -------
    float
        ``sum / (n_per_label * number of labels present)``, in feature units. Labels absent from
        ``labels`` are skipped (Action2Motion assumes all are present).
    """
    f = _features(features, "features")
    y = _labels(labels, len(f), "labels")
    n_per_label = positive_int(n_per_label, "n_per_label")
    rng = check_random_state(random_state)
    present = np.unique(y)
    quota = dict.fromkeys(present.tolist(), int(n_per_label))
    left = len(present) * int(n_per_label)
    total = 0.0
    while left:
        i = int(rng.integers(len(f)))
        if quota[y[i]] == 0:
            continue
        j = int(rng.integers(len(f)))
        while y[j] != y[i]:
            j = int(rng.integers(len(f)))
        total += float(np.linalg.norm(f[i] - f[j]))
        quota[y[i]] -= 1
        left -= 1
    return total / (n_per_label * len(present))


def mpjpe(pred, target, *, mask=None) -> float:
    """Mean per-joint position error: mean Euclidean distance between corresponding joints.

    Parameters
    ----------
    pred, target : Motion or array-like of shape (..., T, J, 3)
        Metres.
    mask : array-like of bool, shape (T,), optional
        Frames to include (True = keep); default all.

    Returns
    -------
    float
        Metres (multiply by 100 for cm). NaN when the mask selects no frame.
    """
    a = to_numpy(pred.joints if isinstance(pred, Motion) else pred, name="pred").astype(np.float64)
    b = to_numpy(target.joints if isinstance(target, Motion) else target, name="target").astype(np.float64)
    if a.shape != b.shape or a.ndim < 3 or a.shape[-1] != 3:
        raise ValueError(f"`pred` and `target` must share a shape (..., T, J, 3); got {a.shape} and {b.shape}.")
    err = np.linalg.norm(a - b, axis=-1)  # (..., T, J)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != (a.shape[-3],):
            raise ValueError(f"`mask` must have shape ({a.shape[-3]},); got {m.shape}.")
        if not m.any():
            return float("nan")
        err = err[..., m, :]
    return float(err.mean())


def confidence_interval(values) -> tuple[float, float]:
    """Mean and 95 % half-width of replicated values: ``1.96 * std / sqrt(R)``, population std (ddof 0).

    Parameters
    ----------
    values : array-like of shape (R,)

    Returns
    -------
    (mean, half_width) : tuple of float
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == 0:
        raise ValueError("`values` is empty.")
    return float(v.mean()), float(1.96 * v.std() / np.sqrt(v.size))
