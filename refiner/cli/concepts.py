"""``motion-refiner concepts``: learn motion concepts (segmentation, anchor and transition concepts) from a dataset."""
from __future__ import annotations

import argparse
from pathlib import Path

from refiner.concepts.segmentation import DEFAULT_PENALTY
from refiner.io.datasets import load_dataset

__all__ = ["concepts_arguments", "concepts_run"]


def concepts_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default="humanact12", choices=["humanact12", "cmu_mocap"])
    p.add_argument("--data", type=Path, default=None, help="dataset file or folder (default: ../shared/data/...)")
    p.add_argument("--split", default="all", choices=["all", "train", "test"])
    p.add_argument("--out", type=Path, required=True, help="folder to write the concepts to")
    p.add_argument("--penalty", type=float, default=None, help="segmentation λ in cm² per joint (default 200)")
    p.add_argument("--n-clusters", type=int, default=8, help="anchor concepts per action")
    p.add_argument("--seed", type=int, default=0)


def concepts_run(args: argparse.Namespace) -> int:
    from refiner.concepts.learning import learn_concepts  # imports torch: here, so that --help stays cheap

    dataset = load_dataset(args.dataset, args.data)
    concepts = learn_concepts(
        dataset, split=args.split, penalty=args.penalty or DEFAULT_PENALTY, n_clusters=args.n_clusters,
        random_state=args.seed, progress=True,
    )
    concepts.save(args.out)
    s = concepts.summary()
    print(f"dataset      {args.dataset} ({args.split})")
    print(f"clips        {s['clips']}")
    print(f"anchors      {s['anchors']}")
    print(f"transitions  {s['transitions']}  ({s['mean_transitions_per_clip']:.2f} per clip, "
          f"{s['mean_transition_frames']:.1f} frames each)")
    print("clusters     " + ", ".join(f"{a}={k}" for a, k in s["clusters_per_action"].items()))
    print(f"seconds      {s['seconds']:.1f}")
    print(f"written to   {args.out}")
    return 0
