"""Train the shipped CMU weights: the learned refinement steps on the CMU subset only.

Usage (each stage resumes from its checkpoints in ``OUT/parts``; run the three part stages in
parallel processes, then ``assemble``; ``SPLIT`` is ``train``, the default, for ``cmu_mocap-train``, or
``all`` for ``cmu_mocap``)::

    python examples/train_cmu_weights.py OUT flaw_classifier [SPLIT]
    python examples/train_cmu_weights.py OUT flaw_recognizer [SPLIT]
    python examples/train_cmu_weights.py OUT flaw_repairer [SPLIT]
    python examples/train_cmu_weights.py OUT noise_filter [SPLIT]          # closed form, about a minute
    python examples/train_cmu_weights.py OUT amplitude_restorer [SPLIT]    # medians, seconds (not shipped)
    python examples/train_cmu_weights.py OUT pose_prior [SPLIT]            # about 8 minutes
    python examples/train_cmu_weights.py OUT noise_residual [SPLIT]        # after noise_filter, about 3 minutes
    python examples/train_cmu_weights.py OUT assemble [SPLIT] [FOLDER]     # default FOLDER: OUT/refiner

Split ``all`` is not shipped: calibrated on its two highest-numbered subjects (133, 136; 59 clips) it
set a noise threshold of 0.13 cm (``train``: 1.31 cm) and a classifier threshold of 0.999, so its
last denoising step touched 10 of 83 clean clips of the other test subjects (first 120 frames), and on
133 and 136 (unseen by both sets' networks) it removed 9.4 % of the flaws' added MPJPE against the
train split's 9.5 % (54 clips, first 60 frames, severity 2, labels given). Its thresholds need more
calibration subjects than two.

Training clips: split ``train``, the CMU subset's training subjects (every subject but
``refiner.io.datasets.CMU_TEST_SUBJECTS``); split ``all``, every subject; clips of at least 16 frames
(790 of 815 training clips). The networks
are HumanAct12's "default" learned configuration, except that the flaw recogniser trains 10 epochs
(not 40): the refiner detects with the flaw classifier, and the recogniser gives actions and anchors.
The paper's parts (anchor and transition refiners) are not trained, so these weights serve
``method="learned"`` only. Thresholds are set on the two highest-numbered training subjects.
"""
import sys
from pathlib import Path

import numpy as np
import torch
from threadpoolctl import threadpool_limits

from refiner.concepts.anchors import AnchorConcepts
from refiner.concepts.segmentation import segment
from refiner.io.datasets import CMU_ACTIONS, load_cmu_mocap
from refiner.refinement import train_learned as tl
from refiner.refinement.pipeline import Refiner
from refiner.refinement.train_refiner import CMU_LICENCE

MIN_FRAMES = 16
#: Why the amplitude step is fitted but not shipped with these weights.
AMPLITUDE_NOTE = ("no amplitude step: with their own labels, clean clips of CMU's held-out subjects read as damped "
                  "(a walk's standing start) and were scaled up: 32 of 185 first-60-frame crops (12.7 cm each), 15 of "
                  "106 first-120-frame crops (15.7 cm); no CMU-layout generator shows a gain to weigh against it")
tl.LEARNED_CONFIGS["cmu"] = dict(tl.LEARNED_CONFIGS["default"])
RECOGNIZER_EPOCHS = 10

torch.set_num_threads(1)
threadpool_limits(1)
out, stage = Path(sys.argv[1]), sys.argv[2]
split = sys.argv[3] if len(sys.argv) > 3 else "train"
if split not in ("train", "all"):
    raise SystemExit(f"unknown split {split!r}; known: train, all")
train = load_cmu_mocap().split(split)
train = train.subset(np.flatnonzero([len(m.joints) >= MIN_FRAMES for m in train]))
if stage in tl.LEARNED_PARTS or stage == "noise_residual":  # the residual behind OUT/parts' noise filter
    if stage == "flaw_recognizer":
        tl.LEARNED_CONFIGS["cmu"]["schedule"] = dict(tl.LEARNED_CONFIGS["default"]["schedule"], n_epochs=RECOGNIZER_EPOCHS)
    config = "cmu" if stage in ("flaw_recognizer", "flaw_repairer") else "default"  # the others have their own tables
    tl.train_learned(train, out, split="all", only=stage, config=config, device="cpu")
elif stage == "assemble":
    parts = tl.train_learned(train, out, split="all")  # loads the finished parts
    parts.pop("amplitude_restorer", None)  # see AMPLITUDE_NOTE
    thresholds = tl.calibrate_learned(parts, train, split="all")
    info = {name: {k: v for k, v in __import__("json").loads((out / "parts" / f"{name}.json").read_text()).items()
                   if k != "history"} for name in tl.LEARNED_PARTS if name in parts}
    calibration = sorted(set(int(s) for s in train.subjects[tl.calibration_split(train.subjects)]))
    held_out = ("held-out subjects: refiner.io.datasets.CMU_TEST_SUBJECTS" if split == "train" else
                "every subject; no held-out subjects (the benchmarks use the cmu_mocap-train weights)")
    manifest = {"dataset": "cmu_mocap", "split": split, "config": "default (flaw recogniser: 10 epochs)",
                "clips": len(train), "subjects": sorted(set(int(s) for s in train.subjects)), "licence": CMU_LICENCE,
                "command": f"python examples/train_cmu_weights.py OUT {{flaw_classifier,flaw_recognizer,flaw_repairer,"
                           f"noise_filter,amplitude_restorer,pose_prior,noise_residual,assemble}} {split}",
                "notes": ["learned steps only: method='concepts' (the paper's parts) is not available for these weights",
                          f"training clips of at least {MIN_FRAMES} frames", held_out,
                          f"networks on every subject but {calibration}, thresholds on those",
                          "anchor_concepts: the repair network's (K-means, 8 per action), for the concept-snap option",
                          AMPLITUDE_NOTE],
                "learned": {**info, **thresholds, **tl.bone_proportion_records(train)}}
    concepts_file = out / "parts" / "anchor_concepts.safetensors"
    if concepts_file.is_file():
        concepts = AnchorConcepts.load(concepts_file)
    else:  # repair networks trained before train_learned kept them: fitted again as it fits them (K-means is seeded)
        fit = np.flatnonzero(~tl.calibration_split(train.subjects))
        concepts = tl.fit_anchor_concepts([train.motions[i].joints for i in fit], train.actions[fit],
                                          [segment(train.motions[i].joints).anchors for i in fit],
                                          n_actions=len(CMU_ACTIONS))
    tokens = parts["flaw_repairer"].concepts_
    if any(not np.allclose(c, tokens[a, : len(c)], atol=1e-5) for a, c in enumerate(concepts.centers_)):
        raise SystemExit("the anchor concepts differ from the repair network's; delete parts/anchor_concepts.safetensors")
    model = Refiner(None, None, None, None, concepts, None, parts["flaw_recognizer"], parts["flaw_repairer"],
                    parts["flaw_classifier"], noise_filter=parts["noise_filter"], pose_prior=parts.get("pose_prior"),
                    amplitude_restorer=None, noise_residual=parts.get("noise_residual"), skeleton="cmu_mocap",  # see AMPLITUDE_NOTE
                    action_names=CMU_ACTIONS, manifest=manifest)
    folder = Path(sys.argv[4]) if len(sys.argv) > 4 else out / "refiner"
    model.save(folder, half=True, int8=("noise_residual",))
    print(Refiner.load(folder).manifest["learned"])
else:
    raise SystemExit(f"unknown stage {stage!r}")
