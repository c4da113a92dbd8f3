"""The ``motion-refiner`` command line: the parser and one sub-command per job.

Each sub-command is a module of :mod:`refiner.cli` with ``<name>_arguments(parser)`` and
``<name>_run(args)``, registered in :data:`COMMANDS`; ``run`` returns the exit code. The command-line
modules are the only code of the package that writes to stdout.
"""
from __future__ import annotations

import argparse
import sys
from typing import Callable, Sequence

from refiner.cli.adapters import adapters_arguments, adapters_run
from refiner.cli.bench import bench_arguments, bench_run
from refiner.cli.concepts import concepts_arguments, concepts_run
from refiner.cli.demo import demo_arguments, demo_run
from refiner.cli.doctor import doctor_arguments, doctor_run
from refiner.cli.refine import refine_arguments, refine_run
from refiner.cli.refine_corpus import refine_corpus_arguments, refine_corpus_run
from refiner.cli.train import train_arguments, train_run
from refiner.cli.train_generator import train_generator_arguments, train_generator_run
from refiner.cli.train_motion import train_motion_arguments, train_motion_run

__all__ = ["main", "build_parser", "COMMANDS"]

#: Sub-command -> (help, add its arguments to a parser, run it with the parsed arguments -> exit code).
COMMANDS: dict[str, tuple[str, Callable, Callable]] = {
    "concepts": ("learn motion concepts from a dataset", concepts_arguments, concepts_run),
    "train-motion": ("train the default refiner's motion model (resumable) and write its weight set",
                     train_motion_arguments, train_motion_run),
    "train": ("train the concepts method's refiner on a dataset", train_arguments, train_run),
    "bench": ("run benchmarks and print figures", bench_arguments, bench_run),
    "adapters": ("list installed generator adapters", adapters_arguments, adapters_run),
    "demo": ("sample every action from a reference generator, refine, write pictures and a table",
             demo_arguments, demo_run),
    "refine": ("refine motion files (.npy/.npz joints or raw generator output)", refine_arguments, refine_run),
    "refine-corpus": ("refine a folder or glob of shards on Ray Data (optional extra: motion-refiner[ray]); resumable",
                      refine_corpus_arguments, refine_corpus_run),
    "train-generator": ("train a reference generator (a2m, actor, mdm, a2m-large, actor-large) on HumanAct12",
                        train_generator_arguments, train_generator_run),
    "doctor": ("show what is installed: weights, evaluators, data found, torch/CUDA, threads",
               doctor_arguments, doctor_run),
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
