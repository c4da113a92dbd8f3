"""Learned noise filter: linear denoising learned from mocap, at the noise level it estimates frame by frame.

Gaussian smoothing treats every joint alone and takes motion with the noise: given the benchmark's
*true* jittered frames (after the rigid-skeleton step) it removes 22.9 % of the added error, and on the
a2m reference generator, whose clips jitter everywhere (joint acceleration 19.5 m/s², real 6.0), it
raised the FID (4.285 -> 4.474). A linear filter fitted by least squares on real clips with white noise
knows how joints move together: each frame's correction comes from the poses of its ``2 h + 1``
neighbouring frames (all joints), the optimal linear (Wiener) estimate for that noise level. With the
true jittered frames it removes 35-38 % (a filter of ``h = 2 / 4 / 6`` frames: 37.1 / 38.5 / 38.6 % at
the benchmark's level); on a2m, applied to every frame, FID 4.285 -> 3.787 and accuracy 42.0 -> 43.2 %
(600 samples), acceleration 19.5 -> 9.2 m/s².

The best filter depends on the noise level, so :class:`NoiseFilterNet` holds one per level of
:data:`NOISE_LEVELS` and :class:`NoiseFilter` estimates the level of every frame from how far its
reference filter (1 cm) moves the frames around it, less the slow part of that move (a wrong pose
asks for slow corrections, noise for white ones), against the same figure measured on the training
clips at each level (``level_rms_``). It serves three steps of the learned refiner:

- the typed repair of flagged noise runs (``TYPED_REPAIRS["noise"] = ("noise_filter", 0)``): every frame
  of the run at its own level;
- the last steps (:func:`filtered_noise`): runs the flaw classifier's noise group finds where its flaw
  probability stays under its threshold (:func:`noise_run_frames`), in clips not noisy throughout, every
  frame at its own level (moves capped as below); and clips noisy *throughout*, as a generator's texture: a clip
  whose level in three frames of four passes ``threshold_`` (calibrated on held-out clean clips) has its
  frames denoised at that level, faded in from 0 at a frame level of ``threshold_`` to full at twice
  it, no joint moved further than noise of that level would have moved it (``max_move``: a linear
  filter also takes fast motion for noise); the frames under it, and every other clip, are returned
  exactly.
"""
from __future__ import annotations

import numpy as np
import torch
from einops import rearrange
from scipy.ndimage import binary_opening, gaussian_filter1d, label, uniform_filter1d
from torch import nn

from refiner.core.skeletons import get_skeleton, rigid_skeleton
from refiner.core.validation import check_is_fitted, check_joint_batch, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.refinement.splicing import project_bone_lengths, reference_lengths

__all__ = ["NoiseFilter", "NoiseFilterNet", "window_features", "filtered_noise", "noise_run_frames", "NOISE_LEVELS",
           "NOISE_PROBABILITY"]

#: Noise levels (standard deviation per coordinate, metres) of the filter bank; the reference level
#: that estimates the noise is 1 cm.
NOISE_LEVELS = (0.005, 0.01, 0.02)
#: Metres: the lowest threshold :meth:`NoiseFilter.calibrate` sets (most clean clips' level is exactly 0).
_MIN_THRESHOLD = 1e-4
#: Frames (Gaussian sigma) of the slow part of a correction that the noise estimate leaves out.
_SLOW = 2.0
#: Noise runs the flaw classifier sees by its noise group alone (:func:`noise_run_frames`): at least
#: ``NOISE_RUN`` frames whose noise-group probability passes ``NOISE_PROBABILITY``, grown while it stays above
#: ``NOISE_LOW``. The classifier's flaw threshold (0.95, calibrated on clean clips) flags too few jittered
#: frames: with the true jittered frames the filter removes 38.4 % of the added error, in the pipeline 22.3 %
#: (calibration subjects 9-10; README, table of choices).
NOISE_PROBABILITY, NOISE_LOW, NOISE_RUN = 0.9, 0.5, 3


