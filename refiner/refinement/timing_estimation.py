"""Learned re-timing: which moment of the true motion each frame of a clip shows.

A timing flaw (a stall, a rush, a time warp) shows the right poses at the wrong moments: frame t
shows the true motion at source time ``s(t) = t + d(t)``. :class:`TimingNet`, dilated residual 1-D
convolutions over each frame's root-relative pose and velocity (receptive field about 4 s at 20 fps),
estimates the offsets ``d (B, T)`` in frames. Trained on real clips re-timed at random (monotone
warps of random windows: ``u + b sin(2 pi u) / (2 pi)``, slow-then-rush ``u ** p`` and its mirror,
freeze-then-rush and its mirror) with, in a share of crops, the non-timing training flaws of
:mod:`refiner.refinement.training_flaws` on top (their offsets stay zero, so they teach it what is
*not* a timing flaw). Playing motion backwards is never used (the benchmark's held-out family).

:func:`retime_by_offsets` undoes an estimate: where ``|d|`` reaches the calibrated threshold (widened
by a few frames) the frames are re-sampled at the inverse of ``s`` (kept non-decreasing), so the
poses come back at their own moments; every other frame is returned exactly.

Shipped in both HumanAct12 weight sets (80 channels on crops turned about the vertical at random, int8 weight matrices:
0.29 MB per set; 40,000 steps since the noise residual's release, about 45 minutes on one CPU core: validation loss
0.395 -> 0.353, threshold 1.65 -> 2.35 frames, bench 38.36 -> 38.94 %, frozen 72.0 -> 75.5, reversed 35.4 -> 36.6,
time_warp 24.2 -> 23.5; ``motion-refiner train --learned --only timing_estimator --base FOLDER`` trains it, sets its
threshold on the split's held-out subjects and adds it to the refiner in FOLDER). A refiner with it re-times first.
Measured first (20,000 steps, threshold 1.65 frames): calibration subjects 9-10 (every 2nd clip) 30.7 -> 34.9 %
(time_warp -0.4 -> 25.3, frozen 57.4 -> 69.5, jitter 34.3 -> 33.1, reversed 43.0 -> 40.0, foot_sliding 39.5 -> 36.9),
clean clips touched 2.4 -> 4.7 %; bench 32.1 -> 37.2 % (time_warp -0.2 -> 24.1, frozen 57.2 -> 71.6), clean clips
0.008 cm, 3.3 %. The bench's re-timings re-sampled by cubic splines instead of linearly (the estimator could have
learnt linear interpolation's kinks): time_warp -0.4 -> 23.6 %, frozen 57.4 -> 72.1: it reads the timing.

A run is re-timed only where the flaw classifier's timing group agrees (``Refiner(timing_agreement=0.8)``: its
probability reaches 0.8 somewhere in the run, read on the clip as given; a generator's clips: every run). Of the runs
the estimator alone re-timed on the calibration subjects, the glides', drifts' and clean clips' made them worse (20 of
21, 5 of 5, 2 of 2), read mostly as no timing flaw. Chosen there (34.98 % without; 35.48 / 35.69 / 35.96 / 35.83 /
35.81 % at 0.3 / 0.5 / 0.8 / 0.9 / 0.95); bench subjects 11-12: 37.23 -> 37.75 % (jitter 35.6 -> 37.6, foot_sliding
52.6 -> 53.8, frozen 71.6 -> 72.0, time_warp 24.1 -> 24.2), clean clips 0.008 -> 0.003 cm, 3.3 -> 1.8 % touched.

Crops turned at random (``turn``): validation loss 0.51 -> 0.41, threshold 3.1 -> 1.65 frames; unturned, bench 36.3 %.

Why time warps gain least: re-timed by their *true* offsets, the calibration subjects' warped clips lose 86 % of the
added error (frozen 92 %); by the estimate, 26 % (70 %). On the bench's warps,
which span half a clip's transitions (median 37 frames, a tenth over 100), the estimate correlates 0.44 with the true
offsets and reaches a third of their size; on the training crops' warps (at most 40 frames), 0.93 and its full size.
Trained on warps of up to 120 frames in 128-frame crops: threshold 11.2 frames, bench 29.5 % (time_warp 1.8 %).

Variants that lost (bench subjects 11-12, mean of the 7 families): 64 channels, 100 epochs: 31.8 % (its
clean-clip threshold 6.7 frames: time_warp 1.2 %; at 3 % of clean clips, 2.4 frames: time_warp 17.3 but jitter
29.3, foot_sliding 43.9); 128 channels, 40 epochs (1.36 MB per set as float16, past the weights budget): 34.7 %;
the network seeing the clip Gaussian-smoothed (``smooth=1.5`` frames, so that noise would not read as timing):
validation loss 0.79-0.84 against 0.50-0.53, threshold 12 frames, 31.5 %. Not taken either: the estimate averaged
with the clip's played backwards (offsets reversed and negated; threshold 2.8 frames): bench 36.3 -> 36.2 % (time_warp
18.6 -> 22.3, frozen 71.6 -> 66.1): no gain worth twice the passes. The estimator reading the clip through the noise filter (capped):
bench 37.23 -> 36.91 % (time_warp 24.1 -> 23.0, frozen 71.6 -> 69.8). Hysteresis on runs: 34.98 -> 34.89 %. A CMU
estimator (this network on CMU's training subjects, threshold 4.8 frames): CMU's held-out clips 25.9 -> 16.9 % (jitter
35.2 -> -14.0, wrong_anchor -2.1 -> -18.8, time_warp 0.0 -> 14.0; 20.6 % with the second opinion): the CMU weights hold none.
"""
from __future__ import annotations

