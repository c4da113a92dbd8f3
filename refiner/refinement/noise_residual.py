"""Noise residual: what the linear noise filter leaves of white noise, corrected by a small network.

The noise filter (:mod:`refiner.refinement.noise_filter`) is the best *linear* estimate of a frame from the
frames around it at one noise level: it smooths a joint alike whether it is still or swinging. How much of
a joint's wiggle is noise depends on how the body moves, which no linear map knows. :class:`NoiseResidualNet`,
an MLP over each frame's window of the clip (the filter's own :func:`~refiner.refinement.noise_filter.window_features`,
in centimetres), the filter's move of the frame and the frame's estimated level, adds the correction the filter
missed. :class:`NoiseResidual` trains it on real clips given white noise of a random level (``min_level`` to
``max_level`` per coordinate) over the clip or a sin-shaped window of it, turned about the vertical at random, put
on rigid bones as the refiner's first step shows them (the frames outside the window are a rigid core) and
denoised by the fitted filter at its estimated levels, capped, as the refiner's noise runs are.

It serves the frames the noise filter denoises as a flaw: the noise runs the flaw classifier finds and the typed
repair of noise runs (``Refiner(noise_residual=...)``); a clip noisy throughout (a generator's texture) keeps the
filter alone, as the generator figures were measured.

Measured on the calibration subjects 9-10 (every 2nd clip, transition jitter at severity 2, its *true* frames
denoised after the rigid-skeleton step, uncapped; ``runs/s37/nf_mlp.py``, git-ignored): the filter alone removes
38.9 % of the added error; with a residual of 512 hidden units trained on 3 / 10 noisy copies of the training
subjects 1-8: 41.2 / 42.7 %; 256 units, 20 copies: 42.6 %; a window of 6 frames instead of 3: 42.8 %; the frame's
window read in its body frame (:func:`~refiner.refinement.pose_prior.body_frame`) instead of turned crops:
40.7 %; a *linear* residual trained alike: 38.9 % (nothing: the gain is the network's nonlinearity). In the refiner
(``motion-refiner bench flaws``, train-split weights, subjects 11-12, severity 2): transition jitter 37.6 -> 41.9 %,
mean of the 7 families 37.75 -> 38.36 %, every other family and the clean clips as before.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from refiner.core.rigid import rigid_skeleton
from refiner.core.rotations import rotvec_to_rotmat
from refiner.core.skeletons import get_skeleton
from refiner.core.validation import check_is_fitted, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.training import TrainSchedule, fit_network, resolve_device, seeded
from refiner.refinement.noise_filter import window_features

__all__ = ["NoiseResidual", "NoiseResidualNet", "residual_features", "check_residual"]

#: The network reads and writes centimetres (unit-sized inputs at the scale of the noise).
_CM = 100.0


def residual_features(x: torch.Tensor, move: torch.Tensor, level: torch.Tensor, half_width: int,
                      root: int = 0) -> torch.Tensor:
    """``(B, T, F)`` centimetres: :func:`~refiner.refinement.noise_filter.window_features` of ``x (B, T, J, 3)``
    metres, the noise filter's move ``(B, T, J, 3)`` metres of every frame and its estimated level ``(B, T)`` metres."""
    flat = move.reshape(*move.shape[:2], -1)
    return torch.cat([window_features(x, half_width, root), flat, level[..., None]], -1) * _CM


class NoiseResidualNet(nn.Module):
    """Features ``(N, F)`` (:func:`residual_features`) -> corrections ``(N, 3J)`` centimetres: an MLP of two hidden
    layers over the features standardised by the training set's ``mean`` and ``scale`` (buffers); its last layer
    starts at zero, so an untrained residual leaves the filter's output as it is."""

    def __init__(self, n_joints: int, half_width: int = 3, hidden: int = 256):
        super().__init__()
        n_in = (2 * half_width + 1) * 3 * n_joints + 3 * n_joints + 1
        self.register_buffer("mean", torch.zeros(n_in))
        self.register_buffer("scale", torch.ones(n_in))
        self.mlp = nn.Sequential(nn.Linear(n_in, hidden), nn.GELU(), nn.Linear(hidden, hidden), nn.GELU(),
                                 nn.Linear(hidden, 3 * n_joints))
        nn.init.zeros_(self.mlp[-1].weight)
        nn.init.zeros_(self.mlp[-1].bias)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return self.mlp((features - self.mean) / self.scale)


