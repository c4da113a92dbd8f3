"""Train the shipped ``cmu_mocap-train`` weights: the learned refinement steps on the CMU subset only.

Usage (each stage resumes from its checkpoints in ``OUT/parts``; run the three part stages in
parallel processes, then ``assemble``)::

    python examples/train_cmu_weights.py OUT flaw_classifier
    python examples/train_cmu_weights.py OUT flaw_recognizer
    python examples/train_cmu_weights.py OUT flaw_repairer
    python examples/train_cmu_weights.py OUT noise_filter                  # closed form, about a minute
    python examples/train_cmu_weights.py OUT amplitude_restorer            # medians, seconds
    python examples/train_cmu_weights.py OUT assemble [FOLDER]     # default FOLDER: OUT/refiner

Training clips: the CMU subset's training subjects (every subject but
``refiner.io.datasets.CMU_TEST_SUBJECTS``), clips of at least 16 frames (790 of 815). The networks
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

from refiner.io.datasets import CMU_ACTIONS, load_cmu_mocap
from refiner.refinement import train_learned as tl
from refiner.refinement.pipeline import Refiner
from refiner.refinement.train_refiner import CMU_LICENCE

MIN_FRAMES = 16
tl.LEARNED_CONFIGS["cmu"] = dict(tl.LEARNED_CONFIGS["default"])
RECOGNIZER_EPOCHS = 10

torch.set_num_threads(1)
threadpool_limits(1)
out, stage = Path(sys.argv[1]), sys.argv[2]
train = load_cmu_mocap().split("train")
train = train.subset(np.flatnonzero([len(m.joints) >= MIN_FRAMES for m in train]))
if stage in tl.LEARNED_PARTS:
    if stage == "flaw_recognizer":
        tl.LEARNED_CONFIGS["cmu"]["schedule"] = dict(tl.LEARNED_CONFIGS["default"]["schedule"], n_epochs=RECOGNIZER_EPOCHS)
    tl.train_learned(train, out, split="all", only=stage, config="cmu", device="cpu")
elif stage == "assemble":
    parts = tl.train_learned(train, out, split="all")  # loads the finished parts
    thresholds = tl.calibrate_learned(parts, train, split="all")
    info = {name: {k: v for k, v in __import__("json").loads((out / "parts" / f"{name}.json").read_text()).items()
                   if k != "history"} for name in tl.LEARNED_PARTS}
    manifest = {"dataset": "cmu_mocap", "split": "train", "config": "default (flaw recogniser: 10 epochs)",
                "clips": len(train), "subjects": sorted(set(int(s) for s in train.subjects)), "licence": CMU_LICENCE,
                "command": "python examples/train_cmu_weights.py OUT {flaw_classifier,flaw_recognizer,flaw_repairer,noise_filter,amplitude_restorer,assemble}",
                "notes": ["learned steps only: method='concepts' (the paper's parts) is not available for these weights",
                          f"training clips of at least {MIN_FRAMES} frames", "held-out subjects: "
                          "refiner.io.datasets.CMU_TEST_SUBJECTS"],
                "learned": {**info, **thresholds}}
    model = Refiner(None, None, None, None, None, None, parts["flaw_recognizer"], parts["flaw_repairer"],
                    parts["flaw_classifier"], noise_filter=parts["noise_filter"],
                    amplitude_restorer=parts["amplitude_restorer"], skeleton="cmu_mocap",
                    action_names=CMU_ACTIONS, manifest=manifest)
    folder = Path(sys.argv[3]) if len(sys.argv) > 3 else out / "refiner"
    model.save(folder, half=True)
    print(Refiner.load(folder).manifest["learned"])
else:
    raise SystemExit(f"unknown stage {stage!r}")