import numpy as np
import torch
from einops import rearrange
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation
from torch import nn

from refiner.core.signal import resample
from refiner.core.skeletons import get_skeleton
from refiner.core.validation import check_is_fitted, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.training import TrainSchedule, fit_network, resolve_device, seeded
from refiner.refinement.repair_candidates import teleports
from refiner.refinement.splicing import project_bone_lengths, reference_lengths
from refiner.refinement.training_flaws import GROUPS, synthesize

__all__ = ["BATCH_MARGIN", "TIMING_AGREEMENT", "AGREED_CLIP_RATE", "AGREED_KEY", "TimingEstimator", "TimingNet", "timing_features", "random_retiming", "retime_by_offsets", "OTHER_KINDS"]

#: Frames: a clip whose estimated peak offset comes this close to the threshold is estimated alone
#: (:meth:`TimingEstimator.retiming_offsets`); batched and single passes differ by about 1e-6 frames.
BATCH_MARGIN = 1e-3
#: ``Refiner(timing_agreement=)``'s default: see :func:`estimated_retiming`.
TIMING_AGREEMENT = 0.8
#: With that agreement, runs pass at the offset this share of held-out clean clips reach (the manifest's
#: :data:`AGREED_KEY`; alone, at 1 %). Calibration subjects 9-10 (every 2nd clip; 1 / 2 / 2.5 / 3 / 4 %: 2.35 / 1.78 /
#: 1.51 / 1.22 / 0.91 frames): mean 37.6 / 37.9 / **38.1** / 38.0 / 37.8 % (time_warp 19.6 / 21.9 / 23.7 / 24.0 / 23.9,
#: frozen 72.9 / 72.6 / 72.5 / 71.9 / 70.8); clean clips re-timed with the agreement: 0 / 0 / 1 / 1 / 1 of 170.
AGREED_CLIP_RATE = 0.025
AGREED_KEY = "timing_agreed_threshold_frames"
#: Training flaws drawn on top of some crops: everything but timing (their offsets are zero).
OTHER_KINDS = GROUPS["pose"] + GROUPS["noise"] + GROUPS["root"]


def timing_features(x: torch.Tensor, root: int = 0) -> torch.Tensor:
    """``(B, T, J, 3)`` metres -> ``(B, 6J, T)``: every joint's position relative to the first frame's root,
    then every joint's velocity (metres per frame, the first frame's zero)."""
    rel = x - x[:, :1, root : root + 1]
    vel = torch.diff(x, dim=1, prepend=x[:, :1])
    return torch.cat([rearrange(rel, "b t j c -> b (j c) t"), rearrange(vel, "b t j c -> b (j c) t")], 1)


