"""Assemble a motion weight set: the trained models (the default and, for HumanAct12, the benchmark's two folds), each
calibrated on the clean clips that none of them learned on (:func:`~refiner.refinement.training.motion_training.training_split`).

``python -m refiner.refinement.training.build_motion_weights --runs DIR --out refiner/weights/humanact12-motion``
reads ``DIR/mm_all`` and, where present, ``DIR/mm_0`` and ``DIR/mm_1`` (:mod:`~refiner.refinement.training.motion_training` outputs).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import torch

from refiner.io.datasets import load_dataset
from refiner.refinement.motion_model import MotionModel
from refiner.refinement.motion_refiner import calibrated_threshold, write_motion_weights
from refiner.refinement.training.motion_training import training_split

_LICENCES = {"humanact12": "trained on HumanAct12 (PHSPD): academic, non-commercial use only",
             "cmu_mocap": "trained on the CMU Graphics Lab Motion Capture Database subset: free for all uses"}
_MODELS = {"all": "mm_all", "fold0": "mm_0", "fold1": "mm_1"}


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--runs", required=True, type=Path)
    p.add_argument("--out", required=True, type=Path)
    p.add_argument("--dataset", default="humanact12", choices=sorted(_LICENCES))
    p.add_argument("--data", default=None)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    ds = load_dataset(args.dataset, args.data)
    learn, calibrate = training_split(ds)
    models = {name: MotionModel.load(args.runs / folder / "motion_model.safetensors")
              for name, folder in _MODELS.items() if (args.runs / folder / "motion_model.safetensors").is_file()}
    for m in models.values():  # calibrated as shipped: float16 weights
        for t in m.network_.state_dict().values():
            if t.is_floating_point():
                t.copy_(t.half().float())
    thresholds = {name: calibrated_threshold(m, [ds[i].joints for i in calibrate], [ds[i].action for i in calibrate])
                  for name, m in models.items()}
    print(thresholds)
    write_motion_weights(args.out, models, thresholds, skeleton=ds[0].skeleton, dataset=f"{args.dataset}: {len(learn)} clips",
                         licence=_LICENCES[args.dataset], notes={"calibration": f"{len(calibrate)} clean clips of other subjects"})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
