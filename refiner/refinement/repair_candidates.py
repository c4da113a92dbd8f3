"""Candidate repairs of one flagged run of frames, for the learned pipeline's selection step.

Each function takes a clip ``y (T, J, 3)`` metres and a flagged run ``[lo, hi)`` and returns a new
clip in which only those frames differ. They encode what a flaw of each kind needs, so that the
refiner can choose, per run, the candidate that its flaw classifier finds most real:

- :func:`retime_run`: the frames keep their path but are re-timed along it with a speed that
  joins the neighbours' speeds smoothly (stalls, rushes, warped timing);
- :func:`forward_retime_run`: the same along the run's *progress* toward its end pose, so motion
  that goes back and forth is replayed forward only (reversals);
- :func:`smooth_run`: Gaussian smoothing in time (jitter, bursts);
- :func:`spline_run`: a cubic smoothing spline whose smoothness is chosen by generalised
  cross-validation (jitter, bursts: it adapts to the noise it finds);
- :func:`root_infill_run`: the root path is linearly in-filled and the pose kept (the whole body
  floating or gliding);
- :func:`planted_feet_run`: a foot that stays on the ground does not slide: the whole body is
  moved back by the horizontal slip of the planted feet (skating, gliding).

All take ``(y, lo, hi, skeleton)``; ``skeleton`` is a :class:`~refiner.core.skeletons.Skeleton`.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import make_smoothing_spline
from scipy.ndimage import gaussian_filter1d, label

from refiner.concepts.transitions import arc_length_profile
from refiner.core.contact import contact_joints, glide_steps, heights
from refiner.core.skeletons import Skeleton

__all__ = ["frame_speed", "speed_profile", "resample_path", "retime_path", "stall_window", "teleports", "GLITCH", "retime_run", "forward_retime_run", "smooth_run", "spline_run", "root_infill_run", "planted_feet_run",
           "CANDIDATES"]


def frame_speed(y: np.ndarray) -> tuple[np.ndarray, float]:
    """Mean joint speed ``(T - 1,)`` of ``y (T, J, 3)`` (``speed[t]``: frame t -> t + 1) and its median."""
    speed = np.linalg.norm(np.diff(y, axis=0), axis=-1).mean(-1)
    return speed, max(float(np.median(speed)), 1e-9)


def _bounds(n: int, lo: int, hi: int) -> tuple[int, int]:
    """Kept frames on each side of the run (or the run's own ends at the clip's edges)."""
    return max(lo - 1, 0), min(hi, n - 1)


def speed_profile(y: np.ndarray, a: int, b: int, length: float) -> np.ndarray:
    """Cumulative share of ``length`` covered at frames ``a..b``: a cubic Hermite curve whose slopes
    are the mean-joint speeds just outside the run, made non-decreasing."""
    n_steps = b - a
    v0 = np.linalg.norm(y[a] - y[a - 1], axis=-1).mean() if a > 0 else length / max(n_steps, 1)
    v1 = np.linalg.norm(y[b + 1] - y[b], axis=-1).mean() if b + 1 < len(y) else length / max(n_steps, 1)
    tau = np.linspace(0.0, 1.0, n_steps + 1)
    s = ((-2 * tau**3 + 3 * tau**2) * length + (tau**3 - 2 * tau**2 + tau) * v0 * n_steps
         + (tau**3 - tau**2) * v1 * n_steps)
    s = np.maximum.accumulate(np.clip(s, 0.0, length))
    return s / length if length > 1e-9 else tau


def resample_path(frames: np.ndarray, progress: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Frames at the times where the non-decreasing ``progress (L,)`` reaches ``target (L,)``."""
    progress = progress + np.arange(len(progress)) * 1e-9  # strictly increasing for interpolation
    idx = np.interp(target * progress[-1], progress, np.arange(len(frames)))
    i0 = np.floor(idx).astype(np.int64)
    i1 = np.minimum(i0 + 1, len(frames) - 1)
    w = (idx - i0)[:, None, None]
    return frames[i0] * (1 - w) + frames[i1] * w


#: A step whose body (the mean of its joints) moves more than this many times the clip's median speed (mean joint
#: speed) while its pose about that mean moves less than half as far is a jump in the recording: the whole body
#: teleports (18 of HumanAct12's 1,191 clips have one). A re-timing window is not grown over it, and a path holding
#: one is not re-timed: the re-timed frames would spread the jump along the path (one held-out clip's retrace cut
#: and stall re-timing did so: +1.2 m at the window's end, 23.6 cm over the clip).
GLITCH = 10.0
#: ... and at least this many metres (6 m/s at 20 frames a second): a clip that mostly stands still has a small median.
GLITCH_METRES = 0.3


