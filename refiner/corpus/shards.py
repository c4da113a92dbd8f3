"""The files of a corpus run: which shards there are, where each one's outputs go, and whether they are complete.

Every input shard ``<stem>.npy|.npz`` gives ``OUT/<stem>.npy`` (``.npz`` when its clips differ in length; the same
layout as ``motion-refiner refine`` writes joints in: always joints, never an adapter's own format such as MDM's
``results.npy``) and ``OUT/<stem>.report.jsonl``: one line per clip (its refinement report)
and a last line that closes the shard (``"status": "done"`` with the output's sha256, or ``"failed"`` with the
error). Both are written under a temporary name and renamed (``os.replace``), the output first: a shard is
complete when its report's last line says ``done``, the output it names has that sha256 and the shard itself still
has the ``input_sha256`` it was refined from (a shard regenerated, or another folder's shard of the same name, is
redone), so a run killed at any point leaves shards that are either complete or redone by the next run. Nothing
here imports Ray.
"""
from __future__ import annotations

import glob
import hashlib
import json
import os
from pathlib import Path

import numpy as np

__all__ = ["find_shards", "report_path", "is_complete", "write_shard", "write_failure", "SUFFIXES"]

SUFFIXES = (".npy", ".npz")


def find_shards(source) -> list[Path]:
    """The ``.npy``/``.npz`` shards of ``source`` (a folder, or a glob pattern such as ``runs/*/samples_*.npy``),
    sorted; ``ValueError`` when there are none or two would be written to the same output (same stem)."""
    source = str(source)
    if Path(source).is_dir():
        found = [p for p in Path(source).iterdir() if p.is_file() and p.suffix.lower() in SUFFIXES]
    elif glob.has_magic(source):
        found = [Path(p) for p in glob.glob(source, recursive=True)
                 if Path(p).is_file() and Path(p).suffix.lower() in SUFFIXES]
    elif Path(source).is_file() and Path(source).suffix.lower() in SUFFIXES:
        found = [Path(source)]
    else:
        raise ValueError(f"IN must be a folder, a glob pattern or a .npy/.npz file; {source!r} is none of them.")
    if not found:
        raise ValueError(f"no .npy or .npz shards in {source!r}.")
    found = sorted(found)
    stems: dict[str, list[Path]] = {}
    for p in found:
        stems.setdefault(p.stem, []).append(p)
    clashes = {s: ps for s, ps in stems.items() if len(ps) > 1}
    if clashes:  # refused before anything is written: the second shard would overwrite the first's output
        shown = "; ".join(", ".join(map(str, ps)) for ps in clashes.values())
        raise ValueError(f"these shards would be written to the same output (same file name): {shown}; rename them.")
    return found


def report_path(shard: Path, out: Path) -> Path:
    """``OUT/<stem>.report.jsonl`` of ``shard``."""
    return Path(out) / f"{Path(shard).stem}.report.jsonl"


def is_complete(shard: Path, out: Path, settings: dict | None = None) -> bool:
    """Whether ``shard``'s report closes with ``done``, its output is there with the sha256 the report names,
    ``shard`` is the file it was refined from (same sha256) and it was refined with these ``settings``."""
    report = report_path(shard, out)
    try:
        last = json.loads(report.read_text().rstrip("\n").rsplit("\n", 1)[-1])
        output = Path(out) / last["output"]
        return (last.get("status") == "done" and _sha256(output) == last["sha256"]
                and _sha256(Path(shard)) == last["input_sha256"] and last.get("settings") == settings)
    except (OSError, ValueError, KeyError, TypeError):  # missing, half-written or foreign: redo the shard
        return False


def write_shard(shard: Path, out: Path, refined: list[np.ndarray], batched: bool, reports: list[dict],
                settings: dict | None = None) -> dict:
    """Write ``shard``'s refined clips (each ``(T, J, 3)`` float32 metres) and its report; returns the closing line.

    ``batched``: the shard held ``(N, T, J, 3)`` (written back so); clips of different lengths go to an ``.npz``
    (``clip_000``, ...), as ``motion-refiner refine`` writes them. ``reports``: each clip's report dict with its
    ``n_frames`` and ``frames_changed``. ``settings``: what it was refined with (a rerun with others redoes it).
    """
    out = Path(out)
    ragged = len({len(c) for c in refined}) > 1
    target = out / (Path(shard).stem + (".npz" if ragged else ".npy"))
    tmp = out / f".{target.name}.tmp"
    with open(tmp, "wb") as f:  # a file object: np.save would otherwise append .npy to the temporary name
        if ragged:
            np.savez(f, **{f"clip_{i:03d}": c for i, c in enumerate(refined)})
        else:
            stacked = np.stack(refined)
            np.save(f, stacked if batched else stacked[0])
    os.replace(tmp, target)
    closing = {"shard": str(shard), "output": target.name, "status": "done", "clips": len(refined),
               "frames": int(sum(r["n_frames"] for r in reports)),
               "frames_changed": int(sum(r["frames_changed"] for r in reports)), "sha256": _sha256(target),
               "input_sha256": _sha256(Path(shard)), "settings": settings}
    _write_lines(report_path(shard, out), [{"clip": i, **r} for i, r in enumerate(reports)] + [closing])
    return closing


def write_failure(shard: Path, out: Path, error: str) -> dict:
    """Write ``shard``'s report as one ``failed`` line with ``error``; an earlier output stays (it is not complete)."""
    closing = {"shard": str(shard), "status": "failed", "error": error}
    _write_lines(report_path(shard, out), [closing])
    return closing


def _write_lines(path: Path, records: list[dict]) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text("".join(json.dumps(r) + "\n" for r in records))
    os.replace(tmp, path)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
