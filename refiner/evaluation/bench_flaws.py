"""``motion-refiner bench flaws``: refiners against the seven seeded flaw families on held-out subjects.

Every held-out clip (subjects 11-12) is corrupted by each family of :mod:`refiner.evaluation.flaws` (seed =
clip index) and refined with its true action. The headline is the share of the flaw's added MPJPE
that a refiner removes, ``100 * (1 - MPJPE(refined) / MPJPE(flawed))`` against the clean clip,
per family. The refiners are :data:`refiner.evaluation.baselines.FLAW_REFINERS`: the baselines, the default
refiner (``ours_full``, the motion model) and the concepts method. The *oracle* row is given the true flaw mask and
replaces exactly those frames by linear interpolation. (Flaws made by mechanisms the motion model's weights never
saw are ``motion-refiner bench heldout``'s.)

The record (``flaws.json``): ``clips``, ``severities``, ``families``, the refiners ``skipped`` (name -> why),
``clean`` (name -> ``mpjpe_change_cm``, ``share_changed``), ``flawed`` (the :func:`flaw_records`), ``summary``
(severity -> name -> ``mean_removed_pct``, the mean % removed over the families) and ``seconds``.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from refiner.concepts.segmentation import segment
from refiner.core.signal import linear_infill
from refiner.evaluation.bench_setup import Progress, load_bench_humanact12, one_thread, write_record
from refiner.evaluation.flaws import FLAW_FAMILIES, corrupt

__all__ = ["bench_flaws", "flaw_records", "ORACLES"]

#: Rows given the true flaw mask: its frames replaced by linear interpolation.
ORACLES = ("oracle_linear",)


def _oracle(name: str, flawed: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``flawed`` with its ``mask`` frames replaced by the oracle ``name``'s proposal."""
    if not mask.any():
        return flawed
    if name != "oracle_linear":
        raise ValueError(f"unknown oracle {name!r}; known: {', '.join(ORACLES)}.")
    out = flawed.copy()
    out[mask] = linear_infill(flawed, mask)[mask]
    return out


def flaw_records(clips, refiners: dict, *, severities=(2,), oracles: bool = True, families=None) -> tuple[list, list]:
    """Refine every clip corrupted by every family; returns ``(clean_rows, records)``.

    ``refiners``: name -> object with ``refine(motion, *, action) -> Motion``; with ``oracles`` the :data:`ORACLES`
    rows are added. ``clean_rows``: ``[name, MPJPE change cm, share of clips changed]``; each record: family,
    severity, refiner, ``mpjpe_cm`` (all frames), ``mpjpe_flawed_cm`` (true flaw frames), ``removed_pct``.
    """
    segs = [segment(m.joints) for m in clips]
    donors = [[d for j, d in enumerate(clips) if j != i and d.action == m.action] for i, m in enumerate(clips)]
    clean_rows = []
    for name, r in refiners.items():
        outs = [r.refine(m, action=m.action) for m in clips]
        err = [np.linalg.norm(o.joints.astype(np.float64) - m.joints, axis=-1).mean() for o, m in zip(outs, clips)]
        clean_rows.append([name, 100 * float(np.mean(err)), float(np.mean(np.array(err) > 0))])
    records = []
    for family in families or FLAW_FAMILIES:
        for severity in severities:
            flawed = [corrupt(m, family, severity, random_state=i, segmentation=segs[i], donors=donors[i])
                      for i, m in enumerate(clips)]
            base = None
            for name in list(refiners) + (list(ORACLES) if oracles else []):
                if name in ORACLES:
                    outs = [_oracle(name, c.motion.numpy(), c.mask) for c in flawed]
                else:
                    outs = [refiners[name].refine(c.motion, action=m.action).numpy() for c, m in zip(flawed, clips)]
                err = [np.linalg.norm(o.astype(np.float64) - m.joints, axis=-1).mean(-1) for o, m in zip(outs, clips)]
                all_cm = 100 * float(np.mean([e.mean() for e in err]))
                masked = [e[c.mask].mean() for e, c in zip(err, flawed) if c.mask.any()]
                if base is None:  # the first refiner is identity: the flaw's added error
                    base = all_cm
                records.append({"family": family, "severity": severity, "refiner": name, "mpjpe_cm": all_cm,
                                "mpjpe_flawed_cm": 100 * float(np.mean(masked)),
                                "removed_pct": 100 * (1 - all_cm / base) if base > 0 else 0.0})
    return clean_rows, records


@one_thread()
def bench_flaws(data: Path | None, out: Path | None, quick: bool, *, stride: int = 1,
                severities: tuple[int, ...] | None = None, weights: Path | None = None,
                progress: Progress | None = None) -> dict:
    """Seeded flaws on held-out HumanAct12 clips; see the module docstring. ``stride`` keeps every
    stride-th clip; ``severities`` default (2,) (the acceptance severity), ``quick`` every 68th clip (4).
    Runs on one thread (:func:`~refiner.evaluation.bench_setup.one_thread`). Returns the record (see the
    module docstring), written as ``flaws.json`` with ``out``; ``weights``: a folder of weight sets looked in before
    the shipped ones (``MotionRefiner.pretrained``, ``Refiner.pretrained``); ``progress`` is accepted like every
    suite's and not called.
    """
    # the refiners import torch and the baselines scipy.signal: here, so that importing the suites stays cheap
    from refiner.evaluation.baselines import FLAW_REFINERS

    test = load_bench_humanact12(data).split("test")
    step = 68 if quick else max(int(stride), 1)
    clips = test.subset(range(0, len(test), step)).motions
    severities = tuple(severities) if severities else (2,)
    skipped, refiners = {}, {}
    for name, factory in FLAW_REFINERS.items():
        try:
            refiners[name] = factory(weights=weights)
        except Exception as e:  # an optional refiner that cannot be built is skipped, not fatal
            skipped[name] = f"{type(e).__name__}: {e}"
    t0 = time.perf_counter()
    clean_rows, records = flaw_records(clips, refiners, severities=severities)
    seconds = time.perf_counter() - t0

    names = list(dict.fromkeys(r["refiner"] for r in records))
    table = {(r["family"], r["severity"], r["refiner"]): r for r in records}
    rec = {"clips": len(clips), "severities": list(severities), "families": list(FLAW_FAMILIES), "skipped": skipped,
           "clean": {row[0]: {"mpjpe_change_cm": row[1], "share_changed": row[2]} for row in clean_rows},
           "flawed": records, "summary": {}, "seconds": seconds}
    for severity in severities:
        removed = {name: {f: table[(f, severity, name)]["removed_pct"] for f in FLAW_FAMILIES} for name in names}
        rec["summary"][str(severity)] = {name: {"mean_removed_pct": float(np.mean(list(r.values())))}
                                         for name, r in removed.items()}
    return write_record(out, "flaws", rec)
