"""``motion-refiner train``: train the concepts method's refiner on a dataset (all of its parts, or one)."""
from __future__ import annotations

import argparse
import logging
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
                   help="fast: the networks stopped after 40 epochs; tiny: seconds, for tests")
    p.add_argument("--device", default="auto", help="auto (CUDA when available), cpu, cuda, ...")
    p.add_argument("--max-seconds", type=float, default=None, help="time limit per module")
    p.add_argument("--only", default=None, help="train just this part (for parallel runs); rerun without to assemble")
    p.add_argument("--seed", type=int, default=0)


def train_run(args: argparse.Namespace) -> int:
    from refiner.refinement.train_refiner import train_refiner  # imports torch: here, so that --help stays cheap

    logging.basicConfig(level=logging.INFO, format="%(message)s")
    dataset = load_dataset(args.dataset, args.data, skeleton=args.skeleton)
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