def window_features(x: torch.Tensor, half_width: int, root: int = 0) -> torch.Tensor:
    """``(B, T, J, 3)`` metres -> ``(B, T, (2 h + 1) 3J)``: every joint's displacement to each of the ``2 h``
    frames around the frame (the clip's ends repeated), then the frame's pose relative to its root.

    Displacements and a root-relative pose span the same linear functions as the raw window (less the
    frame's root) at the scale of the noise, so the fitted weights survive float16 storage."""
    t = x.shape[1]
    padded = torch.cat([x[:, :1].expand(-1, half_width, -1, -1), x, x[:, -1:].expand(-1, half_width, -1, -1)], 1)
    shifts = [padded[:, k : k + t] - x for k in range(2 * half_width + 1) if k != half_width]
    parts = [*shifts, x - x[:, :, root : root + 1]]
    return torch.cat([rearrange(p, "b t j c -> b t (j c)") for p in parts], -1)


class NoiseFilterNet(nn.Module):
    """Joints ``(B, T, J, 3)`` metres -> corrections ``(B, L, T, J, 3)`` metres, one per noise level: a linear
    map of :func:`window_features` per level (``weight (L, F, 3J)``, ``bias (L, 3J)``)."""

    def __init__(self, n_joints: int, half_width: int = 3, n_levels: int = len(NOISE_LEVELS), root: int = 0):
        super().__init__()
        self.half_width, self.root = half_width, root
        n_features = (2 * half_width + 1) * 3 * n_joints
        self.weight = nn.Parameter(torch.zeros(n_levels, n_features, 3 * n_joints))
        self.bias = nn.Parameter(torch.zeros(n_levels, 3 * n_joints))

    def forward(self, x: torch.Tensor, levels: slice = slice(None)) -> torch.Tensor:
        f = window_features(x, self.half_width, self.root)
        c = torch.einsum("btf,lfd->bltd", f, self.weight[levels]) + self.bias[levels][None, :, None]
        return rearrange(c, "b l t (j c) -> b l t j c", c=3)


