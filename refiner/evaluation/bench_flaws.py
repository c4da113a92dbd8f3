"""``motion-refiner bench flaws``: refiners against the seven seeded flaw families on held-out subjects.

Every held-out clip (subjects 11-12) is corrupted by each family of :mod:`refiner.evaluation.flaws` (seed =
clip index) and refined with its true action. The headline is the share of the flaw's added MPJPE
that a refiner removes, ``100 * (1 - MPJPE(refined) / MPJPE(flawed))`` against the clean clip,
per family, with the families whose mechanism training never used
(:data:`refiner.refinement.training_flaws.HELD_OUT_FAMILIES`) reported apart. The *oracle* rows isolate the
repair step: they are given the true flaw mask and replace exactly those frames, by linear
interpolation, by the repair network in-filling them (frames hidden), by the motion in-filler (when
the weights have one), by the repair network seeing them (frames given), or by the flaw denoiser
correcting them (when the weights have one).

The record (``flaws.json``): ``clips``, ``severities``, ``families``, ``held_out_families``, the refiners
``skipped`` (name -> why), ``clean`` (name -> ``mpjpe_change_cm``, ``share_changed``), ``flawed`` (the
:func:`flaw_records`), ``summary`` (severity -> name -> mean % removed over the training families, the
held-out ones and all) and ``seconds``.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from refiner.concepts.segmentation import segment
from refiner.core.signal import linear_infill
from refiner.evaluation.bench_setup import Progress, load_bench_humanact12, one_thread, write_record
from refiner.evaluation.flaws import FLAW_FAMILIES, corrupt
from refiner.refinement.training_flaws import HELD_OUT_FAMILIES

__all__ = ["bench_flaws", "flaw_records", "ORACLES"]

ORACLES = ("oracle_linear", "oracle_infill", "oracle_motion_infill", "oracle_given", "oracle_denoise")
#: Oracle rows that need an optional part of the weights.
_ORACLE_PARTS = {"oracle_denoise": "flaw_denoiser", "oracle_motion_infill": "motion_infiller"}


def _oracle(name: str, model, flawed: np.ndarray, mask: np.ndarray, action: int) -> np.ndarray:
    """``flawed`` with its ``mask`` frames replaced by the oracle ``name``'s proposal."""
    if not mask.any():
        return flawed
    if name == "oracle_linear":
        proposal = linear_infill(flawed, mask)
    elif name == "oracle_denoise":
        proposal = model.flaw_denoiser.denoise(flawed[None], mask[None])[0]
    elif name == "oracle_motion_infill":
        proposal = model.motion_infiller.infill(flawed[None], mask[None])[0]
    else:
        proposal = model.flaw_repairer.repair(flawed[None], mask[None], [action], hide=name == "oracle_infill")[0]
    out = flawed.copy()
    out[mask] = proposal[mask]
    return out


def flaw_records(clips, refiners: dict, *, severities=(2,), model=None, families=None) -> tuple[list, list]:
    """Refine every clip corrupted by every family; returns ``(clean_rows, records)``.

    ``refiners``: name -> object with ``refine(motion, *, action) -> Motion``. With ``model`` (a
    :class:`~refiner.refinement.pipeline.Refiner` with learned parts) the :data:`ORACLES` rows are added.
    ``clean_rows``: ``[name, MPJPE change cm, share of clips changed]``; each record: family,
    severity, refiner, ``mpjpe_cm`` (all frames), ``mpjpe_flawed_cm`` (true flaw frames),
    ``removed_pct``.
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
            oracles = [o for o in ORACLES if model is not None and
                       (o not in _ORACLE_PARTS or getattr(model, _ORACLE_PARTS[o]) is not None)]
            names = list(refiners) + oracles
            for name in names:
                if name in ORACLES:
                    outs = [_oracle(name, model, c.motion.numpy(), c.mask, m.action) for c, m in zip(flawed, clips)]
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
    the shipped ones (``Refiner.pretrained``); ``progress`` is accepted like every suite's and not called.
    """
    # the pipeline imports torch and the baselines scipy.signal: here, so that importing the suites stays cheap
    from refiner.evaluation.baselines import FLAW_REFINERS
    from refiner.refinement.pipeline import Refiner

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
    try:
        model = Refiner.pretrained("humanact12", split="train", weights=weights)
        model = model if model.flaw_repairer is not None else None
    except ValueError:
        model = None
    t0 = time.perf_counter()
    clean_rows, records = flaw_records(clips, refiners, severities=severities, model=model)
    seconds = time.perf_counter() - t0

    names = list(dict.fromkeys(r["refiner"] for r in records))
    table = {(r["family"], r["severity"], r["refiner"]): r for r in records}
    rec = {"clips": len(clips), "severities": list(severities), "families": list(FLAW_FAMILIES),
           "held_out_families": list(HELD_OUT_FAMILIES), "skipped": skipped,
           "clean": {row[0]: {"mpjpe_change_cm": row[1], "share_changed": row[2]} for row in clean_rows},
           "flawed": records, "summary": {}, "seconds": seconds}
    for severity in severities:
        removed = {name: {f: table[(f, severity, name)]["removed_pct"] for f in FLAW_FAMILIES} for name in names}
        rec["summary"][str(severity)] = {name: {
            "training_mean_removed_pct": float(np.mean([v for f, v in r.items() if f not in HELD_OUT_FAMILIES])),
            "held_out_mean_removed_pct": float(np.mean([v for f, v in r.items() if f in HELD_OUT_FAMILIES])),
            "mean_removed_pct": float(np.mean(list(r.values())))} for name, r in removed.items()}
    return write_record(out, "flaws", rec)