def teleports(y: np.ndarray, median: float | None = None) -> np.ndarray:
    """``(T - 1,)`` bool: the steps of ``y (T, J, 3)`` metres where the whole body jumps (:data:`GLITCH`);
    ``median``: the speed to compare with (default ``y``'s own median, :func:`frame_speed`)."""
    x = np.asarray(y, np.float64)
    median = frame_speed(x)[1] if median is None else median
    centre = x.mean(-2, keepdims=True)
    body = np.linalg.norm(np.diff(centre[:, 0], axis=0), axis=-1)
    pose = np.linalg.norm(np.diff(x - centre, axis=0), axis=-1).mean(-1)
    return (body > max(GLITCH * median, GLITCH_METRES)) & (pose < 0.5 * body)


def retime_path(y: np.ndarray, a: int, b: int, path: np.ndarray) -> np.ndarray:
    """``y (T, J, 3)`` with frames ``a..b`` (inclusive) travelling along ``path (L, J, 3)`` (by arc length)
    at a smooth speed that joins the speeds just outside; frames ``a`` and ``b`` keep their poses. A path with a
    jump in the recording (:func:`teleports`) is not re-timed: ``y`` as given."""
    path = np.asarray(path, np.float64)
    if teleports(path, frame_speed(y)[1]).any():
        return y.copy()
    length = float(np.linalg.norm(np.diff(path, axis=0), axis=-1).mean(-1).sum())
    out = y.copy()
    out[a : b + 1] = resample_path(path, arc_length_profile(path), speed_profile(y, a, b, length)).astype(y.dtype)
    out[a], out[b] = y[a], y[b]
    return out


def retime_run(y: np.ndarray, lo: int, hi: int, skeleton: Skeleton) -> np.ndarray:
    """Re-time frames ``lo..hi-1`` along their own path (arc length) with a smooth speed profile."""
    a, b = _bounds(len(y), lo, hi)
    if b - a < 2:
        return y.copy()
    return retime_path(y, a, b, y[a : b + 1])


#: Frames after a stop within which the rush must begin (None: anywhere later in the run): a frozen transition
#: rushes to its end pose as soon as it moves again, while a rest that the motion leaves slowly (a walk's standing
#: start) is caught up with only much later, and re-timing over both spread the rest over a CMU walk (+19.7 cm).
RUSH_WITHIN = 12


#: What a stall re-timing re-times: ``"stall"``, each stop and the rush right after it (frames faster than the rush
#: level from the first such step within :data:`RUSH_WITHIN` to the last of that streak), or ``"run"``, the whole run
#: (the release before). A run widened over a flagged neighbourhood holds motion that never stalled: re-timed along
#: its path, a CMU washing clip's scrubbing after a rest moved 13-20 cm (calibration subjects 122 and 127, frozen
#: -46.0 % with "run", -1.9 % with "stall"; HumanAct12's 9-10: 72.9 / 72.5 %).
STALL_SPAN = "stall"


def stall_retime_run(y: np.ndarray, lo: int, hi: int, skeleton: Skeleton, stall: float = 0.1,
                     min_frames: int = 3, rush: float | None = 1.5, rush_within: int | None = RUSH_WITHIN) -> np.ndarray:
    """:func:`retime_run` where the run holds still (mean joint speed under ``stall`` of the clip's
    median for ``min_frames`` frames in a row) and then rushes (over ``rush`` times the median within
    ``rush_within`` frames after a stop ends, None: anywhere later in the run; ``rush=None``: not asked, the whole
    run re-timed), else no change; over each such stop and its rush, or the whole run (:data:`STALL_SPAN`). Re-timing a run that
    never stops moved it further from the truth (time warps) while it cured stalls; a stop that nothing catches up
    with afterwards is a rest (the still end of a clip), and spreading the motion over it cost one clip 4.7 cm."""
    speed, median = frame_speed(y)
    base = max(lo - 1, 0)
    window = speed[base:hi]  # window[i]: the step from frame base + i
    stops, n_stops = label(window < stall * median)
    spans = []
    for k in range(1, n_stops + 1):
        steps = np.flatnonzero(stops == k)
        if len(steps) < min_frames:
            continue
        first, end = int(steps[0]), int(steps[-1]) + 1
        if rush is None:  # not asked: the whole run, as before the rush rule
            return retime_run(y, lo, hi, skeleton)
        fast = (window[end:] if rush_within is None else window[end : end + rush_within]) > rush * median
        if not fast.any():  # nothing catches up with this stop (soon)
            continue
        last = end + int(np.argmax(fast))
        while last < len(window) and window[last] > rush * median:
            last += 1
        spans.append((first, last))
    if not spans:
        return y.copy()
    if STALL_SPAN == "run":
        return retime_run(y, lo, hi, skeleton)
    out = y.copy()
    for first, last in spans:  # frames base + first (still, kept) .. base + last + 1 (caught up, kept)
        out = retime_run(out, base + first + 1, min(base + last + 1, len(y) - 1), skeleton)
    return out


