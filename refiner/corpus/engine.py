"""Refine a corpus of shards on Ray Data: read each shard into clips, refine them on a pool of workers, write back.

The pipeline is ``from_items(shards) -> flat_map(read one shard into rows, one per clip) -> map_batches(ClipRefiner)``
and the driver (the process that calls :func:`refine_corpus`) gathers each shard's clips and writes its output and
report (:mod:`refiner.corpus.shards`) as soon as the last one arrives. Ray is imported only when a run starts.
"""
from __future__ import annotations

import copy
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from refiner.corpus.shards import find_shards, is_complete, write_failure, write_shard

__all__ = ["refine_corpus", "CorpusSummary", "ClipRefiner", "require_ray", "INSTALL_HINT"]

INSTALL_HINT = "pip install 'motion-refiner[ray]' (in a checkout: pip install -e '.[ray]')"


def require_ray():
    """The ``ray`` module; ``ImportError`` saying how to install it where it is missing."""
    try:
        import ray
        import ray.data  # noqa: F401 -- ray without its data extra has no ray.data
    except ImportError as e:
        raise ImportError(f"corpus refinement runs on Ray Data, which is not installed ({e}); {INSTALL_HINT}.") from e
    return ray


@dataclass
class CorpusSummary:
    """What one :func:`refine_corpus` run did; ``seconds`` is wall time from the pipeline's start (Ray running)."""

    shards: int
    refined: int = 0
    skipped: int = 0
    failed: dict = field(default_factory=dict)
    clips: int = 0
    frames: int = 0
    frames_changed: int = 0
    seconds: float = 0.0

    @property
    def clips_per_s(self) -> float:
        return self.clips / self.seconds if self.seconds > 0 else 0.0

    def to_dict(self) -> dict:
        return {**asdict(self), "clips_per_s": self.clips_per_s}


class ClipRefiner:
    """The ``map_batches`` class: loads the refiner once per worker and refines a batch of clip rows.

    Each clip goes through :func:`refiner.refine` with this worker's :class:`MotionRefiner`, so its output equals
    ``refine()`` on that clip. ``stack``: refine the batch's clips of equal length in one call instead (faster,
    most of all on a GPU; equal to the per-clip result up to float rounding in the network). On a worker given a GPU
    the network runs there (equal to the CPU's result up to float rounding).
    """

    def __init__(self, skeleton: str = "humanact12", weights=None, stack: bool = False):
        import torch

        from refiner.refinement.motion_refiner import MotionRefiner

        self.stack = stack
        self.refiner = MotionRefiner.pretrained(skeleton, weights=weights)
        if torch.cuda.is_available() and require_ray().get_gpu_ids():  # a GPU Ray gave this worker
            self.refiner = _on_gpu(self.refiner, torch.device("cuda"))

    def __call__(self, batch: dict) -> dict:
        from refiner import refine
        from refiner.core.motion import Motion

        n = len(batch["shard"])
        joints, reports = list(batch["joints"]), [""] * n
        errors = [str(e) for e in batch["error"]]
        todo = [i for i in range(n) if not errors[i]]
        groups = _by_length(todo, joints) if self.stack else [[i] for i in todo]
        for group in groups:
            try:
                if self.stack:
                    acts = [None if batch["action"][i] < 0 else int(batch["action"][i]) for i in group]
                    outs, reps = refine(np.stack([joints[i] for i in group]), self.refiner.skeleton, action=acts,
                                        refiner=self.refiner, return_report=True)
                else:
                    i = group[0]
                    act = None if batch["action"][i] < 0 else int(batch["action"][i])
                    motion = Motion(joints[i], skeleton=str(batch["skeleton"][i]), fps=float(batch["fps"][i]), action=act)
                    out, rep = refine(motion, self.refiner.skeleton, refiner=self.refiner, return_report=True)
                    outs, reps = [out.joints], [rep]
            except ValueError as e:  # a clip the refiner refuses fails its shard, not the run
                for i in group:
                    errors[i] = f"clip {int(batch['index'][i])} of {int(batch['clips'][i])}: {e}"
                continue
            for i, out, rep in zip(group, outs, reps):
                joints[i] = np.asarray(out, np.float32)
                reports[i] = json.dumps({**rep.to_dict(), "frames_changed": int(rep.changed_frames.sum())})
        return {**{k: batch[k] for k in ("shard", "index", "clips", "batched")}, "joints": _column(joints),
                "report": np.array(reports, dtype=object), "error": np.array(errors, dtype=object)}


