"""Where the data that is not shipped lives, where it comes from, and the "not found" message for each.

The package ships its weights (refiner, reference generators, the HumanAct12 recogniser), so the demo
and the Quickstart need nothing else. The datasets, the other Action2Motion recognisers and the real
Action2Motion samples are not shipped (licences, size); they are looked up under one data folder,
``$MOTION_REFINER_DATA`` (see :func:`refiner.io.datasets.default_data_dir`):

- ``$MOTION_REFINER_DATA/humanact12/humanact12_joints.npz``
- ``$MOTION_REFINER_DATA/cmu_mocap/cmu_mocap_labeled_joints.npz``
- ``$MOTION_REFINER_DATA/../evaluators/<recogniser>.safetensors`` (or the original ``.tar``)
- ``$MOTION_REFINER_DATA/../samples/action2motion/humanact12_xyz_vae_samples.npy``

Every loader that misses one of them raises a ``ValueError`` built by :func:`missing_message`, which
names the environment variable, the expected file names and where the data come from.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

__all__ = ["DATA_ENV", "DataSource", "SOURCES", "source_folder", "missing_message", "data_status"]

#: The environment variable naming the data folder (the one holding ``humanact12/`` and ``cmu_mocap/``).
DATA_ENV = "MOTION_REFINER_DATA"

_A2M_DATA = "https://ericguo5513.github.io/action-to-motion/#data"
_A2M_REPO = "https://github.com/EricGuo5513/action-to-motion"


@dataclass(frozen=True)
class DataSource:
    """One kind of data that is looked up under the data folder.

    Attributes
    ----------
    name : str
        Short name (``"humanact12"``, ``"cmu_mocap"``, ``"evaluators"``, ``"samples"``).
    title : str
        What it is, for messages.
    folder : str
        Its folder relative to the data folder (``..`` allowed).
    files : tuple of str
        The files expected there (for the evaluators, the safetensors names; the ``.tar`` originals
        are accepted too).
    origin : str
        Where the data come from (dataset name and URL) and their licence.
    """

    name: str
    title: str
    folder: str
    files: tuple[str, ...]
    origin: str


SOURCES: dict[str, DataSource] = {s.name: s for s in (
    DataSource("humanact12", "HumanAct12 data", "humanact12", ("humanact12_joints.npz",),
               f"HumanAct12 as 3D joints (Action2Motion's release, {_A2M_DATA}; the loader also reads its folder "
               "of <name>.npy clips or ACTOR's humanact12poses.pkl); derived from PHSPD, academic non-commercial "
               "use only"),
    DataSource("cmu_mocap", "CMU-Mocap data", "cmu_mocap", ("cmu_mocap_labeled_joints.npz",),
               f"Action2Motion's labelled CMU-Mocap subset ({_A2M_DATA}), from the CMU Graphics Lab Motion "
               "Capture Database (http://mocap.cs.cmu.edu), free for all uses, no resale"),
    DataSource("evaluators", "Action2Motion recogniser files", os.path.join("..", "evaluators"),
               ("humanact12_gru.safetensors", "humanact12_fine_gru.safetensors", "ntu13_vibe_gru.safetensors",
                "cmu_mocap_gru.safetensors"),
               f"Action2Motion's pretrained action recognisers, model_file/action_recognition_model_*.tar in "
               f"{_A2M_REPO} (MIT); humanact12 ships with the package"),
    DataSource("samples", "real Action2Motion samples", os.path.join("..", "samples", "action2motion"),
               ("humanact12_xyz_vae_samples.npy", "humanact12_xyz_vae_labels.npy"),
               f"20 samples of the released Action2Motion xyz VAE ({_A2M_REPO}, MIT) with their labels"),
)}


def source_folder(name: str, data_dir: str | os.PathLike | None = None) -> Path:
    """The folder of data source ``name`` under ``data_dir`` (default :func:`refiner.io.datasets.default_data_dir`)."""
    if data_dir is None:
        from refiner.io.datasets import default_data_dir  # here: datasets imports this module

        data_dir = default_data_dir()
    return Path(os.path.normpath(Path(data_dir) / SOURCES[name].folder))


def missing_message(name: str, where: str | os.PathLike, files: tuple[str, ...] | None = None) -> str:
    """The "not found" message of data source ``name`` looked for at ``where``.

    Parameters
    ----------
    name : str
        A key of :data:`SOURCES`.
    where : path
        The file or folder that was tried.
    files : tuple of str, optional
        The expected file names, when narrower than the source's.

    Returns
    -------
    str
        Names what is missing, the expected files, ``$MOTION_REFINER_DATA`` and where the data come from.
    """
    source = SOURCES[name]
    expected = " or ".join(files or source.files)
    env = os.environ.get(DATA_ENV)
    env_note = f"${DATA_ENV} is {env!r}" if env else f"${DATA_ENV} is not set"
    return (f"no {source.title} at {str(where)!r}: expected {expected} in <data>/{Path(source.folder).as_posix()}, "
            f"where <data> is ${DATA_ENV} ({env_note}; default ../shared/data beside the working directory). "
            f"Source: {source.origin}. Set ${DATA_ENV} or pass the path explicitly.")


def data_status(data_dir: str | os.PathLike | None = None) -> list[dict]:
    """For each data source: its folder and which of its files are found or missing (for ``doctor``)."""
    rows = []
    for name, source in SOURCES.items():
        folder = source_folder(name, data_dir)
        found = [f for f in source.files if (folder / f).is_file()]
        rows.append({"name": name, "title": source.title, "folder": str(folder), "found": found,
                     "missing": [f for f in source.files if f not in found], "origin": source.origin})
    return rows
