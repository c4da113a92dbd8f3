"""``motion-refiner bench concepts``: segmentation speed and fit on HumanAct12, and the anchor K-means.

The record (``concepts.json``): ``clips``, ``frames``, ``penalty`` (the default λ), ``segment_seconds``
(segmenting every clip at that λ), ``penalties`` (per λ of 100, 200, 300, 400: transitions per clip,
mean transition frames, MPJPE of the spline reconstruction in cm over all frames and as the mean of
the actions, and the paper's Table 2 MPJPE) and ``kmeans`` (per action: anchors and the mean joint
distance in cm to the assigned centre for 2, 4, 8, 12 and 16 clusters; None with fewer anchors).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from refiner.concepts.segmentation import DEFAULT_PENALTY, segment
from refiner.evaluation.bench_setup import Progress, ignore_progress, load_bench_humanact12, write_record

__all__ = ["bench_concepts"]

#: The paper's Table 2 per λ: spline-reconstruction MPJPE (cm).
_PAPER = {100: 0.89, 200: 0.94, 300: 1.08, 400: 1.22}
_CLUSTERS = (2, 4, 8, 12, 16)


def bench_concepts(data: Path | None, out: Path | None, quick: bool, *, weights: Path | None = None,
                   progress: Progress | None = None) -> dict:
    """Segmentation speed on all HumanAct12 clips, the λ table beside the paper's Table 2, K-means.

    ``quick`` keeps every 40th clip. Progress events: ``"segmented"`` (the record so far, once the
    clips are segmented at the default λ) and ``"penalty"`` (each row of ``penalties``). ``weights`` is
    accepted like every suite's and not used (no refiner runs here).
    """
    # sklearn.cluster takes a quarter of a second to import: here, so that importing the suites
    # (``motion-refiner --help``) stays cheap
    from sklearn.cluster import KMeans

    from refiner.concepts.anchors import root_relative

    progress = progress or ignore_progress
    dataset = load_bench_humanact12(data)
    if quick:
        dataset = dataset.subset(range(0, len(dataset), 40))

    t0 = time.perf_counter()
    segs = [segment(m.joints, penalty=DEFAULT_PENALTY) for m in dataset]
    seconds = time.perf_counter() - t0
    rec = {"clips": len(dataset), "frames": dataset.n_frames, "penalty": DEFAULT_PENALTY,
           "segment_seconds": seconds, "penalties": [], "kmeans": []}
    progress("segmented", rec)

    for lam in (100.0, 200.0, 300.0, 400.0):
        seg_l = segs if lam == DEFAULT_PENALTY else [segment(m.joints, penalty=lam) for m in dataset]
        n_trans = np.array([s.n_transitions for s in seg_l])
        durations = np.concatenate([s.durations for s in seg_l])
        err = [np.linalg.norm(s.reconstruct() - m.joints, axis=-1) for s, m in zip(seg_l, dataset)]
        overall = 100 * np.concatenate([e.ravel() for e in err]).mean()
        per_action = [100 * np.concatenate([e.ravel() for e, m in zip(err, dataset) if m.action == a]).mean()
                      for a in np.unique(dataset.actions)]
        r = {"penalty": lam, "transitions_per_clip": float(n_trans.mean()),
             "mean_transition_frames": float(durations.mean()), "mpjpe_cm": float(overall),
             "mpjpe_mean_of_actions_cm": float(np.mean(per_action)), "paper_mpjpe_cm": _PAPER[int(lam)]}
        rec["penalties"].append(r)
        progress("penalty", r)

    for a in np.unique(dataset.actions):
        poses = np.concatenate([root_relative(m.joints[s.anchors]) for s, m in zip(segs, dataset) if m.action == a])
        flat = poses.reshape(len(poses), -1)
        dist = {}
        for k in _CLUSTERS:
            if k > len(flat):
                dist[str(k)] = None
                continue
            km = KMeans(k, n_init=2, random_state=0).fit(flat)
            dist[str(k)] = float(100 * np.linalg.norm(poses - km.cluster_centers_[km.labels_].reshape(poses.shape),
                                                      axis=-1).mean())
        rec["kmeans"].append({"action": dataset.action_names[a], "anchors": len(poses), "distance_cm": dist})
    return write_record(out, "concepts", rec)
