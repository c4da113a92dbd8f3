"""``motion-refiner train``: train the refiner's networks on a dataset (all of them, one part, or the learned steps)."""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from refiner.io.datasets import load_dataset

__all__ = ["train_arguments", "train_run"]


def train_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default="humanact12", choices=["humanact12", "cmu_mocap", "joints"],
                   help="joints: your own clips in --data (a folder of .npy + labels.csv, or a .npz; see the README)")
    p.add_argument("--data", type=Path, default=None, help="dataset file or folder (default: ../shared/data/...)")
    p.add_argument("--skeleton", default=None, help="with --dataset joints: registered skeleton of the clips "
                                                    "(default: the file's, else the one with their joint count)")
    p.add_argument("--split", default="all", choices=["all", "train"],
                   help="all subjects, or the benchmark training subjects (HumanAct12 1-10; CMU all but its 12 held out)")
    p.add_argument("--out", type=Path, required=True, help="folder for the trained refiner (rerun to resume)")
    p.add_argument("--config", default="default", choices=["default", "fast", "tiny"],
                   help="fast: the learned steps' schedules cut to about half (with --whole --jobs 2: under an hour "
                        "on 2 CPU cores); tiny: seconds, for tests")
    p.add_argument("--device", default="auto", help="auto (CUDA when available), cpu, cuda, ...")
    p.add_argument("--max-seconds", type=float, default=None, help="time limit per module")
    p.add_argument("--only", default=None, help="train just this part (for parallel runs); rerun without to assemble")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--whole", action="store_true",
                   help="train every part (the paper's and the learned steps) in --jobs parallel processes, then "
                        "calibrate and assemble the refiner in --out (rerun to resume; logs in --out/logs)")
    p.add_argument("--jobs", type=int, default=2, help="with --whole: parallel training processes, one thread each "
                                                       "(default 2; about one per CPU core)")
    p.add_argument("--learned", action="store_true",
                   help="train only the learned steps (flaw recognition and repair, the default method) and add them "
                        "to the refiner in --base; --only flaw_classifier / flaw_recognizer / flaw_repairer / noise_filter / amplitude_restorer / pose_prior / texture_filter / flaw_denoiser / motion_infiller / timing_estimator / noise_residual "
                        "trains one of them")
    p.add_argument("--base", type=Path, default=None,
                   help="with --learned: refiner folder whose concept and paper parts are kept (default: shipped weights of --split); "
                        "with --only and an optional part (flaw_denoiser, motion_infiller, timing_estimator, noise_residual): the refiner "
                        "it is calibrated for and added to, written to --out")


def train_run(args: argparse.Namespace) -> int:
    # these import torch: here, so that --help stays cheap
    from refiner.refinement.train_learned import train_learned_refiner
    from refiner.refinement.train_refiner import train_refiner

    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.whole and (args.learned or args.only is not None or args.base is not None):
        raise ValueError("`--whole` trains every part itself: it takes neither --learned, --only nor --base.")
    dataset = load_dataset(args.dataset, args.data, skeleton=args.skeleton)
    if args.whole:
        return _train_whole(args, dataset)
    if args.learned:
        refiner = train_learned_refiner(dataset, args.out, split=args.split, config=args.config, device=args.device,
                                        random_state=args.seed, max_seconds=args.max_seconds, only=args.only,
                                        base=args.base, progress=True)
        if refiner is None:
            print(f"trained part {args.only!r} into {args.out / 'parts'}")
        elif args.only is not None:
            print(f"part {args.only!r} calibrated and added to the refiner of {args.base}; written to {args.out}")
        else:
            print(f"learned steps added; flaw threshold {refiner.flaw_recognizer.threshold_:.3f}; written to {args.out}")
        return 0
    refiner = train_refiner(dataset, args.out, split=args.split, config=args.config, device=args.device,
                            random_state=args.seed, progress=True, max_seconds=args.max_seconds, only=args.only)
    if refiner is None:
        print(f"trained part {args.only!r} into {args.out / 'parts'}")
        return 0
    counts = refiner.n_parameters()
    print(f"trained on {refiner.manifest['clips']} clips ({args.split}); parameters: "
          + ", ".join(f"{k}={v:,}" for k, v in counts.items()))
    print(f"seconds per module: {refiner.manifest['train_seconds']}")
    print(f"written to {args.out}")
    return 0


def _train_whole(args: argparse.Namespace, dataset) -> int:
    from refiner.refinement.train_whole import train_whole_refiner

    common = ("--dataset", args.dataset, "--split", args.split, "--config", args.config, "--seed", str(args.seed),
              "--device", args.device, *(("--data", str(args.data)) if args.data is not None else ()),
              *(("--skeleton", args.skeleton) if args.skeleton is not None else ()),
              *(("--max-seconds", str(args.max_seconds)) if args.max_seconds is not None else ()))
    try:
        refiner = train_whole_refiner(dataset, args.out, common, split=args.split, n_jobs=args.jobs, config=args.config,
                                      random_state=args.seed, device=args.device)
    except RuntimeError as e:  # a job failed: its log says why, and a rerun resumes
        print(f"motion-refiner train: error: {e}", file=sys.stderr)
        return 1
    record = (args.out / "train_whole.json").read_text()
    print(f"whole refiner written to {args.out} (flaw threshold {refiner.flaw_recognizer.threshold_:.3f}); {record}")
    return 0
