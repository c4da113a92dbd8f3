"""Support: a body floating above its floor without flying put back on it (:class:`GroundStep`), and a body gliding
over it with its planted feet slid back (:class:`GlideStep`).

A person stands on the floor or is in flight, and flight is ballistic. ``detect`` fits the clip's floor as a plane
under the lowest contact joint of each frame (the camera of a capture, or a generator, need not hold the floor
level), then flags runs where the body's offset from it (the gap, smoothed) stays above ``float_m`` while the root
and head rise with it (the body moved, not a limb or a crouch) and the root does not decelerate as a jump does.
``propose`` lowers the whole body along the vertical by the run's offset, so every pose, bone and horizontal path is
kept. ``verify`` keeps a run only where floating falls and jerk, foot skating and penetration do not rise beyond
:func:`~refiner.refinement.steps.base.harms`' tolerances over the levelled floor, nor floating over the given clip's
lowest contact. ``float_m`` is calibrated on clean clips
(:func:`calibrated_ground`) and lives in the weights' manifest. A body sunk below its floor is not raised: by the
floor clips are judged on (their lowest contact) that always makes them float more (``docs/decisions.md`` D24).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scipy.ndimage import gaussian_filter1d, median_filter

from refiner.core.contact import contact_joints, foot_joints, heights
from refiner.core.floor import (floor_gap, floor_plane, levelled, plane_basis, plane_height, support_heights,
                                support_joints)
from refiner.core.skeletons import get_skeleton
from refiner.refinement.steps.base import grown, harms, runs, window_figures

__all__ = ["GroundConfig", "GroundStep", "grown_runs", "float_runs", "calibrated_ground", "GlideConfig", "GlideStep",
           "glide_offset", "glide_runs", "calibrated_glide"]

_G = 9.81  # m/s²


@dataclass(frozen=True)
class GroundConfig:
    """Options of :class:`GroundStep`. ``float_m``: the calibrated height above the floor that flags a run (the
    manifest's), never calibrated under ``least_float_m`` (twice the floor's ``bandwidth_m``: below it the fit of a
    flawed clip's floor moves by as much, ``docs/decisions.md`` D24); ``min_run`` frames; a run grows out while its
    smoothed gap stays beyond ``edge_share`` of its threshold; ``smooth_frames``: the Gaussian that smooths the gap
    into the body's offset (what is repaired); an airborne run whose root decelerates by ``flight_share`` of gravity
    is a jump and is left alone, and so is a run whose root and head do not follow its gap with a slope of
    ``follow_share`` (a limb or a crouch, not a body moved); ``bandwidth_m`` is how far off the floor a frame still
    pulls the plane fit; ``jerk_share``, ``ground_tolerance_m`` and ``slide_pairs`` as in
    :class:`~refiner.refinement.steps.infill.InfillConfig`."""

    float_m: float = 0.05
    least_float_m: float = 0.04
    min_run: int = 3
    edge_share: float = 0.25
    smooth_frames: float = 2.0
    flight_share: float = 0.5
    follow_share: float = 0.5
    bandwidth_m: float = 0.02
    jerk_share: float = 0.05
    ground_tolerance_m: float = 0.0005
    slide_pairs: float = 0


def _departure(v, s: int, e: int) -> np.ndarray:
    """``v[s:e]`` less the straight course between the frames that bound the run, ``v[s - 1]`` and ``v[e]``."""
    v = np.asarray(v, np.float64)
    share = (np.arange(1, e - s + 1) / (e - s + 1)).reshape((-1,) + (1,) * (v.ndim - 1))
    return v[s:e] - (v[s - 1] + (v[e] - v[s - 1]) * share)


def _is_flight(root_height, peak_m: float, fps: float, share: float) -> bool:
    """Whether a run off the floor can be a jump: its root ``(t,)`` metres decelerates by ``share`` of gravity, or it
    rises ``share`` of what a ballistic body in the air that long rises (g t² / 8)."""
    if len(root_height) < 3:
        return False
    t = np.arange(len(root_height)) / fps
    return bool(2.0 * np.polyfit(t, root_height, 2)[0] < -share * _G or peak_m >= share * _G * t[-1] ** 2 / 8)


def grown_runs(size, limit: float, min_run: int, edge_share: float) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` of ``size (T,)``: runs of ``min_run`` frames above ``limit``, each grown while ``size``
    stays above ``edge_share`` of it, kept off the first and last frame (which bound every repair)."""
    out, n = [], len(size)
    for s, e in runs(np.asarray(size) > limit):
        if e - s < min_run:
            continue
        s, e = grown(s, e, np.asarray(size) > edge_share * limit)
        s, e = max(s, 1), min(e, n - 1)
        if e > s:
            out.append((s, e))
    return out


def _merged(found) -> list[tuple[int, int]]:
    """Runs ``[(start, stop), ...]`` in order, those that touch or overlap joined."""
    out = []
    for s, e in found:
        if out and s <= out[-1][1]:
            out[-1] = (out[-1][0], max(e, out[-1][1]))
        else:
            out.append((s, e))
    return out


def float_runs(gap, rest, fps: float, float_m: float, config: GroundConfig) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` over ``gap (T,)`` and ``rest (T, K)``, the heights of the root and the head
    (:func:`support_heights`, metres): :func:`grown_runs` of the smoothed gap over ``float_m`` where the body moved as
    a whole and not in flight."""
    found = [(s, e) for s, e in grown_runs(smoothed_gap(gap, config), float_m, config.min_run, config.edge_share)
             if not _is_flight(rest[s:e, 0], float(np.max(gap[s:e])), fps, config.flight_share)
             and _body_moved(gap, rest, s, e, config.follow_share)]
    return _merged(found)


def _body_moved(gap, rest, s: int, e: int, share: float) -> bool:
    """Whether the run ``[s, e)`` moved the body as a whole: the heights ``rest (T, K)`` of the root and the head follow
    the gap's departure from its course between the bounding frames with a slope of ``share`` or more each, and the
    root's height above the lowest joint departs by under ``share`` of it (a limb off or through the floor moves the
    lowest joint alone, a crouch or a tuck changes the legs' reach; a body raised or lowered moves them all)."""
    d = _departure(gap, s, e)
    slopes = _departure(rest, s, e).T @ d / max(float(d @ d), 1e-12)
    reach = np.abs(_departure(np.asarray(rest)[:, 0] - gap, s, e)).max()  # the root's height above the lowest joint
    return bool(slopes.min() >= share and reach < share * np.abs(d).max())


def smoothed_gap(gap, config: GroundConfig) -> np.ndarray:
    """``gap (..., T)`` low-passed along time (Gaussian of ``smooth_frames``): the body's offset from its floor, without the
    frame-to-frame switching of which foot joint is lowest."""
    return gaussian_filter1d(np.asarray(gap, np.float64), config.smooth_frames, axis=-1, mode="nearest")


class GroundStep:
    """Detect / propose / verify / report for support (see the module docstring) on a batch of one skeleton."""

    name = "ground"
    moves_whole_body = True

    def __init__(self, skeleton: str, config: GroundConfig):
        self.skeleton, self.config = get_skeleton(skeleton).name, config

    def detect(self, clips) -> tuple[np.ndarray, np.ndarray, list]:
        """``clips (N, T, J, 3)`` -> their floors ``plane (N, 3)``, ``gap (N, T)`` and each clip's floating runs (only
        clips whose smoothed gap passes ``float_m`` somewhere are looked at further)."""
        skel, c = get_skeleton(self.skeleton), self.config
        plane = floor_plane(clips, skel, bandwidth_m=c.bandwidth_m)
        gap = floor_gap(clips, skel, plane)
        high = (smoothed_gap(gap, c) > c.float_m).any(-1)
        found = [float_runs(g, support_heights(x, skel), skel.fps, c.float_m, c) if h else []
                 for x, g, h in zip(clips, gap, high)]
        return plane, gap, found

    def propose(self, clip, gap, found) -> np.ndarray:
        """The clip with each run's body lowered by its smoothed gap above the line joining the gaps of the frames
        that bound the run (onto the floor, and no jump where the run meets them)."""
        out = np.array(clip, dtype=np.float64)
        up = get_skeleton(self.skeleton).up_vector
        offset = smoothed_gap(gap, self.config)
        for s, e in found:
            out[s:e] -= np.clip(_departure(offset, s, e), 0, None)[:, None, None] * up
        return out

    def refine(self, clips, actions=None) -> tuple[np.ndarray, list[list[dict]], None]:
        """Detect, propose and verify every clip of ``clips (N, T, J, 3)``: the kept clips and each clip's entries.
        A run is kept where floating over the levelled floor falls, jerk, foot skating and penetration do not rise
        beyond :func:`~refiner.refinement.steps.base.harms`' tolerances, and the clip's floating over the given clip's
        lowest contact (the floor clips are usually judged on) does not rise at all."""
        out, changes, c = np.array(clips, dtype=np.float64), [], self.config
        root = len(get_skeleton(self.skeleton).bones)
        floor = -c.bandwidth_m  # the fitted floor is known to within its bandwidth
        contact = list(contact_joints(self.skeleton))
        planes, gaps, founds = self.detect(out)
        for i, (clip, plane, gap, found) in enumerate(zip(out, planes, gaps, founds)):
            entries = []
            if found:
                lowest = float(heights(clip[:, contact], self.skeleton).min())  # the given clip's floor, as the suites judge
                proposed = self.propose(clip, gap, found)
                before, after = levelled(clip, plane, self.skeleton), levelled(proposed, plane, self.skeleton)
                for s, e in found:
                    fb = window_figures(before, s, e, self.skeleton, floor)
                    fa = window_figures(after, s, e, self.skeleton, floor)
                    worse = harms(fb, fa, jerk_share=c.jerk_share, ground_tolerance_m=c.ground_tolerance_m,
                                  slide_pairs=c.slide_pairs)
                    trial = out[i].copy()
                    trial[s:e] = proposed[s:e]
                    if _clip_floating(trial, self.skeleton, lowest) > _clip_floating(out[i], self.skeleton, lowest) + 1e-9:
                        worse.append("floating over the clip's lowest contact")
                    kept = fa.floating < fb.floating and not worse
                    entries.append({"step": self.name, "start": s, "stop": e, "parts": [root], "kept": kept,
                                    "gap_cm": round(100 * float(gap[s:e].max()), 2), "worse": worse})
                    if kept:
                        out[i] = trial
            changes.append(entries)
        return out, changes, None


def _clip_floating(joints, skeleton, ground: float, tolerance_m: float = 0.005) -> float:
    """Mean height (metres) of each frame's lowest joint above ``ground``, past ``tolerance_m`` (PhysDiff's float)."""
    return float(np.maximum(heights(joints, skeleton).min(-1) - ground - tolerance_m, 0.0).mean())


def calibrated_ground(clips, skeleton, *, share: float = 0.03, window: int = 60, config: GroundConfig = GroundConfig(),
                      most_m: float = 0.25) -> float | None:
    """``float_m`` at which :func:`float_runs` flags ``share`` of ``window``-frame pieces of the clean ``clips`` (real,
    unseen; bisection), never under ``config.least_float_m``; None where it would take
    more than ``most_m``: such clean clips stand on more than one floor (stairs, a ladder), and the step does not
    apply to them."""
    skel = get_skeleton(skeleton)
    found = []
    for c in clips:
        x = np.asarray(c, np.float64)
        found.append((floor_gap(x, skel, bandwidth_m=config.bandwidth_m), support_heights(x, skel)))
    pieces = sum(max(1, -(-(len(g) - window // 2) // window)) for g, _ in found)

    def flagged_share(float_m):
        hit = 0
        for gap, rest in found:
            last = max(0, len(gap) - window // 2 - 1) // window
            hit += len({min(t // window, last) for s, e in float_runs(gap, rest, skel.fps, float_m, config)
                        for t in range(s, e)})
        return hit / pieces

    if flagged_share(most_m) > share:
        return None
    lo, hi = config.least_float_m, most_m
    for _ in range(20):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if flagged_share(mid) > share else (lo, mid)
    return hi


@dataclass(frozen=True)
class GlideConfig:
    """Options of :class:`GlideStep`. ``glide_m``: the calibrated offset that flags a run (the manifest's); the
    planted foot is the slower foot within ``contact_m`` of the floor, its steps despiked over ``despike_frames`` and
    its drift taken against its running median over ``course_frames`` (what the body's own travel looks like); a run
    counts where the root and head follow the offset with a slope of ``follow_share`` (the body slid, not a foot);
    ``min_run``, ``edge_share``, ``smooth_frames``, ``jerk_share``, ``ground_tolerance_m`` and ``slide_pairs`` as in
    :class:`GroundConfig`."""

    glide_m: float = 0.08
    follow_share: float = 0.5
    contact_m: float = 0.05
    despike_frames: int = 3
    course_frames: int = 61
    min_run: int = 3
    edge_share: float = 0.25
    smooth_frames: float = 2.0
    bandwidth_m: float = 0.02
    jerk_share: float = 0.05
    ground_tolerance_m: float = 0.0005
    slide_pairs: float = 0


def glide_offset(joints, skeleton, config: GlideConfig, plane=None) -> np.ndarray:
    """``(..., T, 2)`` metres along :func:`~refiner.core.floor.plane_basis`: how far clips ``joints (..., T, J, 3)``
    have slid with their planted foot, against that foot's running median course (a foot on the floor should not
    travel)."""
    x = np.asarray(joints, np.float64)
    skel = get_skeleton(skeleton)
    plane = floor_plane(x, skel, bandwidth_m=config.bandwidth_m) if plane is None else plane
    feet = list(foot_joints(skel))
    h = heights(x[..., feet, :], skel) - plane_height(x[..., feet, :], plane, skel)  # (..., T, 2)
    step = np.diff(x[..., feet, :] @ plane_basis(skel).T, axis=-3)  # (..., T-1, 2 feet, 2)
    planted = (h[..., 1:, :] < config.contact_m) & (h[..., :-1, :] < config.contact_m)
    slower = np.where(planted, np.linalg.norm(step, axis=-1), np.inf).argmin(-1)
    slide = np.take_along_axis(step, slower[..., None, None], -2)[..., 0, :] * planted.any(-1)[..., None]
    lead = (1,) * (slide.ndim - 2)
    slide = median_filter(slide, size=lead + (config.despike_frames, 1), mode="nearest")
    drift = np.concatenate([np.zeros_like(slide[..., :1, :]), np.cumsum(slide, -2)], -2)
    n = drift.shape[-2]
    course = median_filter(drift, size=lead + (min(config.course_frames, n - 1 + n % 2), 1), mode="nearest")
    return gaussian_filter1d(drift - course, config.smooth_frames, axis=-2, mode="nearest")


def glide_runs(offset, glide_m: float, config: GlideConfig) -> list[tuple[int, int]]:
    """``[(start, stop), ...]``: :func:`grown_runs` of ``|offset (T, 2)|`` over ``glide_m``, those that touch joined."""
    return _merged(grown_runs(np.linalg.norm(offset, axis=-1), glide_m, config.min_run, config.edge_share))


class GlideStep:
    """Gliding: a body whose planted feet slide with it over the floor, slid back (detect / propose / verify / report).

    ``detect``: :func:`glide_offset` above the calibrated ``glide_m``, the root and head sliding with it. ``propose``:
    the whole body moved back along the floor by the run's offset above the line joining its bounding frames' (poses,
    bones and heights kept). ``verify``: kept only where foot skating falls, jerk, penetration and floating do not rise
    beyond :func:`~refiner.refinement.steps.base.harms`' tolerances (over the given clip's lowest contact) and, given
    a ``judge`` (the motion model), it finds the run more real."""

    name = "glide"
    moves_whole_body = True

    def __init__(self, skeleton: str, config: GlideConfig, judge=None):
        self.skeleton, self.config, self.judge = get_skeleton(skeleton).name, config, judge

    def refine(self, clips, actions=None) -> tuple[np.ndarray, list[list[dict]], None]:
        """Detect, propose and verify every clip of ``clips (N, T, J, 3)``: the kept clips and each clip's entries."""
        skel, c = get_skeleton(self.skeleton), self.config
        out, changes, root = np.array(clips, dtype=np.float64), [[] for _ in clips], len(skel.bones)
        actions = [None] * len(out) if actions is None else list(actions)
        offsets = glide_offset(out, skel, c)
        support, proposed = support_joints(skel), {}
        for i in np.flatnonzero((np.linalg.norm(offsets, axis=-1) > c.glide_m).any(-1)):
            offset, carried = offsets[i], out[i][:, support] @ plane_basis(skel).T  # (T, K, 2): root and head
            lowest = float(heights(out[i][:, list(contact_joints(skel))], skel).min())
            trial = out[i].copy()
            for s, e in glide_runs(offset, c.glide_m, c):
                d = _departure(offset, s, e)
                follow = np.einsum("tkc,tc->k", _departure(carried, s, e), d) / max(float((d * d).sum()), 1e-12)
                if follow.min() < c.follow_share:  # a foot moved alone (a limb), not the body with it
                    continue
                trial[s:e] -= (d @ plane_basis(skel))[:, None, :]
                fb, fa = window_figures(out[i], s, e, skel, lowest), window_figures(trial, s, e, skel, lowest)
                worse = harms(fb, fa, jerk_share=c.jerk_share, ground_tolerance_m=c.ground_tolerance_m,
                              slide_pairs=c.slide_pairs)
                worse += [] if fa.slide < fb.slide else ["no less skating"]
                if worse:
                    trial[s:e] = out[i, s:e]
                changes[i].append({"step": self.name, "start": s, "stop": e, "parts": [root], "kept": not worse,
                                   "gap_cm": round(100 * float(np.linalg.norm(d, axis=-1).max()), 2), "worse": worse})
            proposed[i] = trial
        self._judged(out, proposed, actions, changes)
        for i, trial in proposed.items():
            for entry in changes[i]:
                if entry["kept"]:
                    out[i, entry["start"]:entry["stop"]] = trial[entry["start"]:entry["stop"]]
        return out, changes, None

    def _judged(self, given, proposed: dict, actions, changes) -> None:
        """Mark not kept the runs the ``judge`` does not find more real (its flaw probability over the run falls)."""
        todo = [i for i in proposed if any(e["kept"] for e in changes[i])]
        if self.judge is None or not todo:
            return
        acts = [actions[i] for i in todo]
        before = self.judge.scan(given[todo], acts)[1].max(-1)
        after = self.judge.scan(np.stack([proposed[i] for i in todo]), acts)[1].max(-1)
        for k, i in enumerate(todo):
            for entry in changes[i]:
                s, e = entry["start"], entry["stop"]
                if entry["kept"] and not after[k, s:e].max() < before[k, s:e].max():
                    entry["kept"], entry["worse"] = False, ["not more real"]


def calibrated_glide(clips, skeleton, *, share: float = 0.03, window: int = 60, config: GlideConfig = GlideConfig(),
                     most_m: float = 0.25) -> float | None:
    """``glide_m`` that flags ``share`` of ``window``-frame pieces of the clean ``clips`` (real, unseen): the quantile
    of each piece's highest offset held for ``min_run`` frames; None where it would pass ``most_m``."""
    scores = []
    for c in clips:
        size = np.linalg.norm(glide_offset(c, skeleton, config), axis=-1)
        m = config.min_run
        held = np.min(np.stack([size[k:len(size) - m + 1 + k] for k in range(m)]), 0)
        scores += [held[s:s + window].max() for s in range(0, max(1, len(held) - window // 2), window)]
    glide_m = float(np.quantile(scores, 1.0 - share))
    return glide_m if glide_m <= most_m else None
