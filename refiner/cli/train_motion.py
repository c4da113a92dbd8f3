"""``motion-refiner train-motion``: train the default refiner's motion model and assemble its weight set.

One one-thread process per model (the default, and with ``--folds`` the benchmark's two fold models), at most
``--jobs`` at a time; each writes ``progress.log`` and resumes from its checkpoint when rerun. Then every model is
calibrated on clean clips it never saw and ``OUT/<dataset>-motion`` is written
(``_build``).

Under ``torchrun --nproc_per_node N -m refiner train-motion ...`` the N processes train each model together, one
model after another (data-parallel: each draws its part of every batch, :func:`~refiner.refinement.training.motion_training.train_motion_model`);
rank 0 writes the checkpoints, logs and the weight set. Rerun the same command to resume.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["train_motion_arguments", "train_motion_run"]


def train_motion_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, required=True, help="root folder: runs in OUT/runs, the weight set in OUT/<dataset>-motion")
    p.add_argument("--dataset", default="humanact12", choices=["humanact12", "cmu_mocap"])
    p.add_argument("--data", type=Path, default=None, help="the dataset's file (default: ../shared/data/...)")
    p.add_argument("--steps", type=int, default=6000, help="training steps per model")
    p.add_argument("--folds", action="store_true", help="also the benchmark's fold models (`bench heldout` needs them)")
    p.add_argument("--ground-only", action="store_true", help="train nothing: calibrate the support steps' heights and "
                                                                  "the re-timing's stillness on the clean calibration clips into "
                                                                  "OUT/<dataset>-motion/manifest.json")
    p.add_argument("--jobs", type=int, default=2, help="models trained at once (one thread each; under torchrun: "
                                                       "one model at a time, on every process)")


def train_motion_run(args: argparse.Namespace) -> int:
    if args.jobs < 1 or args.steps < 1:
        raise ValueError("`--jobs` and `--steps` must be at least 1.")
    if args.ground_only:
        return _calibrate_ground_into(args)
    runs = args.out / "runs"
    jobs = [("mm_all", [])] + ([("mm_0", ["--fold", "0"]), ("mm_1", ["--fold", "1"])] if args.folds else [])
    if "WORLD_SIZE" in os.environ:  # started by torchrun
        return _train_together(args, runs, jobs)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    data = ["--data", str(args.data)] if args.data else []
    waiting, running, t0 = list(jobs), [], time.perf_counter()
    while waiting or running:
        while waiting and len(running) < args.jobs:
            name, extra = waiting.pop(0)
            cmd = [sys.executable, "-m", "refiner.refinement.training.motion_training", "--out", str(runs / name),
                   "--dataset", args.dataset, "--steps", str(args.steps), *extra, *data]
            print(f"start {name}: progress in {runs / name / 'progress.log'}", flush=True)
            running.append((name, subprocess.Popen(cmd, env=env)))
        time.sleep(5)
        for name, proc in list(running):
            if proc.poll() is not None:
                running.remove((name, proc))
                if proc.returncode != 0:
                    for _, other in running:
                        other.terminate()
                    print(f"{name} failed (exit {proc.returncode}); rerun to resume", file=sys.stderr)
                    return 1
                print(f"{name} done at {time.perf_counter() - t0:.0f} s", flush=True)
    return _build(args, runs)


def _train_together(args: argparse.Namespace, runs: Path, jobs: list) -> int:
    """Every process of the torchrun group trains each model in turn; rank 0 then assembles the weight set."""
    from refiner.nn.distributed import finish_distributed, init_distributed, is_main_process, world
    from refiner.refinement.training.motion_training import main as train

    init_distributed()
    data = ["--data", str(args.data)] if args.data else []
    t0 = time.perf_counter()
    for name, extra in jobs:
        if is_main_process():
            print(f"train {name} on {world()[1]} processes: progress in {runs / name / 'progress.log'}", flush=True)
        train(["--out", str(runs / name), "--dataset", args.dataset, "--steps", str(args.steps), *extra, *data])
        if is_main_process():
            print(f"{name} done at {time.perf_counter() - t0:.0f} s", flush=True)
    main_process = is_main_process()
    finish_distributed()
    return _build(args, runs) if main_process else 0


def _build(args: argparse.Namespace, runs: Path) -> int:
    """Calibrate the trained models (as shipped: float16 weights) on the clean clips none of them learned on
    (:func:`~refiner.refinement.training.motion_training.training_split`) and write ``OUT/<dataset>-motion``."""
    import torch

    from refiner.io.datasets import load_dataset
    from refiner.refinement.motion_model import MotionModel
    from refiner.refinement.motion_refiner import calibrated_threshold, write_motion_weights
    from refiner.refinement.training.motion_training import training_split

    torch.set_num_threads(1)
    ds = load_dataset(args.dataset, args.data)
    learn, calibrate = training_split(ds)
    models = {name: MotionModel.load(runs / folder / "motion_model.safetensors")
              for name, folder in _MODELS.items() if (runs / folder / "motion_model.safetensors").is_file()}
    for m in models.values():
        for t in m.network_.state_dict().values():
            if t.is_floating_point():
                t.copy_(t.half().float())
    thresholds = {name: calibrated_threshold(m, [ds[i].joints for i in calibrate], [ds[i].action for i in calibrate])
                  for name, m in models.items()}
    print("thresholds", thresholds, flush=True)
    write_motion_weights(args.out / f"{args.dataset}-motion", models, thresholds, skeleton=ds[0].skeleton,
                         dataset=f"{args.dataset}: {len(learn)} clips", licence=_LICENCES[args.dataset],
                         support=_support(ds, calibrate),
                         notes={"calibration": f"{len(calibrate)} clean clips of other subjects"})
    return 0


def _support(ds, calibrate) -> dict:
    """The support steps' heights (``ground``: ``float_m``; ``glide``: ``glide_m``) and the re-timing's stillness
    (``retime``: ``still_m``), calibrated on the clean clips ``calibrate`` of ``ds``; no flaw mechanism is involved,
    so one set serves every model of the weight set. A support step the clips do not allow (its height would pass
    25 cm) is left out of it."""
    from refiner.refinement.motion_refiner import CalibrationConfig
    from refiner.refinement.steps.ground import calibrated_glide, calibrated_ground
    from refiner.refinement.steps.retime import calibrated_stillness

    cal, clips = CalibrationConfig(), [ds[i].joints for i in calibrate]
    heights = {"ground": ("float_m", calibrated_ground(clips, ds[0].skeleton, share=cal.share, window=cal.window)),
               "glide": ("glide_m", calibrated_glide(clips, ds[0].skeleton, share=cal.share, window=cal.window))}
    for step, (key, value) in heights.items():
        print(f"{step}: {key} {value}" + ("" if value else " (the clean clips do not allow it: no such step)"), flush=True)
    still_m = calibrated_stillness(clips, share=cal.still_share)
    print(f"retime: still_m {still_m}" + ("" if still_m > 0 else " (the clips hold exact repeats: freezes left alone)"),
          flush=True)
    return {**{step: {key: round(value, 4)} for step, (key, value) in heights.items() if value},
            "retime": {"still_m": round(still_m, 5)}}


def _calibrate_ground_into(args: argparse.Namespace) -> int:
    """``--ground-only``: write the support steps' calibrated heights and the re-timing's stillness into an existing
    weight set's manifest."""
    import json

    from refiner.io.datasets import load_dataset
    from refiner.refinement.training.motion_training import training_split

    path = args.out / f"{args.dataset}-motion" / "manifest.json"
    if not path.is_file():
        raise ValueError(f"no weight set at {path.parent}; train one first (without --ground-only).")
    ds = load_dataset(args.dataset, args.data)
    manifest = json.loads(path.read_text())
    for step in ("ground", "glide", "retime"):
        manifest.pop(step, None)
    manifest.update(_support(ds, training_split(ds)[1]))
    path.write_text(json.dumps(manifest, indent=1))
    return 0


_LICENCES = {"humanact12": "trained on HumanAct12 (PHSPD): academic, non-commercial use only",
             "cmu_mocap": "trained on the CMU Graphics Lab Motion Capture Database subset: free for all uses"}
_MODELS = {"all": "mm_all", "fold0": "mm_0", "fold1": "mm_1"}