class TimingNet(nn.Module):
    """Joints ``(B, T, J, 3)`` metres -> source-time offsets ``(B, T)`` in frames (standardised features,
    ``mean`` and ``scale`` ``(6J,)``; zero output at initialisation)."""

    def __init__(self, n_joints: int, hidden: int = 128, dilations: tuple = (1, 2, 4, 8, 16, 1, 2, 4, 8, 1),
                 root: int = 0):
        super().__init__()
        self.root = root
        self.register_buffer("mean", torch.zeros(6 * n_joints))
        self.register_buffer("scale", torch.ones(6 * n_joints))
        self.inp = nn.Conv1d(6 * n_joints, hidden, 1)
        self.blocks = nn.ModuleList(nn.Sequential(nn.Conv1d(hidden, hidden, 3, padding=d, dilation=d), nn.GELU(),
                                                  nn.Conv1d(hidden, hidden, 1)) for d in dilations)
        self.out = nn.Conv1d(hidden, 1, 1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    @torch.no_grad()
    def standardise(self, x: torch.Tensor) -> None:
        feats = rearrange(timing_features(x, self.root), "b c t -> (b t) c")
        self.mean.copy_(feats.mean(0))
        self.scale.copy_(feats.std(0).clamp_min(1e-4))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.inp((timing_features(x, self.root) - self.mean[:, None]) / self.scale[:, None])
        for block in self.blocks:
            h = h + block(h)
        return self.out(h)[:, 0]


def smoothed_in_time(x: np.ndarray, sigma: float) -> np.ndarray:
    """Joints ``(..., T, J, 3)`` Gaussian-smoothed over time (``sigma`` frames; 0: as given): what the timing
    estimator sees, so that noise, which has no timing, does not read as one."""
    return x if sigma <= 0 else gaussian_filter1d(x, sigma, axis=-3, mode="nearest").astype(x.dtype)


def random_retiming(n_frames: int, rng: np.random.Generator, *, min_len: int = 6, max_len: int = 40) -> np.ndarray:
    """Source times ``(n_frames,)`` of one random monotone re-timing of a random window (see the module docstring)."""
    s = np.arange(n_frames, dtype=np.float64)
    length = int(rng.integers(min_len, min(max_len, n_frames - 1) + 1))
    a = int(rng.integers(0, n_frames - length))
    u = np.linspace(0.0, 1.0, length + 1)
    kind, mirrored = int(rng.integers(4)), rng.random() < 0.5
    if kind == 0:
        w = u + rng.uniform(-0.95, 0.95) * np.sin(2 * np.pi * u) / (2 * np.pi)
    elif kind == 1:
        w = u ** rng.uniform(1.5, 4.0)
    else:  # freeze for a share of the window, then rush (kind 2), or a sharper variant (kind 3)
        f = rng.uniform(0.2, 0.9)
        w = np.clip((u - f) / (1 - f), 0, 1) if kind == 2 else np.clip((u - f) / (1 - f), 0, 1) ** 1.5
    if mirrored:
        w = 1 - w[::-1]
    s[a : a + length + 1] = a + length * np.clip(w, 0, 1)
    return s


def retime_by_offsets(x: np.ndarray, offsets: np.ndarray, threshold: float, *, widen: int = 3, jumps=None
                      ) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Undo estimated offsets ``(T,)`` frames on joints ``x (T, J, 3)``: each run where ``|offsets| >= threshold``,
    widened by ``widen`` frames, is re-sampled at the inverse of its source times; returns ``(joints,
    [(start, stop), ...])`` with every frame outside the runs exactly as given. ``jumps``: ``(T - 1,)`` bool, steps
    (jumps in the recording, :func:`~refiner.refinement.repair_candidates.teleports`) a run must not hold: re-sampling
    would spread them over the run, so such a run is left as given."""
    d = np.asarray(offsets, np.float64)
    out = np.array(x, copy=True)
    if d.shape != (len(out),):
        raise ValueError(f"`offsets` must have one value per frame ({len(out)}); got shape {d.shape}.")
    if widen < 0:
        raise ValueError(f"`widen` must be >= 0; got {widen}.")
    big = np.abs(d) >= threshold
    if not big.any():
        return out, []
    grown = np.convolve(big.astype(float), np.ones(2 * widen + 1))[widen : widen + len(d)] > 0  # any clip length
    edges = np.flatnonzero(np.diff(np.r_[False, grown, False].astype(int)))
    runs = []
    for a, b in zip(edges[::2], np.minimum(edges[1::2], len(d) - 1)):
        if b - a < 2 or (jumps is not None and np.any(jumps[a:b])):
            continue
        frames = np.arange(a, b + 1, dtype=np.float64)
        s = np.clip(frames + d[a : b + 1], a, b)
        s[0], s[-1] = a, b  # the run's ends stay where they are
        s = np.maximum.accumulate(s) + np.arange(len(s)) * 1e-6  # strictly increasing to invert
        t = np.interp(frames, s, frames)
        t[0], t[-1] = a, b  # source times tied with an end (clipped there) must not move the end itself
        out[a : b + 1] = resample(np.asarray(x, np.float64)[a : b + 1], t - a).astype(out.dtype)
        runs.append((int(a), int(b) + 1))
    return out, runs


class _RetimedCrops:
    """Training batches for :class:`TimingEstimator`: random crops of real clips, re-timed in
    ``retimed`` of them (:func:`random_retiming`), with other training flaws on ``negatives`` of them."""

    def __init__(self, clips, window: int, retimed: float, negatives: float, skeleton: str, smooth: float = 0.0,
                 turn: bool = False):
        self.clips = [np.asarray(c, np.float32) for c in clips]
        self.window, self.retimed, self.negatives, self.skeleton = window, retimed, negatives, skeleton
        self.smooth, self.turn = smooth, turn

    def __len__(self) -> int:
        return len(self.clips)

    def _crop(self, clip: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
        n = self.window
        if len(clip) >= n:
            start = int(rng.integers(0, len(clip) - n + 1))
            crop = clip[start : start + n]
        else:  # short clips rest on their last frame
            crop = np.concatenate([clip, np.repeat(clip[-1:], n - len(clip), 0)])
        if self.turn:  # about the vertical through the first frame's root: timing does not depend on heading
            turn = Rotation.from_rotvec(get_skeleton(self.skeleton).up_vector * rng.uniform(0, 2 * np.pi)).as_matrix()
            root = crop[:1, get_skeleton(self.skeleton).root]
            crop = ((crop - root) @ turn.T.astype(np.float32) + root).astype(np.float32)
        s = random_retiming(n, rng) if rng.random() < self.retimed else np.arange(n, dtype=np.float64)
        out = resample(crop.astype(np.float64), s).astype(np.float32)
        if rng.random() < self.negatives:
            donors = [self.clips[k] for k in rng.integers(len(self.clips), size=3)]
            out = synthesize(out, rng, skeleton=self.skeleton, kinds=OTHER_KINDS, max_flaws=2, clean_probability=0.0,
                             donors=donors).joints
        return smoothed_in_time(out, self.smooth), (s - np.arange(n)).astype(np.float32)

    def sample(self, indices, rng, device="cpu") -> dict[str, torch.Tensor]:
        x, d = zip(*(self._crop(self.clips[int(i)], rng) for i in indices))
        return {"joints": torch.from_numpy(np.stack(x)).to(device), "offsets": torch.from_numpy(np.stack(d)).to(device)}

    def validation_batch(self, device="cpu", size: int = 256, seed: int = 12345) -> dict[str, torch.Tensor]:
        rng = np.random.default_rng(seed)
        return self.sample(rng.integers(len(self.clips), size=size), rng, device)


class TimingEstimator(NetworkComponent):
    """Estimates where each frame's pose belongs in time (see the module docstring); undoes timing flaws.

    Parameters
    ----------
    hidden : int, default=80
        Channels (see the module docstring for 64 and 128).
    window : int, default=64
        Training crop length (inference takes any length: the network is convolutional).
    retimed : float, default=0.75
        Share of training crops re-timed; the rest teach it to leave real timing alone.
    negatives : float, default=0.4
        Share of crops that also get non-timing training flaws (:data:`OTHER_KINDS`).
    widen : int, default=3
        Frames a re-timed run reaches beyond the frames whose offset passes the threshold.
    turn : bool, default=True
        Training crops turned about the vertical by a random angle (validation crops are not): see the module
        docstring (False: the first shipped version).
    smooth : float, default=0.0
        Gaussian smoothing (frames) of the clip the network sees, in training and use (:func:`smoothed_in_time`);
        the re-timing re-samples the clip as given.
    schedule : TrainSchedule, default=TrainSchedule(n_epochs=200, batch_size=48, learning_rate=1e-3, patience=200, steps_per_epoch=200)
        40,000 steps: about 45 minutes on one CPU core (20,000 before the noise residual's release).
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : TimingNet
    skeleton_ : str
    threshold_ : float
        Frames: a run re-timed needs an offset at least this large (:meth:`calibrate`; infinite until then);
        ``agreed_threshold_``, with the classifier's agreement, is set there too and kept in the refiner's manifest.
    history_ : list of dict
    """

    _fitted_attributes = ("skeleton_", "n_joints_", "threshold_", "history_")

    def __init__(self, *, hidden: int = 80, window: int = 64, retimed: float = 0.75, negatives: float = 0.4,
                 widen: int = 3, turn: bool = True, smooth: float = 0.0,
                 schedule: TrainSchedule = TrainSchedule(n_epochs=200, batch_size=48, learning_rate=1e-3, patience=200,
                                                         steps_per_epoch=200),
                 random_state: int | None = 0):
        self.hidden = hidden
        self.window = window
        self.retimed = retimed
        self.negatives = negatives
        self.widen = widen
        self.turn = turn
        self.smooth = smooth
        self.schedule = schedule
        self.random_state = random_state

    def _make_network(self, fitted: dict) -> TimingNet:
        return TimingNet(fitted["n_joints_"], self.hidden, root=get_skeleton(fitted["skeleton_"]).root)

    def fit(self, clips, *, skeleton: str = "humanact12", validation=None, checkpoint=None) -> "TimingEstimator":
        """Train on real clips ``(T_i, J, 3)`` metres (at least 8 frames) re-timed at random; ``validation``: held-out clips."""
        rng = check_random_state(self.random_state)
        clips = [np.asarray(c, np.float32) for c in clips if len(c) >= 8]
        if not clips:
            raise ValueError("TimingEstimator.fit needs clips of at least 8 frames.")
        self.skeleton_ = get_skeleton(skeleton).name
        self.n_joints_ = int(clips[0].shape[1])
        self.threshold_ = float("inf")
        batches = _RetimedCrops(clips, self.window, self.retimed, self.negatives, self.skeleton_, self.smooth, self.turn)
        val = _RetimedCrops(clips if validation is None else validation, self.window, self.retimed, self.negatives,
                            self.skeleton_, self.smooth)
        schedule = self._schedule()
        device = resolve_device(schedule.device)
        with seeded(rng):
            self.network_ = self._make_network({"skeleton_": self.skeleton_, "n_joints_": self.n_joints_})
            self.network_.standardise(batches.sample(rng.integers(len(batches), size=128), np.random.default_rng(1))["joints"])
            self.network_.to(device)
            self.history_ = fit_network(self.network_, self._loss, lambda idx, r: batches.sample(idx, r, device),
                                        len(batches), val.validation_batch(device), schedule, rng,
                                        checkpoint=checkpoint, desc="timing estimator")
        self.network_.to("cpu").eval()
        return self

    def _loss(self, net, batch, rng) -> torch.Tensor:
        return nn.functional.smooth_l1_loss(net(batch["joints"]), batch["offsets"])

    @torch.no_grad()
    def offsets(self, joints) -> np.ndarray:
        """Estimated source-time offsets ``(B, T)`` float32, frames, of a batch ``(B, T, J, 3)`` metres, one pass."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        x = np.array(joints, np.float32, copy=True)  # torch shares the memory; the caller's stays untouched
        if x.ndim != 4 or x.shape[2:] != (self.n_joints_, 3):
            raise ValueError(f"`joints` must be (B, T, {self.n_joints_}, 3); got shape {x.shape}.")
        if not np.isfinite(x).all():
            raise ValueError("`joints` must be finite; got NaN or Inf.")
        return self.network_(torch.from_numpy(smoothed_in_time(x, self.smooth)).to(self.device_)).cpu().numpy()

    def retiming_offsets(self, joints, threshold: float | None = None) -> np.ndarray:
        """:meth:`offsets` for re-timing: a clip whose peak comes within :data:`BATCH_MARGIN` frames of ``threshold``
        (default ``threshold_``) gets the offsets of a pass of its own. A batched convolution differs from a single clip's in the last bits
        (1e-6 frames) and re-timed frames follow the offsets continuously, so a clip is re-timed from the same
        numbers alone or in a batch; the others, below the threshold by more than that, are not re-timed at all."""
        x = np.asarray(joints, np.float32)
        d = self.offsets(x)
        if len(x) > 1:
            for b in np.flatnonzero(np.abs(d).max(1) >= (self.threshold_ if threshold is None else threshold) - BATCH_MARGIN):
                d[b] = self.offsets(x[b : b + 1])[0]
        return d

    def retime(self, joints) -> tuple[np.ndarray, list[list[tuple[int, int]]]]:
        """Joints ``(B, T, J, 3)`` with the runs whose offsets pass ``threshold_`` re-timed, and those runs per clip."""
        x = np.asarray(joints, np.float32)
        done = [retime_by_offsets(c, d, self.threshold_, widen=self.widen, jumps=teleports(c))
                for c, d in zip(x, self.retiming_offsets(x))]
        return np.stack([o for o, _ in done]), [r for _, r in done]

    def calibrate(self, clips, *, clip_rate: float = 0.05, agreed_rate: float = AGREED_CLIP_RATE) -> float:
        """Set ``threshold_`` (frames) so that at most ``clip_rate`` of these clean clips (held-out subjects)
        have an estimated offset that large anywhere, and ``agreed_threshold_`` so for ``agreed_rate``; returns the first."""
        if len(clips) == 0 or not (0.0 <= clip_rate <= 1.0 and 0.0 <= agreed_rate <= 1.0):
            raise ValueError(f"calibrate needs clean clips and rates in [0, 1]; got {len(clips)} clips, "
                             f"clip_rate {clip_rate}, agreed_rate {agreed_rate}.")
        peaks = [float(np.abs(self.offsets(np.asarray(c, np.float32)[None])[0]).max()) for c in clips]
        self.threshold_, self.agreed_threshold_ = (float(np.quantile(peaks, 1 - r)) for r in (clip_rate, agreed_rate))
        return self.threshold_


def _timing_probability(refiner, clips: np.ndarray, candidates: np.ndarray, agreement) -> np.ndarray | None:
    """``(B, T)``: the flaw classifier's timing-group probability on the ``candidates (B,)`` clips (0 elsewhere), each
    clip near ``agreement`` read alone (batched passes differ in the last bits); None without a classifier or agreement."""
    classifier = getattr(refiner, "flaw_classifier", None)
    if classifier is None or agreement is None:
        return None
    column = 1 + list(GROUPS).index("timing")
    out = np.zeros(clips.shape[:2])
    todo = np.flatnonzero(candidates)
    if todo.size:
        out[todo] = classifier.predict_all(clips[todo])[..., column]
        for b in todo[np.abs(out[todo] - agreement).min(1) < 1e-4] if todo.size > 1 else ():
            out[b] = classifier.predict_all(clips[b : b + 1])[0, :, column]
    return out


def estimated_retiming(refiner, clips: np.ndarray, reports: list, mode: str) -> np.ndarray:
    """The refiner's re-timing step: ``clips (B, T, J, 3)`` with the runs its ``timing_estimator`` finds re-timed (a
    transition step: not in ``mode="anchor"``) where the flaw classifier's timing group, read on the clip as given,
    reaches the refiner's ``timing_agreement`` somewhere in the run (None: every run, past the estimator's own threshold;
    with it, past the manifest's :data:`AGREED_KEY`), each change in its clip's report."""
    estimator = getattr(refiner, "timing_estimator", None)
    if estimator is None or getattr(refiner, "retiming", "estimated") != "estimated" or mode == "anchor":
        return clips
    agreement = getattr(refiner, "timing_agreement", TIMING_AGREEMENT)
    threshold = estimator.threshold_ if agreement is None else float(
        getattr(refiner, "manifest", {}).get("learned", {}).get(AGREED_KEY, estimator.threshold_))
    offsets = estimator.retiming_offsets(clips, threshold)
    timing = _timing_probability(refiner, clips, np.abs(offsets).max(1) >= threshold, agreement)
    out = clips.copy()
    for b, report in enumerate(reports):
        if np.abs(offsets[b]).max() < threshold:  # no run: spare the clip its search for jumps
            continue
        out[b], runs = retime_by_offsets(clips[b], offsets[b], threshold, widen=estimator.widen,
                                         jumps=teleports(clips[b]))
        if timing is not None:  # the classifier's second opinion: a run it does not read as a timing flaw stays as given
            for lo, hi in [r for r in runs if timing[b, r[0] : r[1]].max() < agreement]:
                out[b][lo:hi] = clips[b][lo:hi]
            runs = [r for r in runs if timing[b, r[0] : r[1]].max() >= agreement]
        changed = np.zeros(len(out[b]), bool)
        for lo, hi in runs:
            changed[lo:hi] = True
        if runs:  # re-sampled frames have shortened bones: back on the clip's own lengths
            out[b] = project_bone_lengths(out[b], reference_lengths(clips[b], refiner.skeleton), changed, refiner.skeleton)
        for lo, hi in runs:
            moved = 100 * float(np.linalg.norm(out[b][lo:hi] - clips[b][lo:hi], axis=-1).mean())
            report.changes.append({"start": lo, "stop": hi, "step": "transition", "repair": "estimated_retime",
                                   "reason": f"the timing estimator put these poses up to "
                                             f"{float(np.abs(offsets[b][lo:hi]).max()):.1f} frames from their own moments "
                                             f"(threshold {threshold:.1f}); re-timed (moved {moved:.1f} cm on "
                                             "average)"})
    return out
