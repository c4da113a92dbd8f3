"""The ``motion-refiner`` command line: one sub-command per job.

Each sub-command is a pair ``(add_arguments, run)`` in ``COMMANDS``; ``run`` returns the exit code.
Only this module and ``refiner.evaluation.bench`` write to stdout.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable, Sequence

from refiner.cli import commands as _cmd
from refiner.cli import doctor as _doctor
__all__ = ["main", "COMMANDS"]


def _concepts_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default="humanact12", choices=["humanact12", "cmu_mocap"])
    p.add_argument("--data", type=Path, default=None, help="dataset file or folder (default: ../shared/data/...)")
    p.add_argument("--split", default="all", choices=["all", "train", "test"])
    p.add_argument("--out", type=Path, required=True, help="folder to write the concepts to")
    p.add_argument("--penalty", type=float, default=None, help="segmentation λ in cm² per joint (default 200)")
    p.add_argument("--n-clusters", type=int, default=8, help="anchor concepts per action")
    p.add_argument("--seed", type=int, default=0)


def _concepts_run(args: argparse.Namespace) -> int:
    from refiner.concepts.learning import learn_concepts
    from refiner.concepts.segmentation import DEFAULT_PENALTY
    from refiner.io.datasets import load_dataset

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


def _train_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dataset", default="humanact12", choices=["humanact12", "joints"],
                   help="joints: your own clips in --data (a folder of .npy + labels.csv, or a .npz; see the README)")
    p.add_argument("--data", type=Path, default=None, help="dataset file or folder (default: ../shared/data/...)")
    p.add_argument("--skeleton", default=None, help="with --dataset joints: registered skeleton of the clips "
                                                    "(default: the file's, else the one with their joint count)")
    p.add_argument("--split", default="all", choices=["all", "train"], help="all subjects, or 1-10 for benchmarks")
    p.add_argument("--out", type=Path, required=True, help="folder for the trained refiner (rerun to resume)")
    p.add_argument("--config", default="default", choices=["default", "tiny"])
    p.add_argument("--device", default="auto", help="auto (CUDA when available), cpu, cuda, ...")
    p.add_argument("--max-seconds", type=float, default=None, help="time limit per module")
    p.add_argument("--only", default=None, help="train just this part (for parallel runs); rerun without to assemble")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--learned", action="store_true",
                   help="train only the learned steps (flaw recognition and repair, the default method) and add them "
                        "to the refiner in --base; --only flaw_recognizer / flaw_repairer trains one of them")
    p.add_argument("--base", type=Path, default=None,
                   help="with --learned: refiner folder whose concept and paper parts are kept (default: shipped weights of --split)")


def _train_run(args: argparse.Namespace) -> int:
    import logging

    from refiner.io.datasets import load_dataset
    from refiner.refinement.train_refiner import train_refiner

    logging.basicConfig(level=logging.INFO, format="%(message)s")
    dataset = load_dataset(args.dataset, args.data, skeleton=args.skeleton)
    if args.learned:
        from refiner.refinement.train_learned import train_learned_refiner

        refiner = train_learned_refiner(dataset, args.out, split=args.split, config=args.config, device=args.device,
                                        random_state=args.seed, max_seconds=args.max_seconds, only=args.only,
                                        base=args.base, progress=True)
        if refiner is None:
            print(f"trained part {args.only!r} into {args.out / 'parts'}")
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


def _bench_arguments(p: argparse.ArgumentParser) -> None:
    from refiner.evaluation.bench import SUITES

    p.add_argument("suite", nargs="?", default="all", choices=[*SUITES, "all"])
    p.add_argument("--data", type=Path, default=None, help="folder holding humanact12/ (default: ../shared/data)")
    p.add_argument("--out", type=Path, default=None, help="folder for REPORT.md, plots and <suite>.json (the figures as records)")
    p.add_argument("--quick", action="store_true", help="tiny configuration (for tests)")
    p.add_argument("--stride", type=int, default=1, help="flaws, skeletons: keep every N-th held-out clip (skeletons default 4)")
    p.add_argument("--severity", type=int, action="append", choices=[1, 2, 3], help="flaws: only these severities")


def _bench_run(args: argparse.Namespace) -> int:
    from refiner.evaluation.bench import run_benchmarks

    return run_benchmarks(args.suite, data=args.data, out=args.out, quick=args.quick, stride=args.stride,
                          severities=tuple(args.severity) if args.severity else None)


def _adapters_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--no-autoload", action="store_true", help="only the built-in adapters (skip entry points)")


def _adapters_run(args: argparse.Namespace) -> int:
    from refiner.plugins.manager import get_plugin_manager

    infos = get_plugin_manager(autoload=not args.no_autoload).adapters()
    rows = [("adapter", "skeletons", "fps", "up", "from", "format")]
    rows += [(i.name, ",".join(i.skeletons), f"{i.fps:g}", i.up, i.source, i.format) for i in infos.values()]
    widths = [max(len(r[k]) for r in rows) for k in range(5)]
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r[:5], widths)) + "  " + r[5])
    return 0


COMMANDS: dict[str, tuple[str, Callable, Callable]] = {
    "concepts": ("learn motion concepts from a dataset", _concepts_arguments, _concepts_run),
    "train": ("train the refiner's networks on a dataset", _train_arguments, _train_run),
    "bench": ("run benchmarks and print figures", _bench_arguments, _bench_run),
    "adapters": ("list installed generator adapters", _adapters_arguments, _adapters_run),
    "demo": ("sample every action from a reference generator, refine, write pictures and a table",
             _cmd.demo_arguments, _cmd.demo_run),
    "refine": ("refine motion files (.npy/.npz joints or raw generator output)", _cmd.refine_arguments,
               _cmd.refine_run),
    "train-generator": ("train a reference generator (a2m or actor) on HumanAct12",
                        _cmd.train_generator_arguments, _cmd.train_generator_run),
    "doctor": ("show what is installed: weights, evaluators, data found, torch/CUDA, threads",
               _doctor.doctor_arguments, _doctor.doctor_run),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="motion-refiner", description="Refine synthesized 3D human motion.")
    sub = parser.add_subparsers(dest="command", required=True)
    for name, (help_text, add_arguments, _) in COMMANDS.items():
        add_arguments(sub.add_parser(name, help=help_text, description=help_text))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    _, _, run = COMMANDS[args.command]
    try:
        return run(args)
    except ValueError as e:
        print(f"motion-refiner {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
