"""``motion-refiner bench corpus``: clips per second of corpus refinement, as a user runs it, on one corpus.

The corpus is the 60-frame pieces of the HumanAct12 clips that start every 20 frames, in shards of 64 (``quick``: 32
pieces, shards of 16).
Each row runs one command in a fresh process and times it from start to exit: ``motion-refiner refine DIR`` (one
process, clip by clip), ``motion-refiner refine-corpus DIR`` with 1 and 2 Ray workers (a local Ray started by the
command; ``pipeline_s`` is the time from the pipeline's start, Ray running, as the command's summary gives it), the
same with ``--stack``, and, where CUDA is available, one GPU worker. Rows that need Ray are left out, with a note,
where the optional extra is not installed. ``corpus.json``: ``clips``, ``shards``, ``frames``, ``cpus``, ``rows``
(per row: ``name``, ``command``, ``wall_s``, ``pipeline_s`` (Ray rows), ``clips_per_s`` (over ``wall_s``),
``pipeline_clips_per_s``) and ``notes``.
"""
from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from refiner.evaluation.bench_setup import Progress, ignore_progress, load_bench_humanact12, write_record

__all__ = ["bench_corpus"]

_SHARD, _QUICK_SHARD = 64, 16


def bench_corpus(data: Path | None, out: Path | None, quick: bool, *, weights: Path | None = None,
                 progress: Progress | None = None) -> dict:
    """Time ``refine DIR`` and ``refine-corpus`` (1 and 2 Ray workers, stacked, GPU) on one corpus; progress event
    ``"row"`` per row measured."""
    progress = progress or ignore_progress
    clips = [m.joints[s:s + 60] for m in load_bench_humanact12(data) for s in range(0, m.n_frames - 59, 20)]
    shard = _QUICK_SHARD if quick else _SHARD
    clips = clips[:32] if quick else clips[: len(clips) // shard * shard]
    extra = [] if weights is None else ["--weights", str(weights)]
    ray_cmd = ["refine-corpus", "IN", "-o", "OUT", *extra]
    rows = [("refine DIR", ["refine", "IN", "-o", "OUT", *extra]),
            ("Ray, 1 worker", [*ray_cmd, "--workers", "1"]),
            ("Ray, 2 workers", [*ray_cmd, "--workers", "2"]),
            ("Ray, 2 workers, --stack", [*ray_cmd, "--workers", "2", "--stack"])]
    notes = []
    if _cuda():
        rows.append(("Ray, 1 GPU worker, --stack", [*ray_cmd, "--workers", "1", "--gpus-per-worker", "1", "--stack"]))
    if importlib.util.find_spec("ray") is None:
        rows = rows[:1]
        notes.append("Ray rows not measured: the optional extra is not installed (pip install -e '.[ray]').")
    rec = {"clips": len(clips), "shards": len(clips) // shard,
           "frames": int(sum(len(c) for c in clips)), "cpus": os.cpu_count(), "rows": [], "notes": notes}
    with tempfile.TemporaryDirectory() as tmp:
        corpus = Path(tmp) / "corpus"
        corpus.mkdir()
        for i in range(0, len(clips), shard):
            np.save(corpus / f"shard_{i // shard:03d}.npy", np.stack(clips[i:i + shard]))
        for k, (name, args) in enumerate(rows):
            target = Path(tmp) / f"out_{k}"
            command = [str(corpus) if a == "IN" else str(target) if a == "OUT" else a for a in args]
            rec["rows"].append(_timed(name, command, target, len(clips)))
            progress("row", rec["rows"][-1])
    return write_record(out, "corpus", rec)


def _timed(name: str, command: list, target: Path, n_clips: int) -> dict:
    """Run ``motion-refiner COMMAND`` in a fresh process; its wall time and, for a corpus run, its summary's."""
    t0 = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "refiner", *command], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if run.returncode != 0:
        raise ValueError(f"bench corpus: `motion-refiner {' '.join(command)}` failed:\n{run.stderr[-2000:]}")
    row = {"name": name, "command": "motion-refiner " + " ".join(command[:1] + ["IN", "-o", "OUT"] + command[4:]),
           "wall_s": wall, "clips_per_s": n_clips / wall}
    summary = target / "summary.json"
    if summary.is_file():
        s = json.loads(summary.read_text())
        row.update(pipeline_s=s["seconds"], pipeline_clips_per_s=s["clips_per_s"])
    return row


def _cuda() -> bool:
    import torch  # here, not at the top: see bench_refiner

    return torch.cuda.is_available()
