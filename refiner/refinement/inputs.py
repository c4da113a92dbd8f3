"""What ``refine()`` checks in its input and options, and the threads it runs with."""
from __future__ import annotations

import numbers
import os
from contextlib import contextmanager
from functools import lru_cache

import numpy as np
import torch
from threadpoolctl import ThreadpoolController

__all__ = ["MODES", "METHODS", "MIN_FRAMES", "AUTO_THREADS_BATCH", "auto_threads", "check_choice", "check_choices",
           "check_metres", "check_metres_each", "check_threads", "thread_limits"]

#: Which steps of the concepts method run after recognition (the motion method has one mode, "full").
MODES = ("full", "anchor", "transition")
#: ``"motion"`` (the default): one learned model of motion, :class:`~refiner.refinement.motion_refiner.MotionRefiner`;
#: ``"concepts"``: the paper's anchor scores and transition residuals, :class:`~refiner.refinement.pipeline.Refiner`.
METHODS = ("motion", "concepts")
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
