"""Transition refinement (paper §3.2.3): concept encoder + bias encoder + transformer.

The concept encoder gives each transition a concept feature (its frames' features pooled), which
an MLP decodes into spline parameters (supervised by the fitted spline, ``L_C``). The bias encoder
gives one bias feature for the whole sequence (individual style). Per frame, the transition's
concept feature, the bias feature and the frame's place in its transition go through a
transformer that outputs the refined sequence (``L_S``, MPJPE to the real clip). Loss
``L_S + concept_weight * L_C`` (Eq. 5).

Beyond the paper: with probability ``corrupt_prob`` a training input has one transition corrupted
(jitter, frozen or blended toward a random pose) while the target stays clean, so the module learns
to *repair* transitions rather than only reconstruct them. ``corrupt_prob=0`` is the paper's variant.
A transition is flagged when the module's output differs from it by more than ``threshold_`` (the
``100 - flaw_percentile`` percentile of that difference on held-out real transitions).
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from refiner.concepts.splines import eval_spline, fit_spline
from refiner.concepts.transitions import arc_length_profile, retime
from refiner.core.signal import overlap_add, window_starts
from refiner.core.validation import check_is_fitted, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.layers import MLP, mpjpe
from refiner.nn.training import TrainSchedule, crop_start, fit_network, put_crop, resolve_device, seeded, to_device
from refiner.refinement.encoders import MotionEncoder, MotionEncoderConfig, encoder_config

__all__ = ["TransitionRefiner", "TransitionRefinementNet", "transition_layout", "corrupt_transition",
           "TransitionRetimer", "spline_residual", "DURATION_BINS"]


def transition_layout(n_frames: int, anchors, length: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame: transition index, local time ``tau`` in [0, 1] and the transition's duration.

    Anchor frames belong to the transition they start (the last frame to the last transition).
    """
    anchors = np.asarray(anchors)
    idx = np.clip(np.searchsorted(anchors, np.arange(n_frames), side="right") - 1, 0, len(anchors) - 2)
    dur = np.diff(anchors)[idx]
    tau = (np.arange(n_frames) - anchors[idx]) / np.maximum(dur, 1)
    return idx.astype(np.int64), tau.astype(np.float32), dur.astype(np.float32)


class TransitionRefinementNet(nn.Module):
    """``(B, T, J*3)`` + transition layout -> refined ``(B, T, J*3)`` and per-transition spline coefficients."""

    def __init__(self, encoder: MotionEncoderConfig, n_joints: int, max_transitions: int):
        super().__init__()
        d = encoder.d_model
        self.n_joints = n_joints
        self.max_transitions = max_transitions
        self.concept_encoder = MotionEncoder(encoder)
        self.bias_encoder = MotionEncoder(encoder)
        self.concept_decoder = MLP(d, 4 * n_joints * 3, d)
        cfg = MotionEncoderConfig(2 * d + 2, d, encoder.n_layers, encoder.n_heads, encoder.ffn_dim, encoder.dropout, encoder.max_len)
        self.transformer = MotionEncoder(cfg)
        self.head = nn.Linear(d, n_joints * 3)

    def forward(self, x, valid, trans_idx, tau, dur):
        """``x (B, T, J*3)``, ``valid (B, T)``, ``trans_idx (B, T)`` int, ``tau, dur (B, T)``.

        Returns refined ``(B, T, J*3)`` and concept spline coefficients ``(B, M, 4, J, 3)``.
        """
        if valid is None:
            valid = torch.ones(x.shape[:2], dtype=torch.bool, device=x.device)
        h = self.concept_encoder(x, valid=valid)
        onehot = torch.nn.functional.one_hot(trans_idx, self.max_transitions).to(h.dtype) * valid[..., None]
        concept = torch.einsum("btm,btd->bmd", onehot, h) / onehot.sum(1)[..., None].clamp_min(1.0)  # (B, M, D)
        coeffs = self.concept_decoder(concept).view(*concept.shape[:2], 4, self.n_joints, 3)
        w = valid.to(h.dtype)[..., None]
        bias = (self.bias_encoder(x, valid=valid) * w).sum(1) / w.sum(1).clamp_min(1.0)  # (B, D)
        per_frame = torch.gather(concept, 1, trans_idx[..., None].expand(-1, -1, concept.shape[-1]))
        z = torch.cat([per_frame, bias[:, None].expand_as(per_frame), tau[..., None], dur[..., None] / 60.0], -1)
        return x + self.head(self.transformer(z, valid=valid)), coeffs


