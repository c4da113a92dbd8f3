"""The Action2Motion evaluation protocol, replicated: FID, accuracy, diversity, multimodality (+ A-FID).

``generator_formats.md`` §8.4: every replication draws new random 60-frame crops, a new recogniser
hidden state and new diversity / multimodality pairs, and the figures are reported as the mean and 95 %
interval over replications. The single metrics are :mod:`refiner.evaluation.metrics`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from refiner.core.motion import Motion
from refiner.core.validation import check_random_state
from refiner.evaluation.metrics import (
    accuracy,
    action_fid,
    confidence_interval,
    diversity,
    fid,
    multimodality,
    positive_int,
)

__all__ = ["Evaluation", "evaluate"]


@dataclass
class Evaluation:
    """Replicated metrics of one evaluation.

    Attributes
    ----------
    values : dict of str to ndarray of shape (R,)
        Per replication: ``fid``, ``accuracy``, ``diversity``, ``multimodality`` of the generated
        clips; ``real_accuracy``, ``real_diversity``, ``real_multimodality`` of the real crops; with
        A-FID, ``a_fid`` (mean over actions) and ``a_fid:<action>``.
    n_replications : int
    """

    values: dict[str, np.ndarray] = field(default_factory=dict)
    n_replications: int = 0

    def mean(self, name: str) -> float:
        return confidence_interval(self.values[name])[0]

    def interval(self, name: str) -> float:
        """95 % half-width ``1.96 * std / sqrt(R)`` (population std)."""
        return confidence_interval(self.values[name])[1]

    def summary(self) -> dict[str, tuple[float, float]]:
        """``name -> (mean, 95 % half-width)`` for every metric."""
        return {k: confidence_interval(v) for k, v in self.values.items()}

    def __repr__(self) -> str:
        body = ", ".join(f"{k}={m:.3f}±{h:.3f}" for k, (m, h) in self.summary().items() if ":" not in k)
        return f"Evaluation(R={self.n_replications}, {body})"


def _clip_labels(motions: Sequence[Motion], name: str) -> np.ndarray:
    labels = []
    for i, m in enumerate(motions):
        if not isinstance(m, Motion):
            raise ValueError(f"`{name}` must be a sequence of Motion; item {i} is {type(m).__name__}.")
        if m.action is None:
            raise ValueError(f"`{name}` clip {i} has no action label; every clip needs `action`.")
        labels.append(m.action)
    if not labels:
        raise ValueError(f"`{name}` is empty.")
    return np.array(labels, dtype=np.int64)


def evaluate(
    recognizer,
    generated: Sequence[Motion] | Callable[[np.random.Generator], Sequence[Motion]],
    real: Sequence[Motion],
    *,
    n_replications: int = 20,
    n_generated: int | None = None,
    n_real: int | None = None,
    n_diversity: int = 200,
    n_multimodality: int = 20,
    a_fid: bool = False,
    n_a_fid: int = 200,
    match_labels: bool = False,
    random_state=0,
) -> Evaluation:
    """Action2Motion evaluation protocol, replicated: FID, accuracy, diversity, multimodality (+ A-FID).

    Every replication draws new random 60-frame crops, a new recogniser hidden state (in
    ``hidden="random"`` mode) and new diversity / multimodality pairs, all from one seeded stream.

    Parameters
    ----------
    recognizer : ActionRecognizer
    generated : sequence of Motion, or callable ``rng -> sequence of Motion``
        Clips to evaluate, each with its conditioning ``action``. A callable is called once per
        replication (Action2Motion generates a fresh set every time).
    real : sequence of Motion
        Real clips (e.g. a :class:`~refiner.io.datasets.MotionDataset`), each with ``action``.
    n_replications : int, default=20
    n_generated : int, optional
        Resample this many generated clips with replacement per replication; default all, once each.
    n_real : int, optional
        Real crops per replication, sampled with replacement (Action2Motion: 3000); default the
        number of generated clips used.
    n_diversity, n_multimodality : int, default=200, 20
        S_d and S_m.
    a_fid : bool, default=False
        Also compute per-action FID with ``n_a_fid`` samples per action and side.
    match_labels : bool, default=False
        Draw the real crops with the generated clips' label mixture (one real clip of the same action
        per generated clip, so ``n_real`` is ignored) instead of the real set's own mixture.
        Action2Motion does not (it compares uniformly drawn actions with the dataset's mixture); on
        HumanAct12 the mismatch alone adds about 0.7 to the FID of real held-out clips.
    random_state : None, int or numpy Generator, default=0

    Returns
    -------
    Evaluation
        ``mean(name)`` and ``interval(name)`` (95 %, ``1.96 σ / sqrt(R)``) of every metric.
    """
    positive_int(n_replications, "n_replications")
    for name, val in (("n_generated", n_generated), ("n_real", n_real)):
        if val is not None and (not isinstance(val, (int, np.integer)) or val < 2):
            raise ValueError(f"`{name}` must be an int >= 2 or None; got {val!r}.")
    real = list(real)
    real_labels = _clip_labels(real, "real")
    rng = check_random_state(random_state)
    values: dict[str, list[float]] = {}

    def add(key, value):
        values.setdefault(key, []).append(float(value))

    for _ in range(int(n_replications)):
        rep = np.random.default_rng(rng.integers(2**63 - 1))
        gen = list(generated(rep)) if callable(generated) else list(generated)
        gen_labels = _clip_labels(gen, "generated")
        if n_generated is not None:
            idx = rep.integers(0, len(gen), n_generated)
            gen, gen_labels = [gen[i] for i in idx], gen_labels[idx]
        if match_labels:
            missing = sorted(set(gen_labels.tolist()) - set(real_labels.tolist()))
            if missing:
                raise ValueError(f"`match_labels` needs real clips of every generated action; none for {missing}.")
            pools = {c: np.flatnonzero(real_labels == c) for c in np.unique(gen_labels)}
            real_idx = np.array([pools[c][rep.integers(len(pools[c]))] for c in gen_labels])
        else:
            real_idx = rep.integers(0, len(real), n_real if n_real is not None else len(gen))
        real_sel, real_sel_labels = [real[i] for i in real_idx], real_labels[real_idx]

        f_gen, logits = recognizer.features_and_logits(gen, crop="random", random_state=rep)
        f_real, real_logits = recognizer.features_and_logits(real_sel, crop="random", random_state=rep)
        add("fid", fid(f_gen, f_real))
        add("accuracy", accuracy(logits, gen_labels))
        add("diversity", diversity(f_gen, n_pairs=n_diversity, random_state=rep))
        add("multimodality", multimodality(f_gen, gen_labels, n_per_label=n_multimodality, random_state=rep))
        add("real_accuracy", accuracy(real_logits, real_sel_labels))
        add("real_diversity", diversity(f_real, n_pairs=n_diversity, random_state=rep))
        add("real_multimodality",
            multimodality(f_real, real_sel_labels, n_per_label=n_multimodality, random_state=rep))
        if a_fid:
            per = action_fid(f_gen, gen_labels, f_real, real_sel_labels, n_per_action=n_a_fid, random_state=rep)
            add("a_fid", np.mean(list(per.values())) if per else np.nan)
            for action, v in per.items():
                add(f"a_fid:{action}", v)
    return Evaluation({k: np.array(v) for k, v in values.items()}, int(n_replications))
