"""The reference generators by kind: loading the shipped weights, training and saving new ones with a manifest.

The shipped weights (float16 safetensors, trained on HumanAct12 subjects 1-10) live in
:data:`WEIGHTS_DIR` with a ``manifest.json`` listing each file's sha256; HumanAct12 is for academic,
non-commercial use only, and so are they.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from dataclasses import replace
from typing import Any

from refiner.core.manifest import file_sha256, read_generator_manifest, write_manifest
from refiner.nn.training import TrainSchedule
from refiner.reference.base import ReferenceGenerator
from refiner.reference.diffusion import MotionDiffusionGenerator
from refiner.reference.lie_vae import LieVAEGenerator
from refiner.reference.transformer_cvae import TransformerCVAEGenerator

__all__ = ["GENERATOR_KINDS", "KIND_PARAMETERS", "LICENCE", "WEIGHTS_DIR", "load_reference_generator", "train_reference_generator"]

#: Where the shipped generator weights and their manifest live.
WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights" / "generators"
LICENCE = ("Trained on HumanAct12 (derived from PHSPD) subjects 1-10: academic, non-commercial use only. "
           "Cite Action2Motion (Guo et al. 2020) and PHSPD (Zou et al. 2020).")

#: Reference generator classes by the short name used by the CLI, the bench and the shipped weights.
#: ``a2m`` and ``actor`` are the small variants (class defaults, 8 minutes of CPU training each), kept so
#: that the bench shows the refiner across generator quality; the ``-large`` kinds are the same
#: designs with the sizes of :data:`KIND_PARAMETERS`, trained far longer.
GENERATOR_KINDS: dict[str, type[ReferenceGenerator]] = {
    "a2m": LieVAEGenerator, "actor": TransformerCVAEGenerator, "mdm": MotionDiffusionGenerator,
    "a2m-large": LieVAEGenerator, "actor-large": TransformerCVAEGenerator,
}
#: Hyper-parameters of a kind beyond its class's defaults.
KIND_PARAMETERS: dict[str, dict[str, Any]] = {
    # 300 epochs, last epoch's weights (its samples improve after the validation loss stops), guidance with
    # the lowest FID: docs/decisions.md D13
    "a2m-large": {"hidden": 256, "schedule": TrainSchedule(n_epochs=300, batch_size=128, learning_rate=1e-3,
                                                            patience=300, keep_best=False), "guidance": 0.25},
    # kl_weight 1e-4 so that the latent is used (1e-2 drew the action's mean motion), the fitted prior keeps
    # samples where the posteriors were (TransformerCVAEGenerator's `prior`), guidance 1: docs/decisions.md D13
    "actor-large": {"d_model": 128, "n_layers": 4, "ffn_dim": 256, "dropout": 0.1, "kl_weight": 1e-4, "prior": "fitted",
                    "guidance": 1.0},
}


def load_reference_generator(kind: str = "a2m", *, folder: str | os.PathLike | None = None, device: str = "cpu",
                             verify: bool = True):
    """Load a trained reference generator.

    Parameters
    ----------
    kind : {"a2m", "actor", "mdm", "a2m-large", "actor-large"}, default="a2m"
    folder : path, optional
        A folder written by :func:`train_reference_generator` (``<kind>.safetensors`` plus
        ``manifest.json``); default the shipped weights, :data:`WEIGHTS_DIR`.
    device : str, default="cpu"
    verify : bool, default=True
        Check the manifest against its `content_sha256` and the file against its sha256.

    Returns
    -------
    ReferenceGenerator

    Raises
    ------
    ValueError
        Unknown kind, missing or corrupt weights.
    """
    cls = _kind(kind)
    folder = Path(folder) if folder is not None else WEIGHTS_DIR
    _, paths = read_generator_manifest(folder, verify=verify)
    if kind not in paths:
        raise ValueError(f"{str(folder / 'manifest.json')!r} lists no {kind!r} generator; train one with "
                         f"`motion-refiner train-generator --kind {kind} --out {folder}`.")
    path = paths[kind]
    return cls.load(path, device=device)


def train_reference_generator(kind: str, dataset, out: str | os.PathLike, *, split: str = "train", quick: bool = False,
                              max_seconds: float | None = None, random_state: int = 0, device: str = "auto",
                              verbose: bool = False, command: str = "", n_epochs: int | None = None,
                              init: str | os.PathLike | None = None, checkpoint: str | os.PathLike | None = None):
    """Train one reference generator on a split of HumanAct12 and save it (float16) with a manifest entry.

    Parameters
    ----------
    kind : {"a2m", "actor", "mdm", "a2m-large", "actor-large"}
    dataset : MotionDataset
        HumanAct12 (with subject ids when ``split`` is not ``"all"``).
    out : path
        Folder; ``<kind>.safetensors`` is written and ``manifest.json`` updated (other kinds kept).
    split : {"train", "all"}, default="train"
        ``"train"`` is subjects 1-10, the shipped weights' split.
    quick : bool, default=False
        A tiny network and a few epochs (for tests).
    max_seconds : float, optional
        Training time limit (training then depends on the machine's speed; by default the fixed
        number of epochs and early stopping make it reproducible for a seed).
    random_state : int, default=0
    device : str, default="auto"
    verbose : bool, default=False
        Show a progress bar.
    command : str, optional
        The command line recorded in the manifest.
    n_epochs : int, optional
        Epochs of the schedule (its learning rate decays to 0 over them); default the class's.
    init : path, optional
        A saved generator of the same kind whose network training goes on from (``warm_start``);
        the kind's :data:`KIND_PARAMETERS` are set on it (a network of other sizes is refused),
        the rest of its hyper-parameters are kept.
    checkpoint : path, optional
        Training state saved every epoch; a run that finds it resumes from it.

    Returns
    -------
    ReferenceGenerator
        The fitted generator.
    """
    cls = _kind(kind)
    data = dataset.split(split)
    base = _init_generator(cls.load(init, device="cpu"), kind, init) if init is not None else cls(**KIND_PARAMETERS.get(kind, {}))
    schedule = replace(base.schedule, max_seconds=max_seconds, device=device, progress=verbose)
    if n_epochs is not None:
        schedule = replace(schedule, n_epochs=int(n_epochs), patience=max(schedule.patience, int(n_epochs)))
    if quick:
        schedule = replace(schedule, n_epochs=2, steps_per_epoch=2, batch_size=16, patience=5)
    params: dict[str, Any] = {"schedule": schedule, "random_state": random_state, "warm_start": init is not None}
    if quick and init is None:
        params.update({"hidden": 16, "latent_dim": 4} if cls is LieVAEGenerator else
                      {"d_model": 16, "n_layers": 1, "n_heads": 2, "ffn_dim": 16})
        if cls is MotionDiffusionGenerator:
            params.update(diffusion_steps=20, sampling_steps=5)
    gen = base.set_params(**params).fit(data, checkpoint=checkpoint)
    gen.set_params(warm_start=False)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{kind}.safetensors"
    gen.save(path, half=True)
    manifest_path = out / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {}
    manifest.update({"dataset": getattr(dataset, "name", "humanact12"), "licence": LICENCE,
                     "crop_frames": gen.n_frames, "frame": "HumanAct12 native (metres, y down, facing -z), "
                     "first-frame root at the origin"})
    subjects = sorted({int(s) for s in getattr(data, "subjects", [])})
    manifest.setdefault("generators", {})[kind] = {
        "file": path.name, "sha256": file_sha256(path), "class": cls.__name__, "split": split, "subjects": subjects,
        "clips": len(data), "parameters": gen.n_parameters(), "epochs": len(gen.history_),
        "best_val_loss": min((h["val"] for h in gen.history_ if "val" in h), default=None),
        "train_seconds": gen.train_seconds_, "seed": random_state, "dtype": "float16", "command": command,
        "adapter": gen.adapter, "adapter_options": {k: v for k, v in gen.adapter_options().items() if k != "reference"},
    }
    write_manifest(manifest_path, manifest)
    return gen


def _init_generator(gen: ReferenceGenerator, kind: str, path) -> ReferenceGenerator:
    """A loaded generator with its kind's parameters set (ValueError when they change its network's sizes)."""
    shapes = {k: v.shape for k, v in gen.network_.state_dict().items()}
    gen.set_params(**KIND_PARAMETERS.get(kind, {}))
    rebuilt = {k: v.shape for k, v in gen._make_network({"action_names_": gen.action_names_}).state_dict().items()}
    if rebuilt != shapes:
        raise ValueError(f"{str(path)!r} is not a generator of kind {kind!r}: its network's sizes are not "
                         f"{KIND_PARAMETERS[kind]}.")
    return gen


def _kind(kind: str) -> type[ReferenceGenerator]:
    if kind not in GENERATOR_KINDS:
        raise ValueError(f"unknown reference generator {kind!r}; known: {', '.join(GENERATOR_KINDS)}.")
    return GENERATOR_KINDS[kind]
