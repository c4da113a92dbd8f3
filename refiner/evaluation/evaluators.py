"""Action2Motion's pretrained GRU action recognisers: the feature extractor of FID, accuracy and diversity.

The four published recognisers (:data:`RECOGNIZERS`) and how they are loaded: the HumanAct12 one
ships in the package (:mod:`refiner.evaluation.evaluator_weights`), the others are read from
:func:`evaluators_dir` as safetensors or as the original ``.tar`` checkpoints. The network and its
hidden-state modes are :mod:`refiner.evaluation.action_recognizer`, the input protocol (crops, root
subtraction, scale; ``generator_formats.md`` §8.3) :mod:`refiner.evaluation.recognizer_input`; their
public names are importable from here as well.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from refiner.core.serialization import load_state
from refiner.evaluation.action_recognizer import HIDDEN_MODES, ActionRecognizer, RecognizerConfig
from refiner.evaluation.evaluator_weights import packaged_recognizer
from refiner.evaluation.recognizer_input import crop_clip, prepare_clips
from refiner.io.data_sources import missing_message
from refiner.io.datasets import _CMU_UNIT_METRES, CMU_ACTIONS, HUMANACT12_ACTIONS, default_data_dir

__all__ = [
    "RecognizerConfig",
    "ActionRecognizer",
    "RECOGNIZERS",
    "HIDDEN_MODES",
    "HUMANACT12_FINE_CODES",
    "load_recognizer",
    "load_recognizer_state",
    "evaluators_dir",
    "crop_clip",
    "prepare_clips",
]

#: Fine HumanAct12 classes of ``humanact12_fine``: the 34 fine codes ``AAff`` in sorted order (the
#: recogniser scores 99 % on real clips with this order).
HUMANACT12_FINE_CODES = (
    "0101", "0102", "0103", "0104", "0105", "0106", "0107", "0201", "0301", "0401", "0402", "0501",
    "0502", "0503", "0504", "0505", "0601", "0602", "0603", "0604", "0605", "0701", "0801", "0802",
    "0803", "0901", "1001", "1002", "1101", "1102", "1103", "1104", "1201", "1202",
)


#: The four published recognisers: config, ``.safetensors`` file and original ``.tar`` file, all in
#: :func:`evaluators_dir`. Their accuracies on real clips (60-frame crops; CMU 100 frames) are in the
#: README of the shared data folder.
RECOGNIZERS: dict[str, tuple[RecognizerConfig, str, str]] = {
    "humanact12": (
        RecognizerConfig(24, 12, "humanact12", "humanact12", 60, 1.0, HUMANACT12_ACTIONS),
        "humanact12_gru.safetensors", "action_recognition_model_humanact12.tar",
    ),
    "humanact12_fine": (
        RecognizerConfig(24, 34, "humanact12_fine", "humanact12", 60, 1.0, HUMANACT12_FINE_CODES),
        "humanact12_fine_gru.safetensors", "action_recognition_model_humanact12_fineG.tar",
    ),
    "ntu13": (
        RecognizerConfig(18, 13, "ntu13", "uestc", 60, 1.0, ()),
        "ntu13_vibe_gru.safetensors", "action_recognition_model_vibe_v2.tar",
    ),
    "cmu_mocap": (
        # Action2Motion feeds raw CMU units / 20; our CMU motions are in metres (refiner.io.datasets).
        RecognizerConfig(20, 8, "cmu_mocap", "cmu_mocap", 100, 1.0 / (_CMU_UNIT_METRES * 20.0), CMU_ACTIONS),
        "cmu_mocap_gru.safetensors", "action_recognition_model_mocap_new.tar",
    ),
}


def evaluators_dir() -> Path:
    """The folder holding the recogniser weights: ``default_data_dir().parent / "evaluators"``."""
    return default_data_dir().parent / "evaluators"


def load_recognizer_state(path: str | os.PathLike) -> dict[str, torch.Tensor]:
    """Read a recogniser state dict from a ``.safetensors`` file or an original ``.tar`` checkpoint.

    Parameters
    ----------
    path : path
        ``.safetensors`` (the tensors themselves), or Action2Motion's ``.tar`` / ``.pt`` / ``.pth``
        (a legacy ``torch.save`` dict with the state dict under ``"model"``), read with
        ``torch.load(weights_only=True)`` so that no code from the file runs.

    Returns
    -------
    dict of str to Tensor
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"no recogniser weights at {str(path)!r}.")
    if path.suffix == ".safetensors":
        tensors, _ = load_state(path)
        return {k: torch.from_numpy(np.array(v)) for k, v in tensors.items()}
    if path.suffix in (".tar", ".pt", ".pth"):
        try:
            ckpt = torch.load(path, map_location="cpu", weights_only=True)
        except Exception as e:  # pickle and zip errors have many types
            raise ValueError(f"{str(path)!r} is not a readable torch checkpoint of tensors: {e}") from e
        if not isinstance(ckpt, dict) or "model" not in ckpt:
            raise ValueError(f"{str(path)!r} must hold a dict with the state dict under 'model'.")
        return dict(ckpt["model"])
    raise ValueError(f"unsupported recogniser file {str(path)!r}: expected .safetensors or .tar.")


