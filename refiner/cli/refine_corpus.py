"""``motion-refiner refine-corpus``: refine a folder or glob of shards on Ray Data (:mod:`refiner.corpus`).

Needs the optional extra (``pip install 'motion-refiner[ray]'``). Ray prints the pipeline's progress; this command
prints one line per failed shard and the summary, and writes it as ``OUT/summary.json``.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

__all__ = ["refine_corpus_arguments", "refine_corpus_run"]


def refine_corpus_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="IN", help="folder of .npy/.npz shards, or a glob pattern in quotes ('runs/*/*.npy')")
    p.add_argument("-o", "--out", type=Path, required=True,
                   help="folder: <stem>.npy (or .npz) and <stem>.report.jsonl per shard; complete shards are skipped")
    p.add_argument("--address", default=None,
                   help="Ray cluster to join ('auto': the one `ray start` runs on this machine); default: a local one")
    p.add_argument("--workers", type=int, default=1, help="refining workers, one CPU each (default 1)")
    p.add_argument("--gpus-per-worker", type=float, default=0.0, help="GPUs per worker (default 0: CPU)")
    p.add_argument("--batch-size", type=int, default=16, help="clips per batch, from any shards (default 16)")
    p.add_argument("--stack", action="store_true",
                   help="refine a batch's clips of equal length in one call: faster (most on a GPU), equal to "
                        "per-clip refinement up to float rounding")
    p.add_argument("--adapter", default=None, help="read raw generator output with this adapter")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE", help="adapter option, repeatable")
    p.add_argument("--skeleton", default="humanact12", help="skeleton of the joints / adapter target")
    p.add_argument("--fps", type=float, default=20.0, help="frame rate of joint files (default 20)")
    p.add_argument("--weights", type=Path, default=None,
                   help="folder holding <skeleton>-motion/, looked in before the shipped weights")


def refine_corpus_run(args: argparse.Namespace) -> int:
    from refiner.cli.refine import _parse_options
    from refiner.corpus import refine_corpus, require_ray

    options = _parse_options(args.option)
    if options and args.adapter is None:
        raise ValueError("`--option` needs `--adapter`.")
    try:
        require_ray()
    except ImportError as e:  # the extra is optional: say how to get it, as a usage error
        raise ValueError(str(e)) from None
    summary = refine_corpus(args.input, args.out, address=args.address, workers=args.workers,
                            gpus_per_worker=args.gpus_per_worker, batch_size=args.batch_size, stack=args.stack,
                            adapter=args.adapter, options=options, skeleton=args.skeleton, fps=args.fps,
                            weights=args.weights)
    for shard, error in summary.failed.items():
        print(f"FAILED {shard}: {error}", file=sys.stderr)
    (args.out / "summary.json").write_text(json.dumps(summary.to_dict(), indent=1) + "\n")
    print(f"refined {summary.refined} of {summary.shards} shard(s) ({summary.skipped} already complete, "
          f"{len(summary.failed)} failed): {summary.clips} clips, {summary.frames_changed} of {summary.frames} frames "
          f"changed, {summary.seconds:.1f} s, {summary.clips_per_s:.1f} clips/s")
    return 1 if summary.failed else 0
