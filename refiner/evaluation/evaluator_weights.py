"""The Action2Motion HumanAct12 recogniser shipped inside the package, with its licence and provenance.

``refiner/weights/evaluators`` holds ``humanact12_gru.safetensors`` (float32, the exact tensors of
Action2Motion's ``model_file/action_recognition_model_humanact12.tar``), the MIT licence of its
source repository and a ``manifest.json`` that records the source (repository, commit, file and its
sha256), the licence and the sha256 of both files, verified on load like every weights folder
(:func:`refiner.core.manifest.read_evaluator_manifest`). :func:`refiner.evaluation.evaluators.load_recognizer` uses
this copy for ``"humanact12"`` unless a ``directory`` is passed, so the demo and the metrics work
without ``../shared``; the other recognisers (fine HumanAct12, NTU13, CMU-Mocap) are looked up in
:func:`refiner.evaluation.evaluators.evaluators_dir` as before.

The recogniser's code and weights are MIT-licensed by their authors; it was trained on HumanAct12
(derived from PHSPD, academic non-commercial use), which the manifest states as well.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Sequence

from refiner.core.manifest import file_sha256, read_evaluator_manifest, write_manifest
from refiner.core.serialization import save_state

__all__ = ["EVALUATOR_WEIGHTS_DIR", "LICENCE_FILE", "SOURCE", "packaged_recognizer", "package_recognizers"]

#: The shipped folder.
EVALUATOR_WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights" / "evaluators"
#: The source repository's licence, copied verbatim.
LICENCE_FILE = "LICENSE-action-to-motion.txt"
#: Where the shipped tensors come from.
SOURCE = {
    "repository": "https://github.com/EricGuo5513/action-to-motion",
    "commit": "fe31871178e7e1b620b113974b47f8854d377be9",
    "folder": "model_file",
    "authors": "Chuan Guo et al., Action2Motion: Conditioned Generation of 3D Human Motions (ACM MM 2020)",
}
_LICENCE = ("MIT (Copyright (c) 2022 Chuan Guo; full text in LICENSE-action-to-motion.txt). Trained by its "
            "authors on HumanAct12, which derives from PHSPD and is for academic, non-commercial use only.")


def packaged_recognizer(name: str, *, folder: str | os.PathLike | None = None, verify: bool = True) -> Path | None:
    """The verified shipped weights file of recogniser ``name``, or None when it is not shipped.

    Parameters
    ----------
    name : str
        A name in :data:`refiner.evaluation.evaluators.RECOGNIZERS`.
    folder : path, optional
        Default :data:`EVALUATOR_WEIGHTS_DIR`.
    verify : bool, default=True
        Check the manifest's ``content_sha256`` and the sha256 of the weights and the licence.

    Raises
    ------
    ValueError
        The manifest or a file is missing, malformed or does not match its sha256.
    """
    _, paths = read_evaluator_manifest(EVALUATOR_WEIGHTS_DIR if folder is None else folder, verify=verify)
    return paths.get(name)


def package_recognizers(source: str | os.PathLike, licence: str | os.PathLike, out: str | os.PathLike,
                        names: Sequence[str] = ("humanact12",)) -> dict:
    """Write the shipped folder from Action2Motion's original ``.tar`` files (how it was made).

    Parameters
    ----------
    source : path
        Folder holding ``action_recognition_model_*.tar`` (Action2Motion's ``model_file/``).
    licence : path
        The source repository's ``LICENSE``, copied as :data:`LICENCE_FILE`.
    out : path
        Folder to write (created).
    names : sequence of str, default=("humanact12",)

    Returns
    -------
    dict
        The manifest written.
    """
    # here, not at the top: evaluators imports this module (and torch)
    from refiner.evaluation.evaluators import RECOGNIZERS, load_recognizer_state

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    entries = {}
    for name in names:
        config, st_file, tar_file = RECOGNIZERS[name]
        original = Path(source) / tar_file
        state = load_recognizer_state(original)
        save_state(out / st_file, state, {"recognizer": name, "source_file": f"{SOURCE['folder']}/{tar_file}"})
        entries[name] = {
            "file": st_file, "sha256": file_sha256(out / st_file), "dtype": "float32",
            "parameters": int(sum(t.numel() for t in state.values())),
            "config": config.to_dict(),
            "source_file": f"{SOURCE['folder']}/{tar_file}", "source_sha256": file_sha256(original),
        }
    shutil.copyfile(licence, out / LICENCE_FILE)
    return write_manifest(out / "manifest.json", {
        "source": SOURCE, "licence": _LICENCE, "evaluators": entries,
        "documents": {"licence": {"file": LICENCE_FILE, "sha256": file_sha256(out / LICENCE_FILE)}},
        "command": "python -c 'from refiner.evaluation.evaluator_weights import package_recognizers; "
                   "package_recognizers(\"<action-to-motion>/model_file\", \"<action-to-motion>/LICENSE\", "
                   "\"refiner/weights/evaluators\")'",
    })
