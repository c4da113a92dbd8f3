"""``motion-refiner bench refiner`` and ``bench speed``: the shipped refiner's figures on held-out clips.

The refiner measured is the default, ``MotionRefiner.pretrained("humanact12")`` (its model learned on subjects 1-8 and
was calibrated on 9-10); the anchor figures are the concepts method's (``Refiner.pretrained("humanact12",
split="train")``, subjects 1-10). Both suites follow :mod:`refiner.evaluation.bench_setup`: they return their record
and, with ``out``, write it as ``refiner.json`` / ``speed.json``. ``refiner.json``: ``clips``, ``parameters`` (per
part and total, the default refiner's), (a) ``real_mpjpe_change_cm`` and ``real_clips_changed``, (b)
``boundary_acceleration`` (``boundaries``, ``real_p99``, ``max``, ``median``, ``above_real_p99``; m/s²), (c)
``anchor_precision`` and ``anchor_recall`` (the concepts method's anchor recognition, ±2 frames of the segmentation's
anchors), (d) ``latency`` (``clips``, ``threads``, ``median_ms``, ``p90_ms``) and ``anchor_quality_auc`` (the concepts
method's anchor scores, per flaw family: ``pairs``, ROC AUC of the ``pose`` mixture and of the ``encoder``-feature
GMM). ``speed.json``: ``clips``, ``batch``, ``devices`` (per device: ``name``, ``median_ms``, ``p90_ms``,
``clips_per_s``, ``peak_mib``, ``peak_of``), ``lengths`` (per clip length in frames, batch 1: ``frames``, ``median_ms``,
``us_per_frame``) and ``parameters``.
"""
from __future__ import annotations

import resource
import time
from pathlib import Path

import numpy as np

from refiner.concepts.segmentation import segment
from refiner.evaluation.bench_setup import Progress, ignore_progress, load_bench_humanact12, one_thread, write_record
from refiner.evaluation.flaws import corrupt
from refiner.evaluation.physics import boundary_velocity_jump

__all__ = ["bench_refiner", "bench_speed", "motion_parameters"]


def motion_parameters(refiner) -> dict:
    """A :class:`~refiner.refinement.motion_refiner.MotionRefiner`'s network parameters, ``motion_model`` and ``total``."""
    n = sum(p.numel() for p in refiner.model.network_.parameters())
    return {"motion_model": n, "total": n}


@one_thread()
def bench_refiner(data: Path | None, out: Path | None, quick: bool, *, weights: Path | None = None,
                  progress: Progress | None = None) -> dict:
    """Issue-3 figures for the default refiner and the concepts method's subject-1-10 weights (``weights``: a folder of
    weight sets looked in first) on held-out subjects 11-12.

    (a) how much real clips change, (b) velocity jumps where refined windows meet kept frames
    against real data's 99th percentile, (c) precision / recall of the anchors the concepts method's recogniser finds
    against the segmentation's (the table calls them "anchor recognition"), (d) refine latency per
    60-frame clip (CPU, batch 1), parameter counts, and the anchor-quality comparison behind the concepts method's
    ``quality`` default (pose mixture vs the paper's encoder-feature GMM, ROC AUC on seeded anchor
    flaws). Runs on one thread
    (:func:`~refiner.evaluation.bench_setup.one_thread`), as ``refine`` itself does. ``quick`` keeps every
    16th clip. Progress events: ``"figures"`` (the record once (a)-(c) are known) and ``"latency"``
    (the record once (d) is).
    """
    # torch and sklearn.metrics are slow to import: here, so that importing the suites
    # (``motion-refiner --help``) stays cheap
    import torch
    from sklearn.metrics import roc_auc_score

    from refiner.refinement.anchor_recognition import match_anchors
    from refiner.refinement.motion_refiner import MotionRefiner
    from refiner.refinement.pipeline import Refiner

    progress = progress or ignore_progress
    test = load_bench_humanact12(data).split("test")
    clips = test.motions[:: (16 if quick else 1)]
    model = MotionRefiner.pretrained("humanact12", weights=weights)
    concepts = Refiner.pretrained("humanact12", split="train", weights=weights)
    rec = {"clips": len(clips), "parameters": motion_parameters(model)}

    segs = [segment(m.joints) for m in clips]
    change, frames, n_changed, tp, n_pred, n_ref = 0.0, 0, 0, 0, 0, 0
    jumps = []
    for m, seg in zip(clips, segs):
        refined, report = model.refine(m, return_report=True)
        err = np.linalg.norm(refined.joints - m.joints, axis=-1).mean(-1)
        change, frames = change + err.sum(), frames + m.n_frames
        n_changed += bool(report.changes)
        counts_ = match_anchors(concepts.recognizer.recognize(m.joints).anchors, seg.anchors)
        tp, n_pred, n_ref = tp + counts_[0], n_pred + counts_[1], n_ref + counts_[2]
    real_acc = np.concatenate([np.linalg.norm(np.diff(m.joints, 2, axis=0), axis=-1).max(-1) * m.fps ** 2
                               for m in clips])
    # window boundaries need changes: refine clips with seeded anchor flaws and measure every splice
    for i, (m, seg) in enumerate(zip(clips, segs)):
        bad = corrupt(m, "anchor_drift", 3, random_state=i, segmentation=seg).motion
        refined, report = model.refine(bad, return_report=True)
        mask = report.changed_frames
        if mask.any() and not mask.all():
            jumps.append(boundary_velocity_jump(refined, mask).jump * m.fps)  # m/s per frame -> m/s²
    p99 = float(np.percentile(real_acc, 99))
    rec.update({
        "real_mpjpe_change_cm": float(100 * change / frames), "real_clips_changed": n_changed,
        "boundary_acceleration": {
            "boundaries": len(jumps), "real_p99": p99, "max": float(max(jumps)) if jumps else None,
            "median": float(np.median(jumps)) if jumps else None,
            "above_real_p99": int(np.sum(np.array(jumps) > p99))},
        "anchor_precision": float(tp / max(n_pred, 1)), "anchor_recall": float(tp / max(n_ref, 1)),
    })
    progress("figures", rec)

    window = [m.joints[:60] for m in clips if m.n_frames >= 60][: (5 if quick else 50)]
    for x in window[:3]:
        model.refine(x)  # warm up
    times = []
    for x in window:
        t0 = time.perf_counter()
        model.refine(x)
        times.append(time.perf_counter() - t0)
    rec["latency"] = {"clips": len(times), "threads": model.threads or torch.get_num_threads(),
                      "median_ms": float(1000 * np.median(times)), "p90_ms": float(1000 * np.percentile(times, 90))}
    progress("latency", rec)

    rec["anchor_quality_auc"] = {}
    rng = np.random.default_rng(0)
    for family in ("anchor_drift", "wrong_anchor"):
        labels, pose_s, enc_s = [], [], []
        for i, (m, seg) in enumerate(zip(clips, segs)):
            a = seg.anchors
            if len(a) < 3:
                continue
            donors = [d for d in test.motions if d.action == m.action and d is not m][:5]
            bad = corrupt(m, family, 2, random_state=i, donors=donors, segmentation=seg).motion
            shift = np.linalg.norm(bad.joints - m.joints, axis=-1).mean(-1)[a]
            k_bad = int(np.argmax(shift[1:-1])) + 1
            k_real = int(rng.integers(1, len(a) - 1))
            for clip, k, label in ((m.joints, k_real, 0), (bad.joints, k_bad, 1)):
                labels.append(label)
                pose_s.append(-concepts.anchor_quality.score(clip[a[k]][None], m.action)[0])
                enc_s.append(-concepts.recognizer.recognize(clip, anchors=a).scores[k])
        rec["anchor_quality_auc"][family] = {"pairs": len(labels) // 2, "pose": float(roc_auc_score(labels, pose_s)),
                                             "encoder": float(roc_auc_score(labels, enc_s))}
    return write_record(out, "refiner", rec)