def load_recognizer(
    name_or_path: str | os.PathLike = "humanact12",
    *,
    hidden: str = "random",
    random_state: int = 0,
    directory: str | os.PathLike | None = None,
) -> ActionRecognizer:
    """Load a pretrained Action2Motion recogniser.

    Parameters
    ----------
    name_or_path : str or path, default="humanact12"
        A name in :data:`RECOGNIZERS` (``humanact12``, ``humanact12_fine``, ``ntu13``, ``cmu_mocap``),
        read from ``directory`` (the ``.safetensors`` file, else the original ``.tar``), or a path to
        either kind of file. For a path the recogniser is identified by its weight shapes. Without
        ``directory``, ``humanact12`` is the copy shipped in the package (the same tensors,
        :mod:`refiner.evaluation.evaluator_weights`).
    hidden : {"random", "fixed", "zeros"}, default="random"
        Initial hidden-state mode, see :class:`ActionRecognizer`.
    random_state : int, default=0
    directory : path, optional
        Default the shipped copy for ``humanact12``, else :func:`evaluators_dir`.

    Returns
    -------
    ActionRecognizer
        In eval mode, on the CPU.

    Raises
    ------
    ValueError
        Unknown name, missing file, or weights that match no known recogniser.
    """
    name = str(name_or_path)
    if name in RECOGNIZERS:
        config, st_file, tar_file = RECOGNIZERS[name]
        path = packaged_recognizer(name) if directory is None else None
        if path is None:
            folder = Path(directory) if directory is not None else evaluators_dir()
            path = folder / st_file if (folder / st_file).is_file() else folder / tar_file
        if not path.is_file():
            raise ValueError(f"recogniser {name!r} not found: " + missing_message("evaluators", folder, (st_file, tar_file)))
        state = load_recognizer_state(path)
    else:
        path = Path(name_or_path)
        if not path.suffix:
            raise ValueError(f"unknown recogniser {name!r}; known: {', '.join(RECOGNIZERS)} (or pass a file path).")
        state = load_recognizer_state(path)
        config = _config_from_state(path, state)
    model = ActionRecognizer(config, hidden=hidden, random_state=random_state)
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError as e:
        raise ValueError(f"{str(path)!r} does not fit recogniser {config.name!r}: {e}") from e
    return model.eval()


def _config_from_state(path: Path, state: dict) -> RecognizerConfig:
    """The known recogniser whose weight shapes match ``state``."""
    try:
        n_in = state["recurrent.weight_ih_l0"].shape[1]
        n_classes = state["linear2.weight"].shape[0]
    except KeyError as e:
        raise ValueError(f"{str(path)!r} is not an Action2Motion recogniser state dict (missing {e}).") from None
    for config, _, _ in RECOGNIZERS.values():
        if (config.n_joints * 3, config.n_classes) == (n_in, n_classes):
            return config
    known = ", ".join(f"{n} ({c.n_joints * 3} inputs, {c.n_classes} classes)" for n, (c, _, _) in RECOGNIZERS.items())
    raise ValueError(f"{str(path)!r} has {n_in} inputs and {n_classes} classes, matching no known recogniser; "
                     f"known: {known}.")