class NoiseFilter(NetworkComponent):
    """Removes white noise from the frames whose estimated noise level passes a threshold (see the module
    docstring); fitted in closed form (ridge least squares), in seconds.

    Parameters
    ----------
    half_width : int, default=3
        Frames on each side that a frame's correction sees.
    levels : tuple of float, default=NOISE_LEVELS
        Noise standard deviations (metres) of the bank's filters; must include 0.01, the reference.
    copies : int, default=2
        Noisy copies of every training clip per level.
    ridge : float, default=1e-6
        Ridge penalty per training frame.
    rigid_tolerance : float or None, default=0.005
        Noisy training clips are put on rigid bones first, as the refiner shows clips to its steps.
    window : int, default=9
        Frames over which a frame's noise level is estimated.
    clip_quantile : float, default=0.25
        A clip's noise level (:meth:`clip_noise_level`) is this quantile of its frames' levels.
    max_move : float or None, default=1.0
        In a clip noisy throughout, no joint moves further than this many times ``sqrt(3)`` times the clip's
        level (noise of that standard deviation moves a joint about that far; a larger correction is
        taking motion). None: no cap.
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : NoiseFilterNet
    skeleton_ : str
    level_rms_ : list of float
        Metres: the median windowed correction of the reference filter on the training clips at noise 0
        and at each level (the curve that :meth:`noise_level` inverts).
    threshold_ : float
        Metres: frames whose estimated level is under it are not changed (set by :meth:`calibrate`;
        infinite until then).
    """

    _fitted_attributes = ("skeleton_", "n_joints_", "level_rms_", "threshold_")

    def __init__(self, *, half_width: int = 3, levels: tuple = NOISE_LEVELS, copies: int = 2, ridge: float = 1e-6,
                 rigid_tolerance: float | None = 0.005, window: int = 9, clip_quantile: float = 0.25,
                 max_move: float | None = 1.0, random_state: int | None = 0):
        self.half_width = half_width
        self.levels = levels
        self.copies = copies
        self.ridge = ridge
        self.rigid_tolerance = rigid_tolerance
        self.window = window
        self.clip_quantile = clip_quantile
        self.max_move = max_move
        self.random_state = random_state

    def _make_network(self, fitted: dict) -> NoiseFilterNet:
        return NoiseFilterNet(fitted["n_joints_"], self.half_width, len(self.levels), get_skeleton(fitted["skeleton_"]).root)

    def _noisy(self, clip: np.ndarray, sigma: float, rng) -> np.ndarray:
        y = clip + sigma * rng.normal(size=clip.shape)
        if self.rigid_tolerance is not None:
            y = rigid_skeleton(y, self.skeleton_, self.rigid_tolerance)[0]
        return y

    def fit(self, clips, *, skeleton: str = "humanact12") -> "NoiseFilter":
        """Fit the bank on real clips ``(T_i, J, 3)`` metres (T_i >= 2), each with ``copies`` noisy copies per level."""
        levels = tuple(float(v) for v in self.levels)
        if len(levels) < 2 or min(levels) <= 0 or list(levels) != sorted(set(levels)) or 0.01 not in levels:
            raise ValueError(f"`levels` must be two or more increasing positive noise levels (metres) including 0.01; "
                             f"got {self.levels}.")
        if self.half_width < 1 or self.copies < 1 or self.window < 1:
            raise ValueError("`half_width`, `copies` and `window` must be >= 1.")
        rng = check_random_state(self.random_state)
        clips = [np.asarray(c, np.float64) for c in clips]
        if not clips or any(c.ndim != 3 or c.shape[-1] != 3 or len(c) < 2 for c in clips):
            raise ValueError("`clips` must be a non-empty list of (T >= 2, J, 3) arrays.")
        self.skeleton_ = get_skeleton(skeleton).name
        self.n_joints_ = int(clips[0].shape[1])
        self.threshold_ = float("inf")
        net = self._make_network({"n_joints_": self.n_joints_, "skeleton_": self.skeleton_})
        for level, sigma in enumerate(levels):
            gram, cross, n = 0.0, 0.0, 0
            for clip in clips:
                for _ in range(self.copies):
                    y = self._noisy(clip, sigma, rng)
                    f = window_features(torch.from_numpy(y[None]), self.half_width, net.root)[0].numpy()
                    f = np.concatenate([f, np.ones((len(f), 1))], 1)
                    gram, cross, n = gram + f.T @ f, cross + f.T @ (clip - y).reshape(len(y), -1), n + len(f)
            penalty = self.ridge * n * np.eye(len(gram))
            penalty[-1, -1] = 0.0  # the bias is not shrunk
            solution = np.linalg.solve(gram + penalty, cross)
            net.weight.data[level] = torch.from_numpy(solution[:-1]).float()
            net.bias.data[level] = torch.from_numpy(solution[-1]).float()
        self.network_ = net.eval()
        rms = [np.median(np.concatenate([self._rms(self._reference((self._noisy(c, s, rng) if s else c)[None]))[0]
                                         for c in clips]))
               for s in (0.0, *levels)]
        self.level_rms_ = [float(v) for v in np.maximum.accumulate(rms)]
        return self

    @torch.no_grad()
    def _corrections(self, x: np.ndarray, levels: slice = slice(None)) -> np.ndarray:
        """``(B, L, T, J, 3)`` metres: the bank's corrections (only ``levels`` of it: the noise estimate needs
        the reference filter alone, a third of the work)."""
        return self.network_(torch.from_numpy(np.array(x, np.float32)), levels).numpy()

    def _reference(self, x: np.ndarray) -> np.ndarray:
        ref = tuple(float(v) for v in self.levels).index(0.01)
        return self._corrections(x, slice(ref, ref + 1))

    def _rms(self, corrections: np.ndarray) -> np.ndarray:
        """``(B, T)`` metres: the reference filter's correction ``(B, 1, T, J, 3)``, less its slow part,
        root-mean-square over joints and over ``window`` frames. White noise asks for corrections as
        white as itself; a drifting or wrong pose asks for slow ones (without this high-pass, 79 % of
        the benchmark's drifting clips read as noisy throughout)."""
        c = corrections[:, 0]
        c = c - gaussian_filter1d(c, _SLOW, axis=1, mode="nearest")
        return np.sqrt(np.maximum(uniform_filter1d((c ** 2).sum(-1).mean(-1), self.window, axis=1, mode="nearest"), 0.0))

    def noise_level(self, joints: np.ndarray) -> np.ndarray:
        """``(B, T)`` metres: each frame's estimated noise level (0 for the training clips' median clean frame)."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        return self._levels(self._reference(np.asarray(joints, np.float32)))

    def _levels(self, corrections: np.ndarray) -> np.ndarray:
        rms = self._rms(corrections)
        grid, table = np.r_[0.0, self.levels], np.asarray(self.level_rms_)
        slope = (grid[-1] - grid[-2]) / max(table[-1] - table[-2], 1e-12)  # beyond the last level: on its line
        return np.where(rms > table[-1], grid[-1] + (rms - table[-1]) * slope, np.interp(rms, table, grid))

    def _checked(self, joints) -> np.ndarray:
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        return check_joint_batch(joints, self.n_joints_)

    def _at_level(self, x: np.ndarray, sigma: np.ndarray, c: np.ndarray) -> np.ndarray:
        """``x (B, T, J, 3)`` plus the bank's corrections ``c (B, L, T, J, 3)`` interpolated at ``sigma (B, T)``
        metres (under the lowest level: its correction scaled down toward none at 0)."""
        grid = np.asarray(self.levels)
        hi = np.clip(np.searchsorted(grid, sigma), 1, len(grid) - 1)
        frac = np.clip((sigma - grid[hi - 1]) / (grid[hi] - grid[hi - 1]), 0.0, 1.0)[..., None, None]
        b, t = np.indices(sigma.shape)
        below = np.clip(sigma / grid[0], 0.0, 1.0)[..., None, None]
        low = (sigma < grid[0])[..., None, None]
        return x + np.where(low, below * c[b, 0, t], (1 - frac) * c[b, hi - 1, t] + frac * c[b, hi, t])

    def denoise(self, joints: np.ndarray, frames: np.ndarray | None = None, *, capped: bool = False,
                residual=None) -> np.ndarray:
        """Every frame of a batch ``(B, T, J, 3)`` metres (or only ``frames (B, T)`` bool) denoised at its own
        estimated level (for frames known to be noisy), no joint moved further than noise of that level would
        have moved it where ``capped``, then corrected by a fitted ``residual``
        (:class:`~refiner.refinement.noise_residual.NoiseResidual`); ``(B, T, J, 3)`` float32, other frames exactly
        as given."""
        x = self._checked(joints)
        levels = self._levels(self._reference(x))
        if frames is not None:
            levels = np.where(np.broadcast_to(np.asarray(frames, bool), levels.shape), levels, 0.0)
        move = self._at_level(x, levels, self._corrections(x)) - x
        move = self._capped(move, levels) if capped else move
        if residual is not None:
            move = move + residual.correction(x, move, levels)
        return (x + move).astype(np.float32)

    def _capped(self, move: np.ndarray, level: np.ndarray) -> np.ndarray:
        """``move (B, T, J, 3)`` with each joint's step cut to ``max_move`` times what noise of ``level (B, T)``
        metres per coordinate would move it (unchanged when ``max_move`` is None)."""
        if self.max_move is None:
            return move
        cap = self.max_move * np.sqrt(3.0) * level[..., None]
        return move * np.minimum(1.0, cap / np.maximum(np.linalg.norm(move, axis=-1), 1e-12))[..., None]

    def clip_noise_level(self, joints: np.ndarray) -> np.ndarray:
        """``(B,)`` metres: each clip's level, the ``clip_quantile`` of its frames' estimates (noise *throughout*,
        as a generator's texture, where even the quieter frames are noisy). A frame's estimate also rises
        with fast motion (on clean held-out clips the largest frame estimates reach 1.3 cm in 10 % of
        clips, 6.6 cm at most); a low quantile over the clip does not."""
        return np.quantile(self.noise_level(self._checked(joints)), self.clip_quantile, axis=1)

    def denoise_clips(self, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Clips ``(B, T, J, 3)`` metres whose :meth:`clip_noise_level` passes ``threshold_`` denoised, every
        frame at the clip's level (moves capped by ``max_move``); returns ``(joints float32, levels (B,))`` (the other clips exactly as given)."""
        x = self._checked(joints)
        frames = self._levels(self._reference(x))
        levels = np.quantile(frames, self.clip_quantile, axis=1)
        noisy = levels > self.threshold_
        if noisy.any():
            given = x[noisy]
            level = np.broadcast_to(levels[noisy, None], frames[noisy].shape).copy()
            weight = np.clip(frames[noisy] / self.threshold_ - 1.0, 0.0, 1.0)[..., None, None]
            move = self._capped(self._at_level(given, level, self._corrections(given)) - given, level)
            x[noisy] = given + weight * move
        return x, levels

    def calibrate(self, clips, *, clip_rate: float = 0.03) -> float:
        """Set ``threshold_`` (metres) so that at most ``clip_rate`` of these clean clips (held-out subjects)
        have a :meth:`clip_noise_level` above it; returns it."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        if len(clips) == 0 or not 0 < clip_rate < 1:
            raise ValueError(f"calibrate needs clean clips and 0 < clip_rate < 1; got {len(clips)} clips, clip_rate {clip_rate}.")
        levels = [float(self.clip_noise_level(np.asarray(c, np.float32)[None])[0]) for c in clips]
        # most clean clips' level is exactly 0: a rate that reaches them must not give a threshold of 0
        self.threshold_ = max(float(np.quantile(levels, 1 - clip_rate)), _MIN_THRESHOLD)
        return self.threshold_


def noise_run_frames(probability: np.ndarray) -> np.ndarray:
    """``(B, T)`` bool: the frames of noise runs in the flaw classifier's noise-group probability ``(B, T)``
    (:data:`NOISE_PROBABILITY`, ``NOISE_LOW``, ``NOISE_RUN``)."""
    p = np.atleast_2d(np.asarray(probability, np.float64))
    seeds = binary_opening(p > NOISE_PROBABILITY, structure=np.ones((1, NOISE_RUN), bool))
    grown, _ = label(p > NOISE_LOW, structure=np.array([[0, 0, 0], [1, 1, 1], [0, 0, 0]], bool))
    return np.isin(grown, np.unique(grown[seeds])) & (grown > 0)


def denoised_noise_runs(refiner, clips: np.ndarray, reports: list, noise_probability: np.ndarray,
                        repaired: np.ndarray, mode: str = "full") -> np.ndarray:
    """In ``clips (B, T, J, 3)``, the noise runs (:func:`noise_run_frames`) of the flaw classifier's noise-group
    probability ``(B, T)`` (on the clips before the repairs) that hold no frame a repair changed (``repaired (B, T)``
    bool), denoised at their frames' estimated level with capped moves and put back on the clip's bone lengths; a run
    holding a recognised anchor (the report's) is an anchor step, else a transition step: only those of ``mode``."""
    keep = np.zeros(clips.shape[:2], bool)
    for b in np.flatnonzero(noise_run_frames(noise_probability).any(1)):
        runs, n_runs = label(noise_run_frames(noise_probability[b : b + 1])[0])
        anchors = np.asarray(reports[b].anchors, int)
        for r in range(1, n_runs + 1):
            frames = np.flatnonzero(runs == r)
            kind = "anchor" if ((anchors >= frames[0]) & (anchors <= frames[-1])).any() else "transition"
            keep[b, frames] = not repaired[b, frames].any() and mode in ("full", kind)
    todo = np.flatnonzero(keep.any(1))
    if not todo.size:
        return clips
    denoised = refiner.noise_filter.denoise(clips[todo], keep[todo], capped=True,
                                            residual=getattr(refiner, "noise_residual", None))
    return _put_back(refiner, clips, denoised, todo, reports, lambda b, n: (
        f"a noise run ({n} frames changed): the noise-group probability passed {NOISE_PROBABILITY:g} for "
        f"{NOISE_RUN} frames or more (grown while above {NOISE_LOW:g}; the flaw probability under its threshold), "
        f"or its bones changed length roughly from frame to frame; denoised at each frame's estimated level"), per_run=True)


def _put_back(refiner, clips: np.ndarray, denoised: np.ndarray, rows, reports: list, reason, per_run: bool = False
              ) -> np.ndarray:
    """``clips (B, T, J, 3)`` with clip ``rows[k]`` taken from ``denoised[k]`` where that changed it, the changed
    frames put back on the clip's bone lengths and a "noise" change with ``reason(b, n_frames_changed)`` reported
    (one per run of changed frames where ``per_run``, else one from the first changed frame to the last)."""
    out = clips.copy()
    for k, b in enumerate(rows):
        changed = (denoised[k] != clips[b]).reshape(clips.shape[1], -1).any(-1)
        if not changed.any():
            continue
        out[b] = project_bone_lengths(denoised[k], reference_lengths(clips[b], refiner.skeleton), changed, refiner.skeleton)
        runs, n_runs = label(changed) if per_run else (changed.astype(int), 1)
        for r in range(1, n_runs + 1):
            frames = np.flatnonzero(runs == r)
            moved = 100 * float(np.linalg.norm(out[b][frames] - clips[b][frames], axis=-1).mean())
            reports[b].changes.append({
                "start": int(frames[0]), "stop": int(frames[-1] + 1), "step": "noise", "repair": "noise_filter",
                "reason": f"{reason(b, len(frames))} (moved {moved:.2f} cm on average)"})
    return out


def filtered_noise(refiner, clips: np.ndarray, reports: list, noise_probability: np.ndarray | None = None,
                   repaired: np.ndarray | None = None, mode: str = "full") -> tuple[np.ndarray, np.ndarray]:
    """The refiner's noise steps, last: in ``clips (B, T, J, 3)`` that its ``noise_filter`` finds noisy throughout
    (a generator's texture rather than a flawed run), the noisy frames denoised and put back on the clip's bone
    lengths; in the others, with the classifier's ``noise_probability`` and the frames the repairs changed
    (``repaired``), the noise runs it saw (:func:`denoised_noise_runs`, ``denoising="filter"`` only). With
    ``denoising="runs"`` (``refine()``'s default) every clip gets the noise runs and none the first step's denoising
    (those clips are still found and reported): on mocap the step cost jittered clips their runs' repair (calibration
    subjects 9-10, jitter 39.2 % without it, 36.6 % with it) and touched 2.4 % of clean clips. Each change is written to the clip's report. Returns ``(clips, noisy
    throughout (B,) bool)``."""
    noise_filter, denoising = getattr(refiner, "noise_filter", None), getattr(refiner, "denoising", "filter")
    none = np.zeros(len(clips), bool)
    if noise_filter is None or denoising not in ("filter", "throughout", "runs"):
        return clips, none
    if denoising == "runs":  # found and reported (the texture filter's "auto", the pose prior's gate), not denoised
        noisy = noise_filter.clip_noise_level(clips) > noise_filter.threshold_
        for b in np.flatnonzero(noisy):
            reports[b].noisy_throughout = True
        if noise_probability is None or repaired is None:
            return clips, noisy
        return denoised_noise_runs(refiner, clips, reports, noise_probability, repaired, mode), noisy
    denoised, levels = noise_filter.denoise_clips(clips)
    rows = np.flatnonzero(levels > noise_filter.threshold_)
    for b in rows:
        reports[b].noisy_throughout = True
    out = _put_back(refiner, clips, denoised[rows], rows, reports, lambda b, n: (
        f"noisy throughout: estimated noise {100 * float(levels[b]):.2f} cm per coordinate in three frames of four "
        f"(threshold {100 * noise_filter.threshold_:.2f} cm); {n} noisy frames denoised by the learned noise filter"))
    calm = levels <= noise_filter.threshold_  # a clip noisy throughout had the step above
    if noise_probability is None or repaired is None or denoising != "filter":
        return out, ~calm
    return denoised_noise_runs(refiner, out, reports, np.where(calm[:, None], noise_probability, 0.0), repaired, mode), ~calm