def corpus_settings(*, adapter: str | None = None, options: dict | None = None, skeleton: str = "humanact12",
                    fps: float = 20.0, weights=None, stack: bool = False) -> dict:
    """What a shard is refined with, as its report stores it (:func:`refine_corpus`'s arguments of the same names):
    a rerun with other settings redoes the shard."""
    given = {"adapter": adapter, "options": options or {}, "skeleton": skeleton, "fps": fps,
             "weights": None if weights is None else str(weights), "stack": stack}
    return json.loads(json.dumps(given, sort_keys=True, default=str))


def refine_corpus(source, out, *, address: str | None = None, workers: int = 1, gpus_per_worker: float = 0.0,
                  batch_size: int = 16, stack: bool = False, adapter: str | None = None, options: dict | None = None,
                  skeleton: str = "humanact12", fps: float = 20.0, weights=None) -> CorpusSummary:
    """Refine every shard of ``source`` with the default refiner on Ray Data; resumable.

    Parameters
    ----------
    source : path or str
        A folder of ``.npy``/``.npz`` shards or a glob pattern; each shard holds joints ``(T, J, 3)`` /
        ``(N, T, J, 3)`` (metres, the skeleton's frame), or a generator's raw output read through ``adapter``
        (:func:`refiner.cli.refine.load_input`). On a cluster it must be readable at this path on every node.
    out : path
        Folder on this machine: ``<stem>.npy`` (``.npz`` for clips of different lengths) and ``<stem>.report.jsonl``
        per shard (:mod:`refiner.corpus.shards`). Shards already complete there are skipped.
    address : str, optional
        Ray cluster to join (``"auto"``: the one ``ray start`` runs here); default: the running one, else a local one.
    workers : int, default=1
        Refining workers (Ray actors), one CPU each.
    gpus_per_worker : float, default=0.0
        GPUs reserved per worker; a worker given one runs the network there.
    batch_size : int, default=16
        Clips per ``map_batches`` batch (they come from any shards).
    stack : bool, default=False
        See :class:`ClipRefiner`.
    adapter, options, skeleton, fps
        As for ``motion-refiner refine``.
    weights : path, optional
        A folder holding ``<skeleton>-motion/``, looked in before the shipped weights.

    Returns
    -------
    CorpusSummary
        A shard that cannot be read or refined is in ``failed`` with its error (its report says so too); the
        others are written all the same.
    """
    if workers < 1 or batch_size < 1 or gpus_per_worker < 0:
        raise ValueError(f"`workers` and `batch_size` must be at least 1 and `gpus_per_worker` at least 0; got "
                         f"{workers}, {batch_size}, {gpus_per_worker}.")
    shards = find_shards(source)
    out = Path(out)
    if any(out.resolve() == s.parent.resolve() for s in shards):
        raise ValueError(f"`out` {str(out)!r} holds input shards; choose another folder.")
    ray = require_ray()
    out.mkdir(parents=True, exist_ok=True)
    reader = {"adapter": adapter, "options": options or {}, "skeleton": skeleton, "fps": fps}
    worker = {"skeleton": skeleton, "weights": None if weights is None else str(weights), "stack": stack}
    settings = corpus_settings(**reader, weights=weights, stack=stack)
    todo = [s for s in shards if not is_complete(s, out, settings)]
    summary = CorpusSummary(shards=len(shards), skipped=len(shards) - len(todo))
    if not todo:
        return summary
    started = not ray.is_initialized()
    if started:
        ray.init(address=address, include_dashboard=False)
    try:
        t0 = time.perf_counter()
        _run(ray, todo, out, summary, workers=workers, gpus=gpus_per_worker, batch_size=batch_size, reader=reader,
             worker=worker, settings=settings)
        summary.seconds = time.perf_counter() - t0
    finally:
        if started:
            ray.shutdown()
    return summary