def stall_window(y: np.ndarray, lo: int, hi: int, *, stall: float = 0.1, rush: float = 1.5, reach: int = 12
                 ) -> tuple[int, int]:
    """``[lo, hi)`` grown over the stall before it (mean joint speed under ``stall`` of the clip's median)
    and the rush after it (over ``rush`` times the median, not a jump: :func:`teleports`), by at most ``reach``
    frames each side: a stalled transition must be re-timed from where it stops to where it has caught up."""
    speed, median = frame_speed(y)
    a, c = lo, hi
    jumps = teleports(y, median)  # the step a grown window would take in: a - 2 -> a - 1 before it, c -> c + 1 after
    while a > max(lo - reach, 1) and speed[a - 1] < stall * median and not jumps[a - 2]:
        a -= 1
    while c < min(hi + reach, len(y) - 1) and speed[c - 1] > rush * median and not jumps[c]:
        c += 1
    return a, c


def forward_retime_run(y: np.ndarray, lo: int, hi: int, skeleton: Skeleton) -> np.ndarray:
    """Re-time frames ``lo..hi-1`` by their progress from the first kept frame toward the last one
    (projection on that chord, kept only where it advances), with a smooth speed profile."""
    a, b = _bounds(len(y), lo, hi)
    if b - a < 2:
        return y.copy()
    frames = y[a : b + 1].astype(np.float64)
    chord = (frames[-1] - frames[0]).reshape(-1)
    norm2 = float(chord @ chord)
    if norm2 < 1e-8:
        return y.copy()
    u = ((frames - frames[0]).reshape(len(frames), -1) @ chord) / norm2
    progress = np.maximum.accumulate(np.clip(u, 0.0, 1.0))
    progress[-1] = 1.0
    length = float(np.sqrt(norm2 / frames.shape[1]))
    out = y.copy()
    out[a : b + 1] = resample_path(frames, progress, speed_profile(y, a, b, length)).astype(y.dtype)
    out[a], out[b] = y[a], y[b]
    return out


def smooth_run(y: np.ndarray, lo: int, hi: int, skeleton: Skeleton, sigma: float = 1.0) -> np.ndarray:
    """Frames ``lo..hi-1`` replaced by a Gaussian smoothing (``sigma`` frames) of the clip.

    With the true jitter frames (HumanAct12 subjects 9-10, ``transition_jitter`` severity 2) sigma
    1 frame removed 25 % of the added error, 1.5 frames 16 %, 2.5 frames -22 %."""
    out = y.copy()
    out[lo:hi] = gaussian_filter1d(y.astype(np.float64), sigma, axis=0, mode="nearest")[lo:hi].astype(y.dtype)
    return out


def spline_run(y: np.ndarray, lo: int, hi: int, skeleton: Skeleton, context: int = 4) -> np.ndarray:
    """Frames ``lo..hi-1`` replaced by a cubic smoothing spline through the run and ``context`` frames
    on each side, one smoothness for all joints chosen by generalised cross-validation.

    With the true jitter frames (HumanAct12 subjects 9-10, ``transition_jitter`` severity 2) it
    removed 30 % of the added error, Gaussian smoothing 25 % (sigma 1 frame), but it takes about
    0.5 s per run (GCV over all joints).
    """
    a, c = max(lo - context, 0), min(hi + context, len(y))
    out = y.copy()
    if c - a < 5:
        return out
    t = np.arange(a, c, dtype=np.float64)
    seg = y[a:c].reshape(c - a, -1).astype(np.float64)
    try:
        fit = make_smoothing_spline(t, seg)(t)
    except ValueError:  # scipy before n-D ordinates: one spline per coordinate
        fit = np.stack([make_smoothing_spline(t, seg[:, k])(t) for k in range(seg.shape[1])], 1)
    fit = fit.reshape(c - a, *y.shape[1:])
    out[lo:hi] = fit[lo - a : hi - a].astype(y.dtype)
    return out


