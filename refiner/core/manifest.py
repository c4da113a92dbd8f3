"""Weights manifests (``manifest.json``): schema checks, file hashes and a sha256 over the manifest's content.

Every weights folder (a saved :class:`~refiner.Refiner`, the reference generators) has a
``manifest.json`` that lists its files with their sha256 and carries what the weights alone do not:
the action names in label order, the calibrated thresholds, the provenance. ``content_sha256`` is the
sha256 of the rest of the manifest (canonical JSON: sorted keys, no spaces), so reordered action names
or an edited threshold are detected on load just like a replaced weight file.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import re
from collections.abc import Iterable, Mapping
from pathlib import Path

__all__ = [
    "CONTENT_KEY",
    "content_sha256",
    "file_sha256",
    "read_evaluator_manifest",
    "read_generator_manifest",
    "read_refiner_manifest",
    "refiner_weight_sets",
    "weight_set_folders",
    "write_manifest",
]

CONTENT_KEY = "content_sha256"
_HEX64 = re.compile(r"[0-9a-f]{64}")


def file_sha256(path: str | os.PathLike) -> str:
    """The hex sha256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def content_sha256(manifest: Mapping) -> str:
    """The hex sha256 of ``manifest`` without its ``content_sha256`` entry, as canonical JSON."""
    body = {k: v for k, v in manifest.items() if k != CONTENT_KEY}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def write_manifest(path: str | os.PathLike, manifest: Mapping) -> dict:
    """Write ``manifest`` as indented JSON with its ``content_sha256``; returns what was written."""
    written = json.loads(json.dumps({k: v for k, v in manifest.items() if k != CONTENT_KEY}))
    written[CONTENT_KEY] = content_sha256(written)
    Path(path).write_text(json.dumps(written, indent=2) + "\n")
    return written


def read_refiner_manifest(folder: str | os.PathLike, parts: Iterable[str], *, verify: bool = True
                          ) -> tuple[dict, dict[str, Path]]:
    """The manifest of a saved refiner and the path of each part it lists.

    Parameters
    ----------
    folder : path
        The folder holding ``manifest.json`` and the ``.safetensors`` files.
    parts : iterable of str
        The part names a refiner has (``files`` may list a subset, nothing else).
    verify : bool, default=True
        Check ``content_sha256`` and every file's sha256.

    Returns
    -------
    manifest : dict
    paths : dict of str to Path

    Raises
    ------
    ValueError
        The manifest is missing, not JSON, lacks a key or has one of a wrong type (``skeleton`` str,
        ``action_names`` list of distinct str, ``files`` dict of ``{"file", "sha256"}``, numeric
        ``calibration``), lists a file that is missing, or its content or a file does not match its
        sha256.
    """
    folder, manifest, where = _read(folder, "no refiner")
    _check_type(manifest, "skeleton", str, where)
    names = _check_type(manifest, "action_names", list, where)
    if not all(isinstance(n, str) for n in names) or len(set(names)) != len(names):
        raise ValueError(f"{where}: `action_names` must be a list of distinct strings; got {names!r}.")
    calibration = manifest.get("calibration", {})
    if not isinstance(calibration, dict):
        raise ValueError(f"{where}: `calibration` must be a dict; got {type(calibration).__name__}.")
    for key in ("anchor_threshold", "transition_threshold"):
        if key in calibration and not _is_number(calibration[key]):
            raise ValueError(f"{where}: `calibration.{key}` must be a number; got {calibration[key]!r}.")
    bins = calibration.get("transition_thresholds", [])
    if not isinstance(bins, list) or not all(isinstance(b, list) and len(b) == 2 and all(map(_is_number, b))
                                             for b in bins):
        raise ValueError(f"{where}: `calibration.transition_thresholds` must be a list of [frames, metres] "
                         f"pairs; got {bins!r}.")
    paths = _check_files(manifest, "files", folder, where, known=tuple(parts), verify=verify)
    return manifest, paths


def read_generator_manifest(folder: str | os.PathLike, *, verify: bool = True) -> tuple[dict, dict[str, Path]]:
    """The manifest of a reference-generators folder and the path of each generator it lists.

    Same checks as :func:`read_refiner_manifest` on the ``generators`` entry (kind to
    ``{"file", "sha256", ...}``); raises ``ValueError``.
    """
    folder, manifest, where = _read(folder, "no reference generators")
    return manifest, _check_files(manifest, "generators", folder, where, known=None, verify=verify)