def corrupt_transition(clip: np.ndarray, anchors, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
    """A copy of ``clip`` with one random transition jittered, frozen or pulled toward another pose."""
    out = clip.copy()
    k = int(rng.integers(len(anchors) - 1))
    a, b = int(anchors[k]), int(anchors[k + 1])
    if b - a < 2:
        return out
    inner = slice(a + 1, b)
    bump = np.sin(np.linspace(0, np.pi, b - a + 1)[1:-1])[:, None, None]
    kind = rng.integers(3)
    if kind == 0:
        out[inner] += rng.normal(scale=0.02 * scale, size=out[inner].shape).astype(np.float32)
    elif kind == 1:
        out[inner] = out[a] + (out[inner] - out[a]) * 0.2
    else:
        other = clip[int(rng.integers(len(clip)))]
        target = other - other[:1] + clip[(a + b) // 2, :1]
        out[inner] += (bump * 0.5 * scale * (target - clip[(a + b) // 2])).astype(np.float32)
    return out


class TransitionRefiner(NetworkComponent):
    """Refine transitions with concept and bias features (paper §3.2.3).

    Parameters
    ----------
    d_model, n_layers, n_heads, ffn_dim, dropout : encoder sizes (all three encoders alike)
    crop_frames : int, default=60
    max_transitions : int, default=32
        Transitions one window may hold.
    concept_weight : float, default=1.0
        λ_C in Eq. 5.
    corrupt_prob : float, default=0.5
        Share of training inputs with a corrupted transition (0 = the paper's variant).
    flaw_percentile : float, default=1.0
    schedule : TrainSchedule, default=TrainSchedule()
        Epochs, batch size, learning rate, device, ... (:class:`~refiner.nn.training.TrainSchedule`).
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : TransitionRefinementNet
    n_joints_ : int
    threshold_ : float
        Flag a transition when the refined frames differ from it by more than this (metres, MPJPE).
    history_ : list of dict
    """

    _fitted_attributes = ("n_joints_", "threshold_", "history_")

    def __init__(self, *, d_model: int = 128, n_layers: int = 2, n_heads: int = 4, ffn_dim: int = 128,
                 dropout: float = 0.1, crop_frames: int = 60, max_transitions: int = 32, concept_weight: float = 1.0,
                 corrupt_prob: float = 0.5, flaw_percentile: float = 1.0,
                 schedule: TrainSchedule = TrainSchedule(), random_state: int | None = 0):
        self.d_model = d_model
        self.n_layers = n_layers
        self.n_heads = n_heads
        self.ffn_dim = ffn_dim
        self.dropout = dropout
        self.crop_frames = crop_frames
        self.max_transitions = max_transitions
        self.concept_weight = concept_weight
        self.corrupt_prob = corrupt_prob
        self.flaw_percentile = flaw_percentile
        self.schedule = schedule
        self.random_state = random_state

    def _make_network(self, fitted: dict) -> TransitionRefinementNet:
        return TransitionRefinementNet(encoder_config(self, fitted["n_joints_"]), fitted["n_joints_"], self.max_transitions)

    def fit(self, clips, anchors, coeffs) -> "TransitionRefiner":
        """Train on real clips with their segmentation anchors and fitted spline coefficients.

        Parameters
        ----------
        clips : sequence of ndarray (T_i, J, 3)
        anchors : sequence of int arrays (K_i,)
        coeffs : sequence of ndarray (K_i - 1, 4, J, 3), the segmentation's splines
        """
        clips = [np.asarray(c, dtype=np.float32) for c in clips]
        if not clips or len(clips) != len(anchors) or len(clips) != len(coeffs):
            raise ValueError("`clips`, `anchors` and `coeffs` must be non-empty and of equal length.")
        rng = check_random_state(self.random_state)
        self.n_joints_ = int(clips[0].shape[1])
        order = rng.permutation(len(clips))
        n_val = max(1, len(clips) // 10)
        val_idx, tr_idx = order[:n_val], order[n_val:]
        schedule = self._schedule()
        device = resolve_device(schedule.device)
        splines = [[eval_spline(c[m], int(a[m + 1] - a[m]) + 1) for m in range(len(a) - 1)] for c, a in zip(coeffs, anchors)]

        def make_batch(idx, r, pool=tr_idx, corrupt=True):
            return to_device(self._batch([pool[i] for i in idx], clips, anchors, splines, r, corrupt), device)

        with seeded(rng):
            self.network_ = self._make_network({"n_joints_": self.n_joints_}).to(device)
            val_batch = make_batch(np.arange(len(val_idx)), np.random.default_rng(0), val_idx, False)
            self.history_ = fit_network(self.network_, self._loss, make_batch, len(tr_idx), val_batch,
                                        schedule, rng, desc="transition refinement")
        self.calibrate([clips[i] for i in val_idx], [anchors[i] for i in val_idx])
        return self

    def calibrate(self, clips, anchors, *, percentile: float | None = None) -> float:
        """Set ``threshold_`` to the ``100 - percentile``-th percentile (default ``flaw_percentile``) of the
        residuals of real transitions (``clips`` ``(T_i, J, 3)`` metres between their ``anchors``); returns it."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        residuals = []
        for clip, a in zip(clips, anchors):
            residuals.extend(self._refine_clip(np.asarray(clip, dtype=np.float32), a)[1])
        percentile = self.flaw_percentile if percentile is None else percentile
        self.threshold_ = float(np.percentile(residuals, 100 - percentile))
        return self.threshold_

    def _batch(self, clip_ids, clips, anchors, splines, rng, corrupt) -> dict:
        length, joints = self.crop_frames, self.n_joints_
        n = len(clip_ids)
        out = {k: np.zeros((n, length, joints, 3), np.float32) for k in ("joints", "target", "spline")}
        valid = np.zeros((n, length), bool)
        trans = np.zeros((n, length), np.int64)
        tau = np.zeros((n, length), np.float32)
        dur = np.ones((n, length), np.float32)
        for b, c in enumerate(clip_ids):
            clip, anc = clips[c], np.asarray(anchors[c])
            start = crop_start(len(clip), length, rng)
            stop = min(start + length, len(clip))
            src = corrupt_transition(clip, anc, rng) if corrupt and rng.random() < self.corrupt_prob else clip
            origin = clip[start : start + 1, :1]
            idx, t, d = transition_layout(len(clip), anc)
            sl = slice(0, stop - start)
            spline_full = np.concatenate([s[:-1] for s in splines[c][:-1]] + [splines[c][-1]])
            for key, frames in (("joints", src), ("target", clip), ("spline", spline_full)):
                put_crop(out[key], b, frames[start:stop], origin, pad=False)
            first = idx[start]
            trans[b, sl] = np.minimum(idx[start:stop] - first, self.max_transitions - 1)
            tau[b, sl], dur[b, sl] = t[start:stop], d[start:stop]
            valid[b, sl] = True
        return {**out, "valid": valid, "trans": trans, "tau": tau, "dur": dur}

    def _loss(self, net: TransitionRefinementNet, batch: dict, rng) -> torch.Tensor:
        x = batch["joints"].flatten(2)
        refined, coeffs = net(x, batch["valid"], batch["trans"], batch["tau"], batch["dur"])
        loss_s = mpjpe(refined.view_as(batch["target"]), batch["target"], batch["valid"])
        # L_C: each frame restored from its transition's decoded spline vs from the fitted spline
        per_frame = torch.gather(coeffs, 1, batch["trans"][..., None, None, None].expand(-1, -1, *coeffs.shape[2:]))
        t = batch["tau"]
        basis = torch.stack([t**3, t**2, t, torch.ones_like(t)], -1)
        restored = torch.einsum("btk,btkjc->btjc", basis, per_frame)
        loss_c = mpjpe(restored, batch["spline"], batch["valid"])
        return loss_s + self.concept_weight * loss_c

    @torch.no_grad()
    def _refine_clip(self, joints: np.ndarray, anchors) -> tuple[np.ndarray, list[float]]:
        net, device = self.network_.eval(), self.device_
        anchors = np.asarray(anchors)
        n_frames, window = len(joints), 2 * self.crop_frames
        starts = window_starts(n_frames, window, self.crop_frames)
        idx, tau, dur = transition_layout(n_frames, anchors)
        windows = []
        for s in starts:
            e = min(s + window, n_frames)
            origin = joints[s : s + 1, :1]
            x = torch.from_numpy(np.ascontiguousarray(joints[s:e] - origin)).to(device).flatten(1)[None]
            trans = torch.from_numpy(np.minimum(idx[s:e] - idx[s], self.max_transitions - 1)).to(device)[None]
            refined, _ = net(x, None, trans, torch.from_numpy(tau[s:e]).to(device)[None],
                             torch.from_numpy(dur[s:e]).to(device)[None])
            windows.append(refined.view(e - s, -1, 3).cpu().numpy() + origin)
        refined = overlap_add(np.stack(windows), starts, n_frames).astype(np.float32)
        diff = np.linalg.norm(refined - joints, axis=-1).mean(-1)
        residuals = [float(diff[anchors[m] : anchors[m + 1] + 1].mean()) for m in range(len(anchors) - 1)]
        return refined, residuals

    def refine_transitions(self, joints, anchors) -> tuple[np.ndarray, np.ndarray]:
        """The module's output for a whole clip and each transition's residual.

        Parameters
        ----------
        joints : ndarray (T, J, 3), metres
        anchors : int array (K,)

        Returns
        -------
        refined : ndarray (T, J, 3), float32
        residuals : ndarray (K - 1,)
            MPJPE (metres) between each input transition and its refined frames; above
            ``threshold_`` the transition is flagged.
        """
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        refined, residuals = self._refine_clip(np.asarray(joints, dtype=np.float32), anchors)
        return refined, np.asarray(residuals)


# Transition refinement by re-timing (``Refiner(method="concepts", transition_method="retime")``): a transition far
# from its least-squares cubic is re-timed along its own path with its transition concept's speed profile (decisions.md).
#: Upper ends (frames) of the duration bins of the thresholds: longer transitions fit a cubic less tightly.
DURATION_BINS = (8, 16, 32, 64)
#: A duration bin needs this many calibration transitions; fewer join the next bin.
_MIN_PER_BIN = 20


def spline_residual(frames: np.ndarray) -> float:
    """MPJPE (metres) between a transition's frames ``(L, J, 3)`` and their least-squares cubic."""
    return float(np.linalg.norm(eval_spline(fit_spline(frames), len(frames)) - frames, axis=-1).mean())


class TransitionRetimer:
    """The re-timing transition step: flags by spline residual, proposes a re-timed transition.

    Attributes
    ----------
    thresholds_ : list of [frames, metres]
        Per duration bin, its upper end and the residual above which a transition that long is
        flagged (ascending; the last bin is open). Empty: nothing is flagged. Set by :meth:`calibrate`,
        or from a saved refiner's manifest (:meth:`from_calibration`).
    """

    def __init__(self):
        self.thresholds_: list[list[float]] = []

    @classmethod
    def from_calibration(cls, calibration: dict) -> "TransitionRetimer":
        """The step as a manifest's ``calibration`` entry describes it: ``transition_thresholds`` (bins) or
        ``transition_threshold`` (one value for every duration, set by hand)."""
        step = cls()
        if "transition_threshold" in calibration:
            step.thresholds_ = [[float("inf"), float(calibration["transition_threshold"])]]
        else:
            step.thresholds_ = [[float(u), float(t)] for u, t in calibration.get("transition_thresholds", [])]
        return step

    def to_calibration(self) -> dict:
        """The ``calibration`` entry of a manifest that :meth:`from_calibration` reads back."""
        return {"transition_thresholds": [list(b) for b in self.thresholds_]}

    def calibrate(self, clips, anchors, *, percentile: float = 1.0) -> list[list[float]]:
        """Per duration bin, the ``100 - percentile``-th percentile of the residuals of real transitions
        (``clips`` ``(T_i, J, 3)`` metres between their ``anchors``); returns ``thresholds_``."""
        durations, residuals = [], []
        for clip, a in zip(clips, anchors):
            x = np.asarray(clip, dtype=np.float32)
            durations.extend(np.diff(a))
            residuals.extend(spline_residual(x[a[m] : a[m + 1] + 1]) for m in range(len(a) - 1))
        durations, residuals = np.asarray(durations), np.asarray(residuals)
        bins = []
        lower = 0
        for upper in (*DURATION_BINS, np.inf):
            sel = (durations > lower) & (durations <= upper)
            if sel.sum() >= _MIN_PER_BIN or (upper == np.inf and sel.any()):
                bins.append([float(upper), float(np.percentile(residuals[sel], 100 - percentile))])
                lower = upper
        if bins:
            bins[-1][0] = float("inf")
        self.thresholds_ = bins
        return bins

    def threshold(self, duration: int) -> float:
        """The residual threshold (metres) of a transition of ``duration`` frame intervals."""
        for upper, value in self.thresholds_:
            if duration <= upper:
                return float(value)
        return float("inf")

    def detect(self, joints: np.ndarray, anchors) -> tuple[np.ndarray, np.ndarray]:
        """Residuals and thresholds ``(K - 1,)`` (metres) of the transitions of ``joints (T, J, 3)``
        between its ``anchors (K,)``; a transition is flagged where the residual is above its threshold."""
        residuals = np.array([spline_residual(joints[anchors[m] : anchors[m + 1] + 1]) for m in range(len(anchors) - 1)])
        return residuals, np.array([self.threshold(int(d)) for d in np.diff(anchors)])

    def propose(self, joints: np.ndarray, a: int, b: int, generator) -> np.ndarray:
        """``joints`` with the transition between anchor frames ``a`` and ``b`` re-timed along its own path
        with the speed profile of the transition ``generator`` (a fitted TransitionGenerator) gives them."""
        concept = generator.generate(joints[a][None], joints[b][None], [b - a])[0]
        proposal = joints.copy()
        proposal[a : b + 1] = retime(joints[a : b + 1], arc_length_profile(concept))
        return proposal