#: Clip lengths (frames) timed at batch 1, to show the cost grows linearly with length.
SPEED_LENGTHS = (60, 240, 960, 3840)


def _seconds(call) -> float:
    """Wall time of one ``call()``."""
    t0 = time.perf_counter()
    call()
    return time.perf_counter() - t0


def _length_row(model, clip, n_frames: int, *, repeats: int) -> dict:
    """Median time to refine one clip of ``n_frames``, made by playing ``clip (T, J, 3)`` back and forth (no jumps);
    a clip with nothing flagged times detection, one with flagged runs adds their repair."""
    back_and_forth = np.concatenate([clip, clip[-2:0:-1]])
    long = np.resize(back_and_forth, (n_frames,) + clip.shape[1:])
    model.refine(long)
    ms = 1000 * float(np.median([_seconds(lambda: model.refine(long)) for _ in range(repeats)]))
    return {"frames": n_frames, "median_ms": ms, "us_per_frame": 1000 * ms / n_frames}


def bench_speed(data: Path | None, out: Path | None, quick: bool, *, weights: Path | None = None,
                progress: Progress | None = None) -> dict:
    """Refine latency (batch 1) and throughput (large batches), peak memory and parameters of the default refiner,
    and the latency of one clip at each of :data:`SPEED_LENGTHS` frames (after the peak memory is read).

    The motion model runs on the CPU (``MotionRefiner`` has no device option), so there is one row, ``cpu``.
    ``quick``: 8 clips and batches of 8 (else 64 and 256). Progress event ``"device"``: each row of ``devices`` as it
    is measured.
    """
    import torch  # here, not at the top: see bench_refiner

    from refiner.refinement.motion_refiner import MotionRefiner

    progress = progress or ignore_progress
    clips = [m.joints[:60] for m in load_bench_humanact12(data).split("test") if m.n_frames >= 60][: (8 if quick else 64)]
    batch_size = 8 if quick else 256
    rec = {"clips": len(clips), "batch": batch_size, "devices": []}
    model = MotionRefiner.pretrained("humanact12", weights=weights)
    for x in clips[:3]:
        model.refine(x)  # warm up (first calls allocate)
    times = [_seconds(lambda x=x: model.refine(x)) for x in clips]
    batch = np.stack([clips[i % len(clips)] for i in range(batch_size)])
    model.refine(batch[:8])
    # the median of three calls: one call is at the mercy of the machine
    runs = [_seconds(lambda: model.refine(batch)) for _ in range(1 if quick else 3)]
    threads = model.threads or torch.get_num_threads()
    rec["devices"].append({
        "device": "cpu", "name": f"{threads} / {threads} threads (batch 1 / {batch_size})",
        "median_ms": float(1000 * np.median(times)), "p90_ms": float(1000 * np.percentile(times, 90)),
        "clips_per_s": len(batch) / float(np.median(runs)),
        "peak_mib": float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024), "peak_of": "process RSS"})
    progress("device", rec["devices"][-1])
    rec["lengths"] = [_length_row(model, clips[0], n, repeats=2 if quick else 5) for n in SPEED_LENGTHS]
    rec["parameters"] = motion_parameters(model)
    return write_record(out, "speed", rec)
