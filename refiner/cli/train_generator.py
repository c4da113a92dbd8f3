"""``motion-refiner train-generator``: train a reference generator (a2m, actor, mdm and the -large kinds) on HumanAct12."""
from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from refiner.cli.options import GENERATOR_NAMES, set_threads
from refiner.io.datasets import load_dataset

__all__ = ["train_generator_arguments", "train_generator_run"]


def train_generator_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--kind", required=True, choices=GENERATOR_NAMES,
                   help="a2m: Action2Motion-style Lie GRU VAE; actor: ACTOR-style transformer CVAE; mdm: MDM-style "
                        "diffusion; a2m-large, actor-large: the same designs, larger")
    p.add_argument("--out", type=Path, required=True,
                   help="folder for <kind>.safetensors and manifest.json (refiner/weights/generators ships them)")
    p.add_argument("--data", type=Path, default=None, help="HumanAct12 file or folder (default: ../shared/data/...)")
    p.add_argument("--split", default="train", choices=["train", "all"], help="train = subjects 1-10 (shipped)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-seconds", type=float, default=None,
                   help="training time limit (default none: fixed epochs with early stopping, reproducible)")
    p.add_argument("--epochs", type=int, default=None,
                   help="epochs of the schedule (the learning rate decays to 0 over them; default the generator's)")
    p.add_argument("--init", type=Path, default=None,
                   help="a saved generator of the same kind (e.g. the shipped one) to go on training from")
    p.add_argument("--checkpoint", type=Path, default=None,
                   help="training state saved every epoch; rerunning the same command resumes from it")
    p.add_argument("--device", default="auto", help="auto (CUDA when available), cpu, cuda, ...")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    p.add_argument("--quick", action="store_true", help="tiny network, a few steps (for tests)")


def train_generator_run(args: argparse.Namespace) -> int:
    from refiner.reference import train_reference_generator  # imports torch: here, so that --help stays cheap

    set_threads(args.threads)
    dataset = load_dataset("humanact12", args.data)
    command = "motion-refiner train-generator " + " ".join(
        shlex.quote(a) for a in (f"--kind={args.kind}", f"--out={args.out}", f"--split={args.split}", f"--seed={args.seed}")
        + ((f"--max-seconds={args.max_seconds:g}",) if args.max_seconds else ())
        + ((f"--epochs={args.epochs}",) if args.epochs else ()) + ((f"--init={args.init}",) if args.init else ())
        + ((f"--threads={args.threads}",) if args.threads else ()) + (("--quick",) if args.quick else ()))
    gen = train_reference_generator(args.kind, dataset, args.out, split=args.split, quick=args.quick,
                                    max_seconds=args.max_seconds, random_state=args.seed, device=args.device,
                                    verbose=True, command=command, n_epochs=args.epochs, init=args.init,
                                    checkpoint=args.checkpoint)
    best = min((h["val"] for h in gen.history_ if "val" in h), default=float("nan"))
    print(f"trained {type(gen).__name__} ({args.kind}) on HumanAct12 split {args.split!r}: "
          f"{gen.n_parameters():,} parameters, {len(gen.history_)} epochs, best validation loss {best:.4f}, "
          f"{gen.train_seconds_:.0f} s")
    print(f"written to {args.out / (args.kind + '.safetensors')} (float16) and {args.out / 'manifest.json'}")
    return 0