class NoiseResidual(NetworkComponent):
    """Corrects the frames a fitted :class:`~refiner.refinement.noise_filter.NoiseFilter` denoised (see the module
    docstring).

    Parameters
    ----------
    hidden : int, default=256
        Units of each of the MLP's two hidden layers.
    copies : int, default=10
        Noisy copies of every training clip.
    min_level, max_level : float, default=0.003, 0.025
        Metres: the range of the training noise's standard deviation per coordinate.
    whole : float, default=0.3
        Share of the copies noisy over the whole clip; the others over a random window (sin-shaped, at least 8 frames).
    rigid_tolerance : float, default=0.005
        Noisy copies are put on rigid bones first (the clean frames outside the window kept as a core), as the
        refiner's first step shows clips to its noise steps.
    schedule : TrainSchedule
        10 epochs of batches of 512 frames at 1e-3 (about 2 minutes on one CPU core for HumanAct12's subjects 1-8).
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : NoiseResidualNet
    skeleton_, n_joints_ : str, int
    half_width_ : int
        The noise filter's half width, whose features the network reads.
    """

    _fitted_attributes = ("skeleton_", "n_joints_", "half_width_")

    def __init__(self, *, hidden: int = 256, copies: int = 10, min_level: float = 0.003, max_level: float = 0.025,
                 whole: float = 0.3, rigid_tolerance: float = 0.005,
                 schedule: TrainSchedule = TrainSchedule(n_epochs=10, batch_size=512, learning_rate=1e-3, patience=3),
                 random_state: int | None = 0):
        self.hidden = hidden
        self.copies = copies
        self.min_level = min_level
        self.max_level = max_level
        self.whole = whole
        self.rigid_tolerance = rigid_tolerance
        self.schedule = schedule
        self.random_state = random_state

    def _make_network(self, fitted: dict) -> NoiseResidualNet:
        return NoiseResidualNet(fitted["n_joints_"], fitted["half_width_"], self.hidden)

    def _examples(self, clips, noise_filter, rng) -> tuple[np.ndarray, np.ndarray]:
        """Features ``(N, F)`` and targets ``(N, 3J)`` centimetres of the noisy frames of ``copies`` noisy copies of
        every clip (the clean frame less the filter's output)."""
        up = get_skeleton(self.skeleton_).up_vector
        root = get_skeleton(self.skeleton_).root
        feats, targets = [], []
        for clip in clips:
            n = len(clip)
            for _ in range(self.copies):
                clean = clip @ rotvec_to_rotmat(up * rng.uniform(0, 2 * np.pi)).T
                lo = int(rng.integers(0, max(n - 8, 0) + 1))
                hi = int(rng.integers(min(lo + 8, n), n + 1))
                u = np.clip((np.arange(n) - lo) / max(hi - lo - 1, 1), 0.0, 1.0)
                w = np.where((np.arange(n) >= lo) & (np.arange(n) < hi), np.sin(np.pi * u), 0.0)
                if rng.random() < self.whole or not (w > 0).any():
                    w = np.ones(n)
                noisy = clean + rng.uniform(self.min_level, self.max_level) * w[:, None, None] * rng.normal(size=clean.shape)
                x = rigid_skeleton(noisy.astype(np.float32), self.skeleton_, self.rigid_tolerance, keep_core=True,
                                   keep_shortened=True, spikes=True)[0][None]
                frames = (w > 0)[None]
                level = np.where(frames, noise_filter.noise_level(x), 0.0)
                denoised = noise_filter.denoise(x, frames, capped=True)
                f = residual_features(torch.from_numpy(x), torch.from_numpy(denoised - x),
                                      torch.from_numpy(level.astype(np.float32)), self.half_width_, root)[0].numpy()
                feats.append(f[frames[0]])
                targets.append(((clean - denoised[0]).reshape(n, -1) * _CM)[frames[0]])
        return np.concatenate(feats).astype(np.float32), np.concatenate(targets).astype(np.float32)

    def fit(self, clips, noise_filter, *, skeleton: str = "humanact12", validation=None, checkpoint=None
            ) -> "NoiseResidual":
        """Fit on real clips ``(T_i, J, 3)`` metres behind the fitted ``noise_filter`` (clips under 8 frames left out);
        ``validation`` clips (default: a tenth of the training clips) judge the epochs."""
        check_is_fitted(noise_filter, "network_", msg=NOT_FITTED)
        clips = [np.asarray(c, np.float64) for c in clips]
        if any(c.ndim != 3 or c.shape[-1] != 3 for c in clips) or not (clips := [c for c in clips if len(c) >= 8]):
            raise ValueError("`clips` must be a list of (T, J, 3) arrays, some of 8 frames or more.")
        if not 0 < self.min_level <= self.max_level or self.copies < 1 or not 0 <= self.whole <= 1:
            raise ValueError("NoiseResidual needs 0 < min_level <= max_level, copies >= 1 and 0 <= whole <= 1; got "
                             f"{self.min_level}, {self.max_level}, {self.copies}, {self.whole}.")
        if noise_filter.skeleton_ != get_skeleton(skeleton).name or noise_filter.n_joints_ != clips[0].shape[1]:
            raise ValueError(f"the noise filter serves {noise_filter.skeleton_!r} ({noise_filter.n_joints_} joints); "
                             f"the clips are {skeleton!r} ({clips[0].shape[1]} joints).")
        rng = check_random_state(self.random_state)
        self.skeleton_, self.n_joints_ = noise_filter.skeleton_, noise_filter.n_joints_
        self.half_width_ = int(noise_filter.half_width)
        x, y = self._examples(clips, noise_filter, rng)
        held = [c for c in (np.asarray(c, np.float64) for c in validation) if len(c) >= 8] if validation is not None else []
        held = held or clips[: max(1, len(clips) // 10)]
        vx, vy = self._examples(held, noise_filter, np.random.default_rng(7))
        device = resolve_device(self.schedule.device)
        with seeded(rng):
            net = self._make_network({"n_joints_": self.n_joints_, "half_width_": self.half_width_})
            net.mean.copy_(torch.from_numpy(x.mean(0)))
            net.scale.copy_(torch.from_numpy(x.std(0) + 1e-3))
            self.network_ = net.to(device)
            val = {"x": torch.from_numpy(vx[:20000]).to(device), "y": torch.from_numpy(vy[:20000]).to(device)}
            self.history_ = fit_network(self.network_, _loss, lambda idx, r: {"x": torch.from_numpy(x[idx]).to(device),
                                                                            "y": torch.from_numpy(y[idx]).to(device)},
                                        len(x), val, self.schedule, rng, checkpoint=checkpoint, desc="noise_residual")
        self.network_.to("cpu").eval()
        return self

    @torch.no_grad()
    def correction(self, x: np.ndarray, move: np.ndarray, level: np.ndarray) -> np.ndarray:
        """``(B, T, J, 3)`` metres: the correction of the frames of ``x (B, T, J, 3)`` metres that the noise filter
        moved by ``move (B, T, J, 3)`` at the estimated ``level (B, T)`` metres; zero where ``level`` is 0."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        x, move = np.asarray(x, np.float32), np.asarray(move, np.float32)
        level = np.asarray(level, np.float32)
        if x.ndim != 4 or x.shape[2:] != (self.n_joints_, 3) or move.shape != x.shape or level.shape != x.shape[:2]:
            raise ValueError(f"`x` and `move` must be (B, T, {self.n_joints_}, 3) and `level` (B, T); got "
                             f"{x.shape}, {move.shape}, {level.shape}.")
        out = np.zeros_like(x)
        frames = level > 0
        if frames.any():
            f = residual_features(torch.from_numpy(x), torch.from_numpy(move), torch.from_numpy(level), self.half_width_,
                                  get_skeleton(self.skeleton_).root)
            out[frames] = (self.network_(f[torch.from_numpy(frames)]).numpy() / _CM).reshape(-1, self.n_joints_, 3)
        return out


def check_residual(noise_filter, residual):
    """``residual`` if it serves ``noise_filter`` (its skeleton, joints and half width: the features it reads), None
    if it is None; ``ValueError`` for a residual without a filter or trained behind another one."""
    if residual is None:
        return None
    if noise_filter is None:
        raise ValueError("a `noise_residual` corrects what a `noise_filter` leaves; give the filter it was trained behind.")
    mine = (residual.skeleton_, residual.n_joints_, residual.half_width_)
    theirs = (noise_filter.skeleton_, noise_filter.n_joints_, int(noise_filter.half_width))
    if mine != theirs:
        raise ValueError(f"the noise residual was trained behind a noise filter of (skeleton, joints, half width) {mine}; "
                         f"this noise filter has {theirs}.")
    return residual


def _loss(net, batch, rng) -> torch.Tensor:
    return ((net(batch["x"]) - batch["y"]) ** 2).mean()
