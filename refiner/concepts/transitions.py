"""Transition concepts (paper §3.1.3): transition data and the CVAE transition generator.

A :class:`TransitionSet` holds every spline transition of a dataset with its end anchors,
duration, coefficients, action and real frames. :class:`TransitionGenerator` is the CVAE that,
given two anchors and a duration, generates spline parameters: the transition concepts.

Representation: everything is relative to the start anchor's root. The spline's constant term
``d`` is the start anchor itself, so the CVAE generates ``a, b, c`` only and every generated
transition starts exactly at its start anchor; ``L_A`` pulls ``a + b + c + d`` to the end anchor.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, fields
from typing import Sequence

import numpy as np
import torch
from torch import nn

from refiner.concepts.segmentation import Segmentation
from refiner.core.serialization import load_state, save_state
from refiner.core.signal import pace
from refiner.core.validation import check_is_fitted, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.layers import MLP, mpjpe
from refiner.nn.training import TrainSchedule, fit_network, resolve_device, seeded

__all__ = ["TransitionSet", "collect_transitions", "TransitionCVAEConfig", "TransitionCVAE", "TransitionGenerator",
           "spline_frames", "arc_length_profile", "retime"]

#: Duration scale of the condition (frames); transitions are mostly under 60 frames.
_DURATION_SCALE = 60.0


@dataclass(frozen=True)
class TransitionSet:
    """All transitions of a set of clips, flat arrays of N transitions.

    Attributes
    ----------
    start, end : ndarray of shape (N, J, 3), float32
        Anchor poses at both ends, metres, in the clip's frame.
    durations : ndarray of int, shape (N,)
        Frame intervals (the transition covers ``duration + 1`` frames).
    coeffs : ndarray of shape (N, 4, J, 3), float32
        Fitted spline coefficients (``refiner.concepts.splines`` convention).
    actions, clips, start_frames : ndarray of int, shape (N,)
        Action label, source clip index and first frame of each transition.
    frames : ndarray of shape (F, J, 3), float32
        Real frames of all transitions, concatenated; transition i is
        ``frames[offsets[i]:offsets[i + 1]]`` (``durations[i] + 1`` frames).
    offsets : ndarray of int, shape (N + 1,)
    """

    start: np.ndarray
    end: np.ndarray
    durations: np.ndarray
    coeffs: np.ndarray
    actions: np.ndarray
    clips: np.ndarray
    start_frames: np.ndarray
    frames: np.ndarray
    offsets: np.ndarray

    def __len__(self) -> int:
        return len(self.durations)

    def transition_frames(self, i: int) -> np.ndarray:
        """Real frames ``(duration + 1, J, 3)`` of transition ``i``."""
        return self.frames[self.offsets[i] : self.offsets[i + 1]]

    def subset(self, indices) -> "TransitionSet":
        idx = np.asarray(indices, dtype=np.int64)
        pieces = [self.transition_frames(i) for i in idx]
        lengths = np.array([len(p) for p in pieces], dtype=np.int64)
        frames = np.concatenate(pieces) if pieces else self.frames[:0]
        return TransitionSet(
            self.start[idx], self.end[idx], self.durations[idx], self.coeffs[idx], self.actions[idx],
            self.clips[idx], self.start_frames[idx], frames, np.concatenate([[0], np.cumsum(lengths)]),
        )

    def save(self, path: str | os.PathLike) -> None:
        save_state(path, {f.name: getattr(self, f.name) for f in fields(self)}, {"refiner.class": "TransitionSet"})

    @classmethod
    def load(cls, path: str | os.PathLike) -> "TransitionSet":
        tensors, metadata = load_state(path)
        if metadata.get("refiner.class") != "TransitionSet":
            raise ValueError(f"{str(path)!r} holds a {metadata.get('refiner.class')!r}, expected a 'TransitionSet'.")
        return cls(**{f.name: tensors[f.name] for f in fields(cls)})


def collect_transitions(
    clips: Sequence[np.ndarray], segmentations: Sequence[Segmentation], actions: Sequence[int]
) -> TransitionSet:
    """Gather the transitions of segmented clips.

    Parameters
    ----------
    clips : sequence of ndarray (T_i, J, 3)
    segmentations : sequence of Segmentation, one per clip
    actions : sequence of int, one per clip
    """
    if not (len(clips) == len(segmentations) == len(actions)):
        raise ValueError(
            f"need one segmentation and action per clip; got {len(clips)} clips, "
            f"{len(segmentations)} segmentations, {len(actions)} actions."
        )
    start, end, durations, coeffs, acts, clip_ids, starts, frames = [], [], [], [], [], [], [], []
    for c, (clip, seg, action) in enumerate(zip(clips, segmentations, actions)):
        clip = np.asarray(clip, dtype=np.float32)
        if seg.n_frames != len(clip):
            raise ValueError(f"clip {c}: segmentation covers {seg.n_frames} frames, the clip has {len(clip)}.")
        k, n = seg.anchors[:-1], seg.anchors[1:]
        start.append(clip[k])
        end.append(clip[n])
        durations.append(n - k)
        coeffs.append(seg.coeffs)
        acts.append(np.full(len(k), int(action)))
        clip_ids.append(np.full(len(k), c))
        starts.append(k)
        frames.extend(clip[a : b + 1] for a, b in zip(k, n))
    durations = np.concatenate(durations).astype(np.int64)
    return TransitionSet(
        start=np.concatenate(start),
        end=np.concatenate(end),
        durations=durations,
        coeffs=np.concatenate(coeffs).astype(np.float32),
        actions=np.concatenate(acts).astype(np.int64),
        clips=np.concatenate(clip_ids).astype(np.int64),
        start_frames=np.concatenate(starts).astype(np.int64),
        frames=np.concatenate(frames).astype(np.float32),
        offsets=np.concatenate([[0], np.cumsum(durations + 1)]).astype(np.int64),
    )


def spline_frames(coeffs: torch.Tensor, durations: torch.Tensor, n_frames: int) -> torch.Tensor:
    """Frames of a batch of transitions of different lengths.

    ``coeffs (B, 4, J, 3)``, ``durations (B,)`` -> ``(B, n_frames, J, 3)``: frame ``i`` is the spline
    at ``tau = i / duration`` (values past ``tau = 1`` are extrapolations; mask them).
    """
    i = torch.arange(n_frames, device=coeffs.device, dtype=coeffs.dtype)
    tau = i[None] / durations[:, None].to(coeffs.dtype)
    basis = torch.stack([tau**3, tau**2, tau, torch.ones_like(tau)], dim=-1)  # (B, L, 4)
    return torch.einsum("blk,bkjc->bljc", basis, coeffs)


@dataclass
class TransitionCVAEConfig:
    n_joints: int = 24
    latent_dim: int = 32
    hidden: int = 256


class TransitionCVAE(nn.Module):
    """CVAE over spline parameters ``(a, b, c)`` conditioned on both end anchors and the duration."""

    def __init__(self, config: TransitionCVAEConfig):
        super().__init__()
        self.config = config
        pose = config.n_joints * 3
        cond = 2 * pose + 1
        self.encoder = MLP(3 * pose + cond, 2 * config.latent_dim, config.hidden)
        self.decoder = MLP(config.latent_dim + cond, 3 * pose, config.hidden)

    def condition(self, start: torch.Tensor, end: torch.Tensor, durations: torch.Tensor) -> torch.Tensor:
        """``start, end (B, J, 3)`` root-relative to the start root, ``durations (B,)`` -> ``(B, 2*J*3+1)``."""
        return torch.cat([start.flatten(1), end.flatten(1), durations[:, None] / _DURATION_SCALE], dim=1)

    def encode(self, abc: torch.Tensor, cond: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mu, logvar = self.encoder(torch.cat([abc.flatten(1), cond], 1)).chunk(2, dim=1)
        return mu, logvar.clamp(-10, 10)

    def decode(self, z: torch.Tensor, cond: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
        """Full coefficients ``(B, 4, J, 3)``: generated ``a, b, c`` and ``d = start``."""
        abc = self.decoder(torch.cat([z, cond], 1)).view(-1, 3, *start.shape[1:])
        return torch.cat([abc, start[:, None]], dim=1)


class TransitionGenerator(NetworkComponent):
    """CVAE transition generator: samples transition concepts between two anchors.

    Paper §3.1.3; loss ``L_T + anchor_weight * L_A + kl_weight * L_KL`` (Eq. 3).

    Parameters
    ----------
    latent_dim : int, default=32
    hidden : int, default=256
    anchor_weight : float, default=0.5
        λ_A in Eq. 3.
    kl_weight : float, default=1e-4
        λ_KL in Eq. 3.
    max_frames : int, default=120
        Longest transition used for training (longer ones are skipped).
    schedule : TrainSchedule, default=TrainSchedule(n_epochs=300, patience=20)
        Epochs, batch size, learning rate, device, ... (:class:`~refiner.nn.training.TrainSchedule`).
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : TransitionCVAE
    n_joints_ : int
    history_ : list of dict
    """

    _fitted_attributes = ("n_joints_", "history_")

    def __init__(self, latent_dim: int = 32, *, hidden: int = 256, anchor_weight: float = 0.5, kl_weight: float = 1e-4,
                 max_frames: int = 120, schedule: TrainSchedule = TrainSchedule(n_epochs=300, patience=20),
                 random_state: int | None = 0):
        self.latent_dim = latent_dim
        self.hidden = hidden
        self.anchor_weight = anchor_weight
        self.kl_weight = kl_weight
        self.max_frames = max_frames
        self.schedule = schedule
        self.random_state = random_state

    def _make_network(self, fitted: dict) -> TransitionCVAE:
        return TransitionCVAE(TransitionCVAEConfig(fitted["n_joints_"], self.latent_dim, self.hidden))

    def fit(self, transitions: TransitionSet, *, validation: TransitionSet | None = None) -> "TransitionGenerator":
        """Train on real transitions (a :class:`TransitionSet`)."""
        if not isinstance(transitions, TransitionSet) or len(transitions) == 0:
            raise ValueError("`transitions` must be a non-empty TransitionSet.")
        rng = check_random_state(self.random_state)
        schedule = self._schedule()
        device = resolve_device(schedule.device)
        keep = np.flatnonzero(transitions.durations <= self.max_frames)
        train = transitions.subset(keep)
        if validation is None:
            order = rng.permutation(len(train))
            n_val = max(1, len(train) // 10)
            validation, train = train.subset(order[:n_val]), train.subset(order[n_val:])
        self.n_joints_ = int(transitions.start.shape[1])
        with seeded(rng):
            self.network_ = self._make_network({"n_joints_": self.n_joints_}).to(device)
            arrays = _transition_arrays(train, self.max_frames)
            val = _transition_batch(_transition_arrays(validation, self.max_frames), np.arange(len(validation)), device)
            self.history_ = fit_network(
                self.network_, self._loss, lambda idx, r: _transition_batch(arrays, idx, device), len(train), val,
                schedule, rng, desc="transition CVAE",
            )
        return self

    def _loss(self, net: TransitionCVAE, batch: dict, rng) -> torch.Tensor:
        start, end, dur, frames, valid, coeffs = (batch[k] for k in ("start", "end", "durations", "frames", "valid", "coeffs"))
        cond = net.condition(start, end, dur)
        mu, logvar = net.encode(coeffs[:, :3], cond)
        z = mu + torch.randn_like(mu) * torch.exp(0.5 * logvar) if net.training else mu
        full = net.decode(z, cond, start)
        restored = spline_frames(full, dur, frames.shape[1])
        loss_t = mpjpe(restored, frames, valid)
        loss_a = mpjpe(full.sum(1), end)
        kl = -0.5 * torch.mean(torch.sum(1 + logvar - mu**2 - logvar.exp(), dim=1))
        return loss_t + self.anchor_weight * loss_a + self.kl_weight * kl

    @torch.no_grad()
    def generate(self, start, end, durations, *, sample: bool = False, random_state=None, exact_end: bool = True) -> list[np.ndarray]:
        """Transitions between anchor pairs.

        Parameters
        ----------
        start, end : array-like of shape (N, J, 3)
            Anchor poses in metres, in one frame (any translation).
        durations : array-like of int, shape (N,)
            Frame intervals; transition i has ``durations[i] + 1`` frames.
        sample : bool, default=False
            Draw the latent from the prior; False uses its mean (deterministic).
        exact_end : bool, default=True
            Add a linear correction so the last frame equals ``end`` exactly.

        Returns
        -------
        list of ndarray (durations[i] + 1, J, 3), float32, metres, starting exactly at ``start``.
        """
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        start = np.asarray(start, dtype=np.float32)
        end = np.asarray(end, dtype=np.float32)
        durations = np.asarray(durations, dtype=np.int64)
        if start.shape != end.shape or start.ndim != 3 or start.shape[1:] != (self.n_joints_, 3) or durations.shape != (len(start),):
            raise ValueError(f"`start`/`end` must be (N, {self.n_joints_}, 3) and `durations` (N,); "
                             f"got {start.shape}, {end.shape}, {durations.shape}.")
        if (durations < 1).any():
            raise ValueError(f"`durations` must be >= 1; got {durations.min()}.")
        net, device = self.network_.eval(), self.device_
        root = start[:, :1]
        s = torch.tensor(start - root, device=device)
        e = torch.tensor(end - root, device=device)
        d = torch.tensor(durations, device=device, dtype=torch.float32)
        cond = net.condition(s, e, d)
        if sample:
            g = torch.Generator(device="cpu").manual_seed(int(check_random_state(random_state).integers(2**31)))
            z = torch.randn(len(s), self.latent_dim, generator=g).to(device)
        else:
            z = torch.zeros(len(s), self.latent_dim, device=device)
        coeffs = net.decode(z, cond, s)
        frames = spline_frames(coeffs, d, int(durations.max()) + 1).cpu().numpy()
        out = []
        for i, n in enumerate(durations):
            f = frames[i, : n + 1] + root[i]
            if exact_end:
                tau = np.linspace(0.0, 1.0, n + 1, dtype=np.float32)[:, None, None]
                f = f + tau * (end[i] - f[-1])
            out.append(f.astype(np.float32))
        return out


def _transition_arrays(t: TransitionSet, max_frames: int) -> dict:
    """Root-relative padded arrays of a TransitionSet for fast batching."""
    root = t.start[:, :1]
    n, length = len(t), int(min(t.durations.max(), max_frames)) + 1
    frames = np.zeros((n, length) + t.start.shape[1:], dtype=np.float32)
    valid = np.zeros((n, length), dtype=bool)
    for i in range(n):
        f = t.transition_frames(i)[:length] - root[i]
        frames[i, : len(f)] = f
        valid[i, : len(f)] = True
    coeffs = t.coeffs.copy()
    coeffs[:, 3] -= root  # d is a position: re-centre it like the frames; a, b, c are offsets
    return {"start": t.start - root, "end": t.end - root, "durations": t.durations.astype(np.float32),
            "frames": frames, "valid": valid, "coeffs": coeffs}


def _transition_batch(arrays: dict, idx, device) -> dict:
    idx = np.asarray(idx)
    length = int(arrays["durations"][idx].max()) + 1
    out = {}
    for k, v in arrays.items():
        sel = v[idx][:, :length] if k in ("frames", "valid") else v[idx]
        out[k] = torch.from_numpy(np.ascontiguousarray(sel)).to(device)
    return out


def arc_length_profile(frames: np.ndarray) -> np.ndarray:
    """Cumulative mean-joint path length of ``(L, J, 3)`` frames, normalised to end at 1, ``(L,)``."""
    s = np.concatenate([[0.0], np.cumsum(pace(frames)[1:])])
    return s / s[-1] if s[-1] > 1e-9 else np.linspace(0.0, 1.0, len(frames))


def retime(frames: np.ndarray, profile: np.ndarray) -> np.ndarray:
    """Move along the path of ``frames`` ``(L, J, 3)`` with the speed profile ``profile`` ``(L,)``.

    ``profile`` is the share of the path covered at each frame (0 -> 1, non-decreasing), for
    example :func:`arc_length_profile` of a transition concept. Ends are kept exactly; the path
    is linearly interpolated between frames.
    """
    s = arc_length_profile(frames)
    if s[-1] - s[0] < 1e-9:
        return frames.copy()
    idx = np.interp(np.clip(profile, 0.0, 1.0), s, np.arange(len(frames)))
    lo = np.floor(idx).astype(np.int64)
    hi = np.minimum(lo + 1, len(frames) - 1)
    w = (idx - lo)[:, None, None]
    out = frames[lo] * (1 - w) + frames[hi] * w
    out[0], out[-1] = frames[0], frames[-1]
    return out.astype(frames.dtype)
