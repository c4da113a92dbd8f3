"""Texture filter: a temporal convolution that takes a generator's texture off whole clips.

A generator's clips are off real motion a little everywhere, not in runs that stand out: the a2m
reference generator's joints accelerate three times as hard as mocap's, and the flaw steps, which change
what stands out from the rest of its clip, leave most of that. :class:`TextureFilterNet` reads a whole clip,
turned to its mean heading and centred on its mean, through dilated residual 1-D convolutions (receptive
field 41 frames, 2 s at 20 fps; 0.27 M parameters, 0.55 MB a weight set) and returns a correction of every
frame; :class:`TextureFilter` trains it on real clips given white noise of a random, unknown level (over
the crop or a window of it, or none), so it learns what real motion looks like under any roughness (12,000
steps, 28 minutes on one CPU core). The step (:func:`filtered_texture`, last) applies it three times, then the
noise filter (the passes leave some roughness of their own), then puts the clip back on rigid bones (the
network bends them: 8.5 % bone-length variation on a2m's clips), then, on clips known to be a generator's,
the pose prior (:func:`~refiner.refinement.pose_prior.prior_posed`) at the drift threshold: the frames it would
move further than half of held-out clean frames.

It cannot tell a person it never saw from a rough clip (on clean held-out clips it moves joints 0.37 cm,
against the 0.3 cm the refiner may move them), so it runs where the clip is known or found to be a
generator's: ``Refiner(texture="all")``, what :class:`~refiner.refinement.refined_generator.RefinedGenerator`
and ``motion-refiner refine --adapter`` use (every clip is generated). ``refine()`` leaves it off by default:
the option ``"auto"`` (the clips the noise step found noisy throughout) took 1.8 % of clean held-out clips and
moved those 1.2 cm, and cost ``bench flaws`` 5 points on transition jitter (30.8 -> 25.8 %; mean 28.6 ->
27.8 %). No gate on the clip did better than every clip on generator output (same samples as below): the
noise step's level above 0 or above real clips' 90th percentile, or acceleration above mocap's 6.5 m/s², kept
actor's FID at 4.22-4.26 but gave back most of a2m-large's and mdm's gain (1.030-1.050, 1.336-1.339).
Chosen on 600 samples per reference
generator drawn with seeds the benchmark does not use (5 replications; FID after the rest of the refiner
-> with two passes): a2m 3.966 -> 3.573 (generated 4.461; acceleration 16.9 -> 13.1 m/s², accuracy 41.2 ->
42.2 %), a2m-large 1.076 -> 1.022, mdm 1.337 -> 1.321, actor-large 1.056 -> 1.055, actor 4.209 -> 4.278
(worse: its clips are smoother than mocap); three passes: a2m 3.492, a2m-large 1.011, the others within
0.5 %; three and the pose prior after them: a2m 3.393, a2m-large 1.006, actor 4.288 (the prior twice: 3.361;
before the texture filter it could not be run on every clip: about half the frames of every clean clip
move). Uncapped passes: one 3.675, three 3.418, four 3.267 but acceleration 25 m/s², six run away (README,
table of choices).
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from refiner.core.rotations import rotvec_to_rotmat
from refiner.core.skeletons import get_skeleton, rigid_skeleton
from refiner.core.validation import check_is_fitted, check_joint_batch, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.training import TrainSchedule
from refiner.refinement.pose_prior import body_frame, prior_posed

__all__ = ["TextureFilter", "TextureFilterNet", "filtered_texture"]

#: Coordinates are fed and read at this many times metres (decimetres: unit-sized inputs).
_SCALE = 10.0


class TextureFilterNet(nn.Module):
    """Joints ``(B, T, J, 3)`` metres -> corrections ``(B, T, J, 3)`` metres: dilated residual 1-D convolutions
    over the clip in one frame for the clip, its joints' mean and its mean heading (:func:`body_frame`)."""

    def __init__(self, n_joints: int, skeleton: str, channels: int = 96, kernel: int = 5,
                 dilations: tuple = (1, 2, 4, 2, 1)):
        super().__init__()
        self.skeleton = skeleton
        self.inp = nn.Conv1d(3 * n_joints, channels, kernel, padding=kernel // 2)
        self.blocks = nn.ModuleList([nn.Conv1d(channels, channels, kernel, padding=d * (kernel // 2), dilation=d,
                                               padding_mode="replicate") for d in dilations])
        self.out = nn.Conv1d(channels, 3 * n_joints, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        _, axes = body_frame(x, self.skeleton)
        centre = x.mean((1, 2), keepdim=True)
        u, _, vh = torch.linalg.svd(axes.mean(1, keepdim=True))  # the orthogonal matrix nearest the mean heading
        frame = u @ vh  # (body_frame's axes are left-handed: a fixed mirror, undone on the way back)
        h = torch.einsum("btjc,bskc->btjk", x - centre, frame).flatten(2).transpose(1, 2) * _SCALE
        h = F.gelu(self.inp(h))
        for block in self.blocks:
            h = h + F.gelu(block(h))
        c = self.out(h).transpose(1, 2).reshape(x.shape) / _SCALE
        return torch.einsum("btjk,bskc->btjc", c, frame)


class TextureFilter(NetworkComponent):
    """Learned texture filter: the correction that takes every frame of a rough clip back to real motion.

    Parameters
    ----------
    channels, kernel : int, default=96, 5
        Width and kernel of the convolutions.
    dilations : tuple of int, default=(1, 2, 4, 2, 1)
        One residual block per dilation.
    max_noise : float, default=0.03
        Metres: the largest standard deviation of the white noise given to training crops.
    clean_probability : float, default=0.2
        Share of training crops left clean.
    rotation_share : float, default=0.0
        Share of the spoiled training crops given jitter of their bones' directions instead of white noise of the
        joints (a generator that decodes rotations jitters so: a turned bone carries its whole limb along).
    max_rotation : float, default=0.02
        Radians: the largest standard deviation of that jitter, per axis and frame.
    crop : int, default=48
        Training crop length.
    passes : int, default=3
        Times :meth:`filtered` applies the network (each pass takes part of the texture off; more than three passes
        run away from real motion).
    max_correction : float, default=0.1
        Metres: the longest step one pass may move a joint (a clip far from anything in training can draw a
        correction of metres; real noise of ``max_noise`` asks for under 0.1).
    schedule : TrainSchedule
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : TextureFilterNet
    skeleton_, n_joints_ : str, int
    history_ : list of dict
    """

    _fitted_attributes = ("skeleton_", "n_joints_", "history_")

    def __init__(self, *, channels: int = 96, kernel: int = 5, dilations: tuple = (1, 2, 4, 2, 1),
                 max_noise: float = 0.03, clean_probability: float = 0.2, rotation_share: float = 0.0,
                 max_rotation: float = 0.02, crop: int = 48, passes: int = 3, max_correction: float = 0.1,
                 schedule: TrainSchedule = TrainSchedule(n_epochs=24, batch_size=64, learning_rate=1e-3, patience=24,
                                                         steps_per_epoch=500),
                 random_state: int | None = 0):
        self.channels = channels
        self.kernel = kernel
        self.dilations = dilations
        self.max_noise = max_noise
        self.clean_probability = clean_probability
        self.rotation_share = rotation_share
        self.max_rotation = max_rotation
        self.crop = crop
        self.passes = passes
        self.max_correction = max_correction
        self.schedule = schedule
        self.random_state = random_state

    def _make_network(self, fitted: dict) -> TextureFilterNet:
        return TextureFilterNet(fitted["n_joints_"], fitted["skeleton_"], self.channels, self.kernel,
                                tuple(self.dilations))

    def _rough(self, crops: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Crops ``(N, L, J, 3)`` with white noise of a random level over the crop or a random window of it: of the
        joints, or (``rotation_share`` of the crops) of their bones' directions."""
        n, length = crops.shape[:2]
        spoiled = rng.random((n, 1, 1, 1)) >= self.clean_probability
        level = rng.uniform(0.0, 1.0, (n, 1, 1, 1)) * spoiled
        start, span = rng.uniform(-0.5, 1.0, (n, 1)) * length, rng.uniform(5, 2 * length, (n, 1))
        ramp = np.sin(np.pi * np.clip((np.arange(length) - start) / span, 0, 1))
        ramp = np.where(rng.random((n, 1)) < 0.5, ramp, 1.0)[..., None, None]
        out = crops + self.max_noise * level * ramp * rng.normal(size=crops.shape)
        turned = rng.random(n) < self.rotation_share
        if turned.any():
            out[turned] = _turned_bones(crops[turned], self.max_rotation * level[turned] * ramp[turned], self.skeleton_, rng)
        return out.astype(np.float32)

    def fit(self, clips, *, skeleton: str = "humanact12", validation=None, checkpoint=None) -> "TextureFilter":
        """Train on real clips ``(T_i, J, 3)`` metres (T_i >= 2); ``validation``: held-out clips."""
        rng = check_random_state(self.random_state)
        clips = [np.asarray(c, np.float32) for c in clips]
        if not clips or any(c.ndim != 3 or c.shape[-1] != 3 or len(c) < 2 for c in clips):
            raise ValueError("`clips` must be a non-empty list of (T >= 2, J, 3) arrays.")
        if (not 0 <= self.clean_probability < 1 or self.max_noise <= 0 or self.crop < 2 or int(self.passes) < 1
                or self.max_correction <= 0 or not 0 <= self.rotation_share <= 1 or self.max_rotation < 0):
            raise ValueError("need 0 <= clean_probability < 1, max_noise > 0, crop >= 2, passes >= 1, max_correction > 0, "
                             "0 <= rotation_share <= 1 and max_rotation >= 0.")
        self.skeleton_ = get_skeleton(skeleton).name
        self.n_joints_ = int(clips[0].shape[1])
        self._fit_on_crops(clips, validation, self._rough, _loss, rng, checkpoint=checkpoint, desc="texture filter")
        return self

    @torch.no_grad()
    def filtered(self, joints) -> np.ndarray:
        """A batch ``(B, T, J, 3)`` metres with every frame corrected ``passes`` times (each step of a joint cut to
        ``max_correction``); float32."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        x = torch.from_numpy(check_joint_batch(joints, self.n_joints_)).to(self.device_)
        for _ in range(int(self.passes)):
            step = self.network_(x)
            size = step.norm(dim=-1, keepdim=True)
            x = x + step * (self.max_correction / size.clamp_min(self.max_correction))
        return x.cpu().numpy().astype(np.float32)


def _turned_bones(joints: np.ndarray, sigma: np.ndarray, skeleton: str, rng: np.random.Generator) -> np.ndarray:
    """Joints ``(N, L, J, 3)`` metres rebuilt from the root outward with every joint's rotation jittered by a random
    turn of ``sigma`` (broadcast to ``(N, L, 1, 1)``) radians per axis, as a generator of local rotations jitters:
    bone lengths kept, each turn carried to the joint's whole subtree."""
    parents = get_skeleton(skeleton).parents
    turns = rotvec_to_rotmat(sigma * rng.normal(size=joints.shape))  # (N, L, J, 3, 3)
    carried = turns.copy()  # each joint's turn composed with its ancestors'
    out = joints.copy()
    for j, p in enumerate(parents):
        if p >= 0:  # parents come before their children
            carried[:, :, j] = carried[:, :, p] @ turns[:, :, j]
            out[:, :, j] = out[:, :, p] + np.einsum("nlab,nlb->nla", carried[:, :, p], joints[:, :, j] - joints[:, :, p])
    return out


def _loss(net, batch, rng) -> torch.Tensor:
    """Mean squared distance (m²) of the corrected joints from the clean ones."""
    return ((batch["flawed"] + net(batch["flawed"]) - batch["clean"]) ** 2).sum(-1).mean()


def filtered_texture(refiner, clips: np.ndarray, reports: list, noisy: np.ndarray | None) -> np.ndarray:
    """The texture step, last: the clips of ``clips (B, T, J, 3)`` that ``refiner.texture`` names (``"all"``: every
    one; ``"auto"``: the ``noisy (B,)`` ones, found noisy throughout by the noise step) through the refiner's
    ``texture_filter`` (:meth:`TextureFilter.filtered`), the others as given. One report entry (step ``"texture"``)
    per clip filtered."""
    part, texture = getattr(refiner, "texture_filter", None), getattr(refiner, "texture", "off")
    todo = np.ones(len(clips), bool) if texture == "all" else (
        np.zeros(len(clips), bool) if texture == "off" or noisy is None else np.asarray(noisy, bool))
    if part is None or not todo.any():
        return clips
    out = clips.copy()
    y = part.filtered(clips[todo])
    noise = getattr(refiner, "noise_filter", None)
    if noise is not None:  # the filter's passes leave some roughness of their own
        y = noise.denoise(y)
    proportions = refiner.bone_proportions if getattr(refiner, "rigid_lengths", None) == "proportions" else None
    out[todo] = rigid_skeleton(y, refiner.skeleton, 0.0, proportions=proportions)[0]  # it bends bones (a2m: 8.5 %)
    why = ("the clips are a generator's (texture='all')" if texture == "all" else
           "the clip is noisy throughout (a generator's texture)")
    for b in np.flatnonzero(todo):
        moved = 100 * float(np.linalg.norm(out[b] - clips[b], axis=-1).mean())
        reports[b].changes.append({"start": 0, "stop": int(clips.shape[1]), "step": "texture", "repair": "texture_filter",
                                   "reason": f"{why}: every frame filtered by the texture filter ({int(part.passes)} "
                                             f"passes{', then the noise filter' if noise is not None else ''}) and put "
                                             f"back on rigid bones (moved {moved:.2f} cm on average)"})
    if texture == "all":  # known to be a generator's: the poses the filter left off real motion, as a drift's
        out = prior_posed(refiner, out, reports, np.zeros(len(out), bool), generated=todo)
    return out
