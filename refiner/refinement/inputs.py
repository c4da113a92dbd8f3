"""What ``refine()`` checks in its input and options, and the threads it runs with."""
from __future__ import annotations

import numbers
import os
from contextlib import contextmanager
from functools import lru_cache

import numpy as np
import torch
from threadpoolctl import ThreadpoolController

__all__ = ["MODES", "METHODS", "RIGID_LENGTHS", "RETIMING", "DENOISING", "AMPLITUDE", "POSING", "TEXTURE", "GENERATOR_OPTIONS", "MIN_FRAMES", "AUTO_THREADS_BATCH", "auto_threads", "check_choice", "check_choices", "check_flag", "check_metres",
           "check_metres_each", "check_threads", "thread_limits"]

#: Which refinement steps run after recognition.
MODES = ("full", "anchor", "transition")
#: ``"learned"``: flaw recognition + repair networks; ``"concepts"``: anchor scores and transition residuals.
METHODS = ("learned", "concepts")
#: Lengths of the rigid skeleton: the clip's medians drawn toward learned proportions, or the medians.
RIGID_LENGTHS = ("proportions", "median")
#: Timing flaws: the estimator's runs re-timed first (``"estimated"``); flagged retraces cut and the stalls in runs
#: flagged as timing re-timed (``"flagged"``, and after the estimator); the stalls only (``"stalls"``).
RETIMING = ("estimated", "flagged", "stalls")
#: Noise: flagged runs, noise-group runs, clips noisy throughout (``"filter"``); no noise-group runs (``"throughout"``); flagged runs only.
DENOISING = ("runs", "filter", "throughout", "flagged")
#: Clips that move too little for their action: scaled back (``"restore"``, for a generator's clips) or kept (``"keep"``).
AMPLITUDE = ("restore", "keep")
#: Poses off real motion: corrected by the pose prior (``"prior"``) or kept (``"keep"``).
POSING = ("prior", "keep")
#: Clips the texture filter runs on: those the noise step finds noisy throughout (``"auto"``), every clip
#: (``"all"``: the clips are a generator's), none (``"off"``).
TEXTURE = ("auto", "all", "off")
#: Refiner options for a generator's clips, as :class:`~refiner.refinement.refined_generator.RefinedGenerator`,
#: ``motion-refiner refine --adapter`` and the benchmarks of generator output refine them: every clip through the
#: texture filter, a damped clip's motion scaled back to its action's spread, and a clip that reads as another action
#: than the one it was generated for snapped onto its action's anchor concepts (all off for ``refine()``, which may be
#: given mocap: the amplitude step scaled a calm held-out clip of subjects 11-12 by 3.5, 3.1 cm); and every run the
#: timing estimator finds re-timed, without the flaw classifier's agreement (600 samples of each reference generator,
#: against 0.8: FID actor 4.069 -> 3.844, mdm 1.151 -> 1.139, actor-large 0.979 -> 0.973, a2m 3.033 -> 3.065, a2m-large
#: 0.901 -> 0.903); and a clip noisy throughout denoised as a whole (``denoising="filter"``; ``refine()``'s ``"runs"``
#: leaves that step out: it cost jittered mocap its runs' repair).
GENERATOR_OPTIONS = {"texture": "all", "amplitude": "restore", "misread_snap": 1.0, "timing_agreement": None, "denoising": "filter"}
#: Shortest clip refined; shorter ones pass through unchanged (reported).
MIN_FRAMES = 8
#: ``threads="auto"`` uses more than one thread from this many clips in a batch on (2-core CPU: a 60-frame clip took
#: 12 ms on one thread, 113 ms on two; a batch of 256 went at 515 and 742 clips/s).
AUTO_THREADS_BATCH = 32


def check_choice(name: str, value: str, choices) -> str:
    """``value`` if it is one of ``choices``, else a ``ValueError`` naming the option and the choices."""
    if value not in choices:
        raise ValueError(f"unknown {name} {value!r}; known: {', '.join(choices)}.")
    return value