def read_evaluator_manifest(folder: str | os.PathLike, *, verify: bool = True) -> tuple[dict, dict[str, Path]]:
    """The manifest of the packaged-evaluators folder and the path of each recogniser it lists.

    Same checks as :func:`read_generator_manifest` on the ``evaluators`` entry (recogniser name to
    ``{"file", "sha256", ...}``) and on ``documents`` (the licence text); raises ``ValueError``.
    """
    folder, manifest, where = _read(folder, "no packaged evaluators")
    _check_files(manifest, "documents", folder, where, known=None, verify=verify)
    return manifest, _check_files(manifest, "evaluators", folder, where, known=None, verify=verify)


def _read(folder, missing: str) -> tuple[Path, dict, str]:
    """The folder, its parsed manifest (a dict) and the manifest's path for messages."""
    folder = Path(folder)
    path = folder / "manifest.json"
    if not path.is_file():
        raise ValueError(f"{missing} at {str(folder)!r}: manifest.json is missing.")
    try:
        manifest = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{str(path)!r} is not valid JSON: {e}") from e
    if not isinstance(manifest, dict):
        raise ValueError(f"{str(path)!r} must hold a JSON object; got {type(manifest).__name__}.")
    return folder, manifest, repr(str(path))


def _check_files(manifest: dict, key: str, folder: Path, where: str, *, known, verify: bool) -> dict[str, Path]:
    """Validate ``manifest[key]`` (name to file entry), then the content hash and the files' hashes."""
    entries = _check_type(manifest, key, dict, where)
    paths = {}
    for name, entry in entries.items():
        if known is not None and name not in known:
            raise ValueError(f"{where}: `{key}` lists unknown part {name!r}; known: {', '.join(known)}.")
        if not isinstance(entry, dict) or not isinstance(entry.get("file"), str) \
                or not isinstance(entry.get("sha256"), str) or not _HEX64.fullmatch(entry["sha256"]):
            raise ValueError(f"{where}: `{key}.{name}` must be {{\"file\": name, \"sha256\": 64 hex digits}}; "
                             f"got {entry!r}.")
        if Path(entry["file"]).name != entry["file"]:
            raise ValueError(f"{where}: `{key}.{name}.file` must be a file name in the folder; got {entry['file']!r}.")
        paths[name] = folder / entry["file"]
        if not paths[name].is_file():
            raise ValueError(f"{str(paths[name])!r} is listed in {where} but missing; reinstall or retrain the weights.")
    if verify:
        if manifest.get(CONTENT_KEY) != content_sha256(manifest):
            raise ValueError(f"{where}: its content does not match its `{CONTENT_KEY}` "
                             f"({'missing' if CONTENT_KEY not in manifest else 'edited'}): action names, "
                             "thresholds or file list were changed after the weights were saved.")
        for name, path in paths.items():
            if file_sha256(path) != entries[name]["sha256"]:
                raise ValueError(f"{str(path)!r} does not match the sha256 in {where}; "
                                 "the weights are corrupt or were replaced.")
    return paths


def _check_type(manifest: dict, key: str, kind: type, where: str):
    """``manifest[key]``, which must exist and be a ``kind``."""
    if key not in manifest:
        raise ValueError(f"{where} has no `{key}` entry.")
    if not isinstance(manifest[key], kind):
        raise ValueError(f"{where}: `{key}` must be a {kind.__name__}; got {type(manifest[key]).__name__}.")
    return manifest[key]


def _is_number(x) -> bool:
    """A JSON number that is not NaN (infinity allowed: an open upper bin)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and not math.isnan(x)


def weight_set_folders(name: str, roots) -> list[Path]:
    """The folders ``root/name`` then ``root/name-train`` that hold a manifest, for each of ``roots`` in turn within each
    name (a user's folder of weight sets before the shipped one; a skeleton that ships a train split only falls back)."""
    return [Path(root) / n for n in (name, f"{name}-train") for root in roots if (Path(root) / n / "manifest.json").is_file()]


def refiner_weight_sets(weights: str | os.PathLike) -> list[dict]:
    """The refiner weight sets in the folder ``weights``: ``folder``, ``skeleton``, ``split``, ``dataset``,
    ``licence`` and ``parts`` of each, from its manifest (``Refiner.shipped()`` lists the package's)."""
    out = []
    root = Path(weights)
    for folder in sorted(p for p in root.iterdir() if (p / "manifest.json").is_file()) if root.is_dir() else []:
        manifest = json.loads((folder / "manifest.json").read_text())
        if "action_names" not in manifest:  # evaluator and generator weights have manifests of another kind
            continue
        out.append({"folder": folder.name, "skeleton": manifest["skeleton"], "split": manifest.get("split", "all"),
                    "dataset": manifest.get("dataset"), "licence": manifest.get("licence"),
                    "parts": sorted(manifest.get("files", {}))})
    return out
