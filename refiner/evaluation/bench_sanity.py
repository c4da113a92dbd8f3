"""``motion-refiner bench sanity``: real held-out clips through the Action2Motion evaluation protocol.

The record (``sanity.json``): ``test_clips`` (subjects 11-12), ``train_clips``, ``n_replications``,
``n_crops`` (random 60-frame crops per side and replication) and ``comparisons``: per comparison
(test vs train, the same with matched action mixtures, train vs train matched as the floor) its
``metrics`` (:func:`~refiner.evaluation.protocol.evaluate` summary, metric -> ``[mean, 95 % half-width]``)
and ``seconds``.
"""
from __future__ import annotations

import time
from pathlib import Path

from refiner.evaluation.bench_setup import (
    Progress,
    ignore_progress,
    load_humanact12_and_recognizer,
    one_thread,
    summary_record,
    write_record,
)
from refiner.evaluation.protocol import evaluate

__all__ = ["bench_sanity"]


@one_thread()
def bench_sanity(data: Path | None, out: Path | None, quick: bool, *, weights: Path | None = None,
                 progress: Progress | None = None) -> dict:
    """Real held-out clips through the evaluation protocol: FID near zero and the recogniser's accuracy.

    ``quick``: 3 replications of 300 crops (else 20 of 1,000). Progress event ``"comparison"``: the
    comparison's ``label``, ``metrics`` and ``seconds``, as each one is done. ``weights`` is accepted like every suite's and not
    used (no refiner runs here).
    """
    progress = progress or ignore_progress
    dataset, recognizer = load_humanact12_and_recognizer(data, hidden="random")
    test, train = dataset.split("test"), dataset.split("train")
    n_rep, n = (3, 300) if quick else (20, 1000)
    rec = {"test_clips": len(test), "train_clips": len(train), "n_replications": n_rep, "n_crops": n,
           "comparisons": {}}
    for label, gen, ref, match in (("test vs train", test, train, False),
                                   ("test vs train, matched", test, train, True),
                                   ("train vs train, matched (floor)", train, train, True)):
        t0 = time.perf_counter()
        ev = evaluate(recognizer, gen.motions, ref.motions, n_replications=n_rep, n_generated=n, n_real=n,
                      match_labels=match, random_state=0)
        rec["comparisons"][label] = {"metrics": summary_record(ev.summary()), "seconds": time.perf_counter() - t0}
        progress("comparison", {"label": label, **rec["comparisons"][label]})
    return write_record(out, "sanity", rec)