def check_flag(name: str, value) -> bool:
    """``value`` as a bool if it is one (numpy's too), else a ``ValueError`` naming the option."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"`{name}` must be True or False; got {value!r}.")
    return bool(value)


def check_choices(name: str, values, choices) -> frozenset:
    """``values`` (a collection of names, or one name) as a frozenset, each one of ``choices``; else a
    ``ValueError`` naming the option, what was wrong and the choices."""
    if isinstance(values, str):
        values = (values,)
    if not isinstance(values, (tuple, list, set, frozenset)) or any(v not in choices for v in values):
        raise ValueError(f"`{name}` must name some of {', '.join(choices)}; got {values!r}.")
    return frozenset(values)


def check_threads(threads):
    """A positive int, ``"auto"`` or None (``ValueError`` otherwise); numpy integers become ints."""
    if not (threads is None or (isinstance(threads, str) and threads == "auto")
            or (isinstance(threads, numbers.Integral) and not isinstance(threads, (bool, np.bool_)) and threads >= 1)):
        raise ValueError(f"`threads` must be a positive int, 'auto' or None; got {threads!r}.")
    return threads if threads is None or isinstance(threads, str) else int(threads)


def auto_threads(seq) -> int:
    """One thread for a clip or a small batch, the available cores (at most 4) for a large one."""
    shape = getattr(seq, "shape", None)
    if shape is None and isinstance(seq, (list, tuple)):
        shape = np.shape(seq)
    if shape is None or len(shape) != 4 or shape[0] < AUTO_THREADS_BATCH:
        return 1
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(4, cores))


@lru_cache(maxsize=1)
def _blas_controller() -> ThreadpoolController:
    """The BLAS / OpenMP libraries loaded when ``refine`` is first called (numpy, scipy and torch are
    imported by then). Finding them takes about 1.7 ms, a third of a 60-frame clip's refinement, so it is
    done once and the limits are set through it on every call."""
    return ThreadpoolController()


@contextmanager
def thread_limits(threads: int | None):
    """torch intra-op and BLAS threads set to ``threads`` inside the block, restored after (None: untouched)."""
    if threads is None:
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        with _blas_controller().limit(limits=threads):  # under load, free BLAS threads made a call 3-12x slower
            yield
    finally:
        torch.set_num_threads(before)


def check_metres_each(clips: np.ndarray, skel, batched: bool) -> None:
    """:func:`check_metres` per clip of ``clips (B, T, J, 3)`` (one clip in centimetres must not hide in a
    batch's median), naming the clip when the input was a batch. Judged for the whole batch at once (a
    loop over 256 clips took a tenth of refining them); the first clip refused is checked again alone for
    its message."""
    extent, median = _metres_evidence(clips, skel)
    for i in np.flatnonzero((extent > _MAX_EXTENT) | (median > _MAX_MEDIAN_BONE))[:1]:
        try:
            check_metres(clips[i], skel)
        except ValueError as e:
            if not batched:
                raise
            raise ValueError(f"clip {i} of {len(clips)}: {e}") from e


#: Coordinates and median bone length (in the joints' units) beyond which joints cannot be metres.
_MAX_EXTENT, _MAX_MEDIAN_BONE = 1e3, 1.5
#: Frames whose bones judge the unit: 16 spread over the clip (a unit is the same on every frame).
_UNIT_FRAMES = 16


def _metres_evidence(clips: np.ndarray, skel) -> tuple[np.ndarray, np.ndarray]:
    """Per clip of ``(B, T, J, 3)``: the largest |coordinate| and the median bone length over
    :data:`_UNIT_FRAMES` frames, each ``(B,)``."""
    step = max(1, clips.shape[1] // _UNIT_FRAMES)
    extent = np.abs(clips).reshape(len(clips), -1).max(1)
    return extent, np.median(skel.bone_lengths(clips[:, ::step]).reshape(len(clips), -1), axis=1)


def check_metres(x: np.ndarray, skel) -> None:
    """Refuse joints ``(T, J, 3)`` that cannot be metres: huge values, or bones metres long (centimetres given)."""
    extent, median = (float(v[0]) for v in _metres_evidence(np.asarray(x)[None], skel))
    if extent > _MAX_EXTENT:
        raise ValueError(f"`seq` has coordinates up to {extent:.3g}; joints must be in metres (|x| < 1000).")
    if median > _MAX_MEDIAN_BONE:
        raise ValueError(f"`seq` has bones of {median:.3g} units median length; joints must be in metres "
                         "(centimetres: divide by 100).")