def planted_feet_run(y: np.ndarray, lo: int, hi: int, skeleton: Skeleton, min_shift: float = 0.05) -> np.ndarray:
    """The whole body over ``lo..hi-1`` moved back by the part of its planted feet's horizontal slip
    that the root shares (:func:`refiner.core.contact.glide_steps`), step by step (moving the body for
    the rest made wrong poses worse). Frames where no foot is planted keep the
    shift reached so far; the splice takes it back to the kept frames. A glide that never moves
    the body ``min_shift`` metres away is left alone (planted feet of real clips slip a little)."""
    a, b = _bounds(len(y), lo, hi)
    out = y.copy()
    if b - a < 2:
        return out
    glide = glide_steps(y, skeleton)[a:b]  # (b - a, 3)
    shift = np.concatenate([np.zeros((1, 3)), -np.cumsum(glide, 0)])
    if np.linalg.norm(shift, axis=-1).max() < min_shift:
        return out
    out[a : b + 1] = (y[a : b + 1].astype(np.float64) + shift[:, None]).astype(y.dtype)
    return out


def grounded_run(y: np.ndarray, lo: int, hi: int, skeleton: Skeleton, min_shift: float = 0.05) -> np.ndarray:
    """The whole body over ``lo..hi-1`` moved along the up axis by the part of its lowest ground-contact joint's rise
    (or fall) that the root shares: a floating or sinking body carries root and feet alike, while a wrong pose or a
    squat moves the feet against the root. Both are measured from their linear course between the kept frames (at a
    clip's edge, from the one kept frame's level, and only where the body is back at that level by the edge: a
    held-out clip that climbs a step and stays up, its run reaching the clip's end, was pulled down 12 cm over 77
    frames). A body never moved ``min_shift`` metres is left alone (a real clip's feet and root rise together a
    little)."""
    a, b = _bounds(len(y), lo, hi)
    out = y.copy()
    if b - a < 2 or (lo <= 0 and hi >= len(y)):  # no kept frame: no level to come back to
        return out
    h = heights(y, skeleton)  # (T, J)
    t = (np.arange(a, b + 1) - a) / (b - a)

    def rise(v):  # (b - a + 1,): v over its course between the kept frames
        course = np.full(len(t), v[b]) if lo <= 0 else np.full(len(t), v[a]) if hi >= len(y) else (1 - t) * v[a] + t * v[b]
        return v[a : b + 1] - course

    dh, dr = rise(h[:, list(contact_joints(skeleton))].min(-1)), rise(h[:, skeleton.root])
    shared = np.where(dh * dr > 0, np.sign(dh) * np.minimum(np.abs(dh), np.abs(dr)), 0.0)
    edge = 0 if lo <= 0 else -1 if hi >= len(y) else None
    if np.abs(shared).max() < min_shift or (edge is not None and abs(shared[edge]) >= min_shift):
        return out
    out[a : b + 1] = (y[a : b + 1].astype(np.float64) - shared[:, None, None] * skeleton.up_vector).astype(y.dtype)
    return out


def root_infill_run(y: np.ndarray, lo: int, hi: int, skeleton: Skeleton) -> np.ndarray:
    """Root path over ``lo..hi-1`` linearly in-filled between the kept frames; each frame's pose kept."""
    root = skeleton.root
    a, b = _bounds(len(y), lo, hi)
    out = y.copy()
    if b - a < 2:
        return out
    t = (np.arange(a, b + 1) - a) / (b - a)
    path = (1 - t)[:, None] * y[a, root] + t[:, None] * y[b, root]
    out[a : b + 1] = y[a : b + 1] - y[a : b + 1, root : root + 1] + path[:, None]
    return out.astype(y.dtype)


#: Hand-written candidates by name (the network's proposals join them in the pipeline).
CANDIDATES = {"retime": retime_run, "stall_retime": stall_retime_run, "forward_retime": forward_retime_run, "smooth": smooth_run,
              "spline": spline_run, "root_infill": root_infill_run, "planted_feet": planted_feet_run,
              "grounded": grounded_run}
