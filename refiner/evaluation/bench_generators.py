"""``motion-refiner bench generators``: the shipped reference generators' samples before and after refinement.

The record (``generators.json``): ``per_action`` (samples per HumanAct12 action), ``n_replications``,
``reference_clips`` (real clips of subjects 11-12) and ``rows``: per ``<kind>/generated``,
``<kind>/refined`` (by the default refiner, ``MotionRefiner.pretrained``, as
:class:`~refiner.refinement.refined_generator.RefinedGenerator` refines) and ``real``
(train clips of subjects 1-10), ``samples``, ``metrics``
(:func:`~refiner.evaluation.protocol.evaluate` summary, metric -> ``[mean, 95 % half-width]``) and
``physics`` (:func:`physical_record`: mean joint acceleration m/s², foot-skating ratio, bone-length
variation); refined rows also ``frames_changed`` (share), ``changes_per_clip`` (the reports' changes) and
``refine_seconds_per_clip``.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from refiner.evaluation.bench_setup import (
    Progress,
    ignore_progress,
    load_humanact12_and_recognizer,
    one_thread,
    summary_record,
    write_record,
)
from refiner.evaluation.ground_metrics import foot_skating_ratio
from refiner.evaluation.physics import acceleration, bone_length_variation
from refiner.evaluation.protocol import evaluate

__all__ = ["bench_generators", "physical_record"]


def physical_record(motions) -> dict:
    """Means over HumanAct12 ``motions`` of their joint acceleration (m/s²), foot-skating ratio (share of
    frame pairs) and bone-length variation (std / mean per bone, a share)."""
    return {"acceleration": float(np.mean([acceleration(m) for m in motions])),
            "foot_skating": float(np.mean([foot_skating_ratio(m) for m in motions])),
            "bone_length_variation": float(np.mean([bone_length_variation(m) for m in motions]))}


@one_thread()
def bench_generators(data: Path | None, out: Path | None, quick: bool, *, weights: Path | None = None,
                     progress: Progress | None = None) -> dict:
    """The shipped reference generators' samples before and after refinement, scored by the HumanAct12 recogniser.

    ``quick``: 3 samples per action, 2 replications and, for a diffusion generator, 10 sampling steps instead of
    its own (else the paper's Table 1 protocol and the generators as shipped). Progress
    event ``"row"``: ``kind``, ``label`` (generated or refined) and ``metrics`` of each generator row.
    ``weights``: a folder of weight sets looked in before the shipped ones.
    """
    # these import torch: here, so that importing the suites (``motion-refiner --help``) stays cheap
    from refiner.reference import GENERATOR_KINDS, load_reference_generator
    from refiner.refinement.motion_refiner import MotionRefiner

    progress = progress or ignore_progress
    dataset, recognizer = load_humanact12_and_recognizer(data, hidden="random")
    real = dataset.split("test")
    # as RefinedGenerator refines a generator's clips: the default refiner
    refiners = {"refined": MotionRefiner.pretrained("humanact12", weights=weights)}
    # the paper's Table 1 protocol: 3,000 samples (250 per action), 20 replications
    per_action, n_rep = (3, 2) if quick else (250, 20)
    n_actions = len(dataset.action_names)
    rec = {"per_action": per_action, "n_replications": n_rep, "reference_clips": len(real), "rows": {}}
    for kind in GENERATOR_KINDS:
        gen = load_reference_generator(kind)
        if quick and "sampling_steps" in gen.get_params():
            gen.set_params(sampling_steps=10)  # the smoke test, not the figure: most of its time was DDIM steps
        before = [m for a in range(n_actions)
                  for m in gen.sample_motions(a, per_action, random_state=1000 * a + 7)]
        outputs = {"generated": (before, None, None)}
        for label, refiner in refiners.items():
            t0 = time.perf_counter()
            joints, reports = refiner.refine(np.stack([m.joints for m in before]), action=[m.action for m in before],
                                             return_report=True)
            outputs[label] = ([m.with_joints(j) for m, j in zip(before, joints)], reports, time.perf_counter() - t0)
        for label, (motions, reports, seconds) in outputs.items():
            s = evaluate(recognizer, motions, real.motions, n_replications=n_rep, match_labels=True,
                         random_state=0).summary()
            row = rec["rows"][f"{kind}/{label}"] = {"samples": len(motions), "metrics": summary_record(s),
                                                    "physics": physical_record(motions)}
            if reports is not None:
                row.update(frames_changed=float(np.mean([r.changed_frames.mean() for r in reports])),
                           changes_per_clip=float(np.mean([len(r.changes) for r in reports])),
                           refine_seconds_per_clip=seconds / len(before))
            progress("row", {"kind": kind, "label": label, "metrics": row["metrics"]})
    s = evaluate(recognizer, dataset.split("train").motions, real.motions, n_replications=n_rep,
                 n_generated=per_action * n_actions, match_labels=True, random_state=0).summary()
    rec["rows"]["real"] = {"samples": per_action * n_actions, "metrics": summary_record(s),
                           "physics": physical_record(dataset.split("train").motions)}
    return write_record(out, "generators", rec)