def _run(ray, todo: list[Path], out: Path, summary: CorpusSummary, *, workers, gpus, batch_size, reader, worker,
         settings):
    """Build the pipeline and write each shard as its last clip arrives."""
    items = [{"shard": str(s)} for s in todo]
    ds = ray.data.from_items(items, override_num_blocks=len(items))
    # readers take no CPU slot (with every slot held by a worker, one that needed a slot would wait forever) and
    # are as many as the workers, so that a few processes import the package once, not one per shard
    ds = ds.flat_map(_read_shard, fn_kwargs=reader, num_cpus=0, compute=ray.data.TaskPoolStrategy(size=workers))
    ds = ds.map_batches(ClipRefiner, fn_constructor_kwargs=worker, batch_size=batch_size, batch_format="numpy",
                        compute=ray.data.ActorPoolStrategy(size=workers), num_cpus=1, num_gpus=gpus)
    pending, closed = {}, set()
    for batch in ds.iter_batches(batch_size=None, batch_format="numpy"):
        for i in range(len(batch["shard"])):
            shard = str(batch["shard"][i])
            if shard in closed:
                continue
            if batch["error"][i]:
                _close(shard, out, summary, closed, pending, settings, error=str(batch["error"][i]))
                continue
            entry = pending.setdefault(shard, {"n": int(batch["clips"][i]), "batched": bool(batch["batched"][i]), "clips": {}})
            entry["clips"][int(batch["index"][i])] = (np.asarray(batch["joints"][i]), json.loads(batch["report"][i]))
            if len(entry["clips"]) == entry["n"]:
                _close(shard, out, summary, closed, pending, settings)
    for shard in map(str, todo):
        if shard not in closed:  # every clip row comes back unless the pipeline lost one
            _close(shard, out, summary, closed, pending, settings, error="not every clip came back from the workers")


def _close(shard: str, out: Path, summary: CorpusSummary, closed: set, pending: dict, settings: dict, *,
           error: str | None = None):
    """Write ``shard``'s output and report (or its failure) and count it."""
    closed.add(shard)
    entry = pending.pop(shard, None)
    if error is None:
        clips = [entry["clips"][i] for i in range(entry["n"])]
        try:
            closing = write_shard(Path(shard), out, [c[0] for c in clips], entry["batched"], [c[1] for c in clips],
                                  settings)
        except OSError as e:
            error = f"could not write its output: {e}"
        else:
            summary.refined += 1
            summary.clips += closing["clips"]
            summary.frames += closing["frames"]
            summary.frames_changed += closing["frames_changed"]
            return
    write_failure(Path(shard), out, error)
    summary.failed[shard] = error


def _read_shard(row: dict, *, adapter, options, skeleton, fps) -> list[dict]:
    """One shard as rows, one per clip; a shard that cannot be read is one row carrying the error."""
    from refiner.cli.refine import load_input

    shard = str(row["shard"])
    try:
        motions, batched = load_input(shard, adapter=adapter, skeleton=skeleton, options=options, fps=fps)
        if not motions:
            raise ValueError("it holds no clips")
    except Exception as e:  # noqa: BLE001 -- whatever breaks one shard is that shard's failure, reported
        return [{"shard": shard, "index": 0, "clips": 0, "batched": False, "joints": np.zeros((0, 1, 3), np.float32),
                 "action": -1, "fps": 0.0, "skeleton": "", "error": f"{type(e).__name__}: {e}"}]
    return [{"shard": shard, "index": i, "clips": len(motions), "batched": batched, "joints": m.joints,
             "action": -1 if m.action is None else int(m.action), "fps": float(m.fps), "skeleton": m.skeleton,
             "error": ""} for i, m in enumerate(motions)]


def _by_length(rows: list[int], joints: list) -> list[list[int]]:
    """``rows`` grouped by their clips' frame count."""
    groups: dict[int, list[int]] = {}
    for i in rows:
        groups.setdefault(len(joints[i]), []).append(i)
    return list(groups.values())


def _column(arrays: list) -> np.ndarray:
    """A column of arrays that may differ in shape (a 1-D object array; numpy would try to stack them)."""
    col = np.empty(len(arrays), dtype=object)
    for i, a in enumerate(arrays):
        col[i] = a
    return col


def _on_gpu(refiner, device):
    """A copy of ``refiner`` whose network runs on ``device`` (the cached one stays on the CPU)."""
    from refiner.nn.distributed import OnDevice
    from refiner.refinement.motion_refiner import MotionRefiner

    model = copy.copy(refiner.model)
    model.set_network(OnDevice(copy.deepcopy(refiner.model.network_).to(device), device), refiner.model.training_)
    return MotionRefiner(model, refiner.config, skeleton=refiner.skeleton, threads=refiner.threads)
