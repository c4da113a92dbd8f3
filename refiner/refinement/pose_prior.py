"""Pose prior: a network that knows how real bodies hold together, for clips whose skeleton drifts.

Joints that drift keep the motion smooth, so the flaw classifier, which reads kinematic evidence,
barely sees them (ROC AUC 0.42 on the benchmark's anchor drift), and the rigid-skeleton step only
restores bone lengths, and from the drifted frames at that (13.7 % of drift's added error removed).
What is left is a pose no body holds. :class:`PosePriorNet` reads a frame's pose and four neighbours
(:data:`OFFSETS`), turned to the body's own heading and centred on the joints' mean, and returns the
correction that takes the frame back to real motion; :class:`PosePrior` trains it on real clips given
random slow offsets of all or some joints (over the crop or a window of it), white noise, or nothing,
after the rigid-skeleton step as the refiner shows them.

It cannot tell a person it never saw from a flaw: on clean clips of held-out subjects its correction
averages 0.67 cm, on the drifted ones not much more, so no threshold on it alone separates them
(gated at the 3 % of clean clips' largest corrections, every clip judged: anchor drift 12.6 -> 14.6 %,
7 % of clean clips touched). The clip decides instead. The step (:func:`prior_posed`, last in the
learned refiner) runs where most bones vary in length, slowly and throughout the clip, as drifting
joints make them (:func:`drifting_skeleton`, on the input; real mocap has rigid bones): frames whose
correction passes ``threshold_`` (the median of held-out clean frames', :meth:`PosePrior.calibrate`) are
corrected, in full from ``fade`` times it, and the clip goes back on rigid bones of the *corrected*
frames' lengths, truer than the drifted ones (put back on the drifted clip's lengths, the same
corrections left 5.6 % of drift removed, not 33 %). It also runs on clips the noise step found noisy
throughout (a generator's texture, judged against held-out clean clips), past the higher
``texture_threshold_`` (their 95th percentile): there it takes the a2m reference generator's FID from 4.10
to 3.71 (600 samples). Calibration subjects 9-10, severity 2: anchor drift 12.6 -> 33.3 % (33.2 % before the texture step), jitter 28.5 ->
28.4 %, every other family and the clean clips unchanged (README, table of choices).
"""
from __future__ import annotations

import math

import numpy as np
import torch
from scipy.ndimage import label, uniform_filter1d
from torch import nn

from refiner.core.skeletons import bone_lengths, get_skeleton, rigid_skeleton
from refiner.core.validation import check_is_fitted, check_joint_batch, check_random_state
from refiner.nn.components import NOT_FITTED, NetworkComponent
from refiner.nn.training import TrainSchedule

__all__ = ["PosePrior", "PosePriorNet", "body_frame", "drifting_skeleton", "prior_posed", "OFFSETS", "DRIFT_AUTOCORRELATION",
           "DRIFT_SHARE", "DRIFT_OFF", "DRIFT_BONES"]

#: Frames, relative to the frame corrected, whose poses the network reads.
OFFSETS = (-6, -3, 0, 3, 6)
#: A clip's skeleton drifts (:func:`drifting_skeleton`) where its varying bones keep their deviation from frame to frame
#: (lag-1 autocorrelation) and are off their median by ``DRIFT_OFF`` metres in this share of the frames.
DRIFT_AUTOCORRELATION, DRIFT_SHARE, DRIFT_OFF = 0.8, 0.65, 0.005
#: ... and where at least this share of its bones vary in length by more than the rigid-skeleton step's tolerance: one
#: stretching bone (a limb displaced whole) is the rigid step's to fix, the prior's correction of the rest costs more.
DRIFT_BONES = 0.5
#: Coordinates are fed and read at this many times metres (decimetres: unit-sized inputs).
_SCALE = 10.0


def body_frame(x: torch.Tensor, skeleton: str) -> tuple[torch.Tensor, torch.Tensor]:
    """Each frame's body frame: ``x (B, T, J, 3)`` metres -> ``(centre (B, T, 1, 3), axes (B, T, 3, 3))``.

    The centre is the joints' mean (a slow offset of single joints moves it least); the axes, rows, are the
    hip line's heading in the horizontal plane, up, and the horizontal axis across them, so that
    ``(x - centre) @ axes.T`` reads every pose facing one way."""
    skel = get_skeleton(skeleton)
    up = torch.as_tensor(skel.up_vector, dtype=x.dtype)
    ahead = torch.as_tensor(skel.forward_vector, dtype=x.dtype)
    side = torch.linalg.cross(up, ahead)
    hips = x[:, :, skel.index("left_hip")] - x[:, :, skel.index("right_hip")]
    angle = torch.atan2(hips @ side, hips @ ahead)[..., None]
    first = torch.cos(angle) * ahead + torch.sin(angle) * side
    third = -torch.sin(angle) * ahead + torch.cos(angle) * side
    axes = torch.stack([first, up.expand_as(first), third], -2)
    return x.mean(2, keepdim=True), axes


class PosePriorNet(nn.Module):
    """Joints ``(B, T, J, 3)`` metres -> corrections ``(B, T, J, 3)`` metres: an MLP over each frame's window of
    :data:`OFFSETS` poses in its body frame (:func:`body_frame`; the clip's ends repeated)."""

    def __init__(self, n_joints: int, skeleton: str, hidden: int = 256, n_layers: int = 3,
                 offsets: tuple = OFFSETS):
        super().__init__()
        self.skeleton, self.offsets = skeleton, tuple(int(o) for o in offsets)
        sizes = [len(self.offsets) * 3 * n_joints] + [hidden] * n_layers
        layers = []
        for a, b in zip(sizes[:-1], sizes[1:]):
            layers += [nn.Linear(a, b), nn.GELU()]
        self.mlp = nn.Sequential(*layers, nn.Linear(sizes[-1], 3 * n_joints))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        centre, axes = body_frame(x, self.skeleton)
        t = torch.arange(x.shape[1], device=x.device)
        window = [x[:, (t + o).clamp(0, x.shape[1] - 1)] for o in self.offsets]
        feats = torch.cat([torch.einsum("btjc,btkc->btjk", w - centre, axes).flatten(2) for w in window], -1)
        c = self.mlp(_SCALE * feats).view(x.shape) / _SCALE
        return torch.einsum("btjk,btkc->btjc", c, axes)  # back to the clip's frame


class PosePrior(NetworkComponent):
    """Learned pose prior: the correction that puts a frame back on real motion, and the frames that need it.

    Parameters
    ----------
    hidden, n_layers : int, default=256, 3
        MLP width and depth.
    max_offset : float, default=0.06
        Metres: the largest standard deviation of the slow offsets given to training crops.
    clean_probability : float, default=0.25
        Share of training crops left clean (the network learns to leave real poses alone).
    crop : int, default=40
        Training crop length.
    rigid_tolerance : float or None, default=0.005
        Flawed training crops go on rigid bones first, as the refiner shows clips to its steps (None: not).
    window : int, default=9
        Frames over which a frame's correction is averaged into its level (:meth:`level`).
    fade : float, default=2.0
        A frame's correction is applied in full from ``fade`` times ``threshold_``, in part above it.
    schedule : TrainSchedule
    random_state : int or None, default=0

    Attributes
    ----------
    network_ : PosePriorNet
    skeleton_ : str
    threshold_ : float
        Metres: the level under which the prior corrects no frame of a drifting skeleton (the clip's refit onto rigid
        bones still moves them, reported as a skeleton change; :meth:`calibrate`; infinite until then).
    texture_threshold_ : float
        Metres: the same for a clip noisy throughout, a generator's texture (:meth:`calibrate`; infinite until then).
    history_ : list of dict
    """

    _fitted_attributes = ("skeleton_", "n_joints_", "threshold_", "texture_threshold_", "history_")
    _attribute_defaults = {"texture_threshold_": float("inf")}  # files before it: no texture step

    def __init__(self, *, hidden: int = 256, n_layers: int = 3, max_offset: float = 0.06,
                 clean_probability: float = 0.25, crop: int = 40, rigid_tolerance: float | None = 0.005,
                 window: int = 9, fade: float = 2.0,
                 schedule: TrainSchedule = TrainSchedule(n_epochs=100, batch_size=64, learning_rate=1e-3, patience=10,
                                                         steps_per_epoch=200),
                 random_state: int | None = 0):
        self.hidden = hidden
        self.n_layers = n_layers
        self.max_offset = max_offset
        self.clean_probability = clean_probability
        self.crop = crop
        self.rigid_tolerance = rigid_tolerance
        self.window = window
        self.fade = fade
        self.schedule = schedule
        self.random_state = random_state

    def _make_network(self, fitted: dict) -> PosePriorNet:
        return PosePriorNet(fitted["n_joints_"], fitted["skeleton_"], self.hidden, self.n_layers)

    def _flawed(self, crops: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Crops ``(N, L, J, 3)`` with random slow offsets (all joints or a random subset, over the crop or a
        window of it), white noise, or nothing, put on rigid bones as the refiner would; float32."""
        n, length, n_joints, _ = crops.shape
        t = np.arange(length)[None, :, None, None, None]
        period = rng.uniform(8.0, 80.0, (n, 1, 1, 1, 1))  # frames: a slow drift to a limb swinging off
        freq = rng.uniform(0.0, 1.0, (n, 1, 3, n_joints, 3)) / period
        phase = rng.uniform(0, 2 * math.pi, (n, 1, 3, n_joints, 3))
        slow = (rng.normal(size=(n, 1, 3, n_joints, 3)) * np.sin(2 * math.pi * freq * t + phase)).sum(2)
        slow /= np.maximum(slow.std(axis=(1, 2, 3), keepdims=True), 1e-9)
        white = rng.normal(size=crops.shape) * rng.uniform(0.0, 0.4, (n, 1, 1, 1))  # relative to the offset's level
        noise = np.where(rng.random((n, 1, 1, 1)) < 0.2, white, slow)
        noise *= rng.random((n, 1, n_joints, 1)) < np.where(rng.random((n, 1, 1, 1)) < 0.3, 0.3, 1.0)  # some joints
        start, span = rng.uniform(-0.5, 1.0, (n, 1)) * length, rng.uniform(5, 2 * length, (n, 1))
        ramp = np.sin(np.pi * np.clip((np.arange(length) - start) / span, 0, 1)) ** 2
        ramp = np.where(rng.random((n, 1)) < 0.5, ramp, 1.0)[..., None, None]
        level = rng.uniform(0.0, self.max_offset, (n, 1, 1, 1)) * (rng.random((n, 1, 1, 1)) >= self.clean_probability)
        flawed = crops + level * ramp * noise
        if self.rigid_tolerance is not None:
            flawed = rigid_skeleton(flawed, self.skeleton_, self.rigid_tolerance, iterations=30)[0]  # enough for training
        return flawed.astype(np.float32)

    def fit(self, clips, *, skeleton: str = "humanact12", validation=None, checkpoint=None) -> "PosePrior":
        """Train on real clips ``(T_i, J, 3)`` metres (T_i >= 2); ``validation``: held-out clips."""
        rng = check_random_state(self.random_state)
        clips = [np.asarray(c, np.float32) for c in clips]
        if not clips or any(c.ndim != 3 or c.shape[-1] != 3 or len(c) < 2 for c in clips):
            raise ValueError("`clips` must be a non-empty list of (T >= 2, J, 3) arrays.")
        if not 0 <= self.clean_probability < 1 or self.max_offset <= 0 or self.crop < 2:
            raise ValueError("need 0 <= clean_probability < 1, max_offset > 0 and crop >= 2.")
        self.skeleton_ = get_skeleton(skeleton).name
        self.n_joints_ = int(clips[0].shape[1])
        self.threshold_ = self.texture_threshold_ = float("inf")
        self._fit_on_crops(clips, validation, self._flawed, _loss, rng, checkpoint=checkpoint, desc="pose prior")
        return self

    def _checked(self, joints) -> np.ndarray:
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        return check_joint_batch(joints, self.n_joints_)

    @torch.no_grad()
    def correction(self, joints) -> np.ndarray:
        """``(B, T, J, 3)`` metres: what the prior would add to each frame of a batch ``(B, T, J, 3)`` metres."""
        x = self._checked(joints)
        return self.network_(torch.from_numpy(x).to(self.device_)).cpu().numpy()

    def _levels(self, correction: np.ndarray) -> np.ndarray:
        size = np.linalg.norm(correction, axis=-1).mean(-1)
        return uniform_filter1d(size, min(self.window, size.shape[1]), axis=1, mode="nearest")

    def level(self, joints) -> np.ndarray:
        """``(B, T)`` metres: each frame's correction (mean over joints) averaged over ``window`` frames."""
        return self._levels(self.correction(joints))

    def weight(self, level: np.ndarray, threshold=None) -> np.ndarray:
        """Share of the correction applied at ``level`` (metres, ``(B, T)``): 0 up to ``threshold`` (metres, a number
        or one per clip ``(B,)``; default ``threshold_``), 1 from ``fade`` times it."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        level = np.asarray(level, np.float64)
        threshold = np.asarray(self.threshold_ if threshold is None else threshold, np.float64)
        ratio = level / np.maximum(threshold, 1e-12).reshape(threshold.shape + (1,) * (level.ndim - threshold.ndim))
        return np.clip((ratio - 1.0) / max(self.fade - 1.0, 1e-9), 0.0, 1.0)

    def posed(self, joints, threshold=None) -> tuple[np.ndarray, np.ndarray]:
        """A batch ``(B, T, J, 3)`` metres with every frame whose :meth:`level` passes ``threshold`` (default
        ``threshold_``; or one per clip) corrected (:meth:`weight` of it); returns ``(joints float32, level (B, T)
        metres)``; frames at or under the threshold exactly as given."""
        x = self._checked(joints)
        c = self.correction(x)
        level = self._levels(c)
        w = self.weight(level, threshold)[..., None, None]
        return np.where(w > 0, x + w * c, x).astype(np.float32), level

    def calibrate(self, clips, *, quantile: float = 0.5, texture_quantile: float = 0.95) -> tuple[float, float]:
        """Set ``threshold_`` and ``texture_threshold_`` (metres) to these quantiles of the :meth:`level` of every
        frame of these clean clips (held-out subjects: the prior's correction of people it never saw, which it
        cannot tell from a flaw); returns both."""
        check_is_fitted(self, "network_", msg=NOT_FITTED)
        if len(clips) == 0 or not (0 < quantile < 1 and 0 < texture_quantile < 1):
            raise ValueError(f"calibrate needs clean clips and quantiles in (0, 1); got {len(clips)} clips, quantile "
                             f"{quantile}, texture_quantile {texture_quantile}.")
        levels = np.concatenate([self.level(np.asarray(c, np.float32)[None])[0] for c in clips])
        self.threshold_, self.texture_threshold_ = (float(np.quantile(levels, q)) for q in (quantile, texture_quantile))
        return self.threshold_, self.texture_threshold_


def _loss(net, batch, rng) -> torch.Tensor:
    """Mean squared distance (m²) of the corrected joints from the clean ones."""
    return ((batch["flawed"] + net(batch["flawed"]) - batch["clean"]) ** 2).sum(-1).mean()


def drifting_skeleton(joints: np.ndarray, skeleton: str, tolerance: float = 0.005, *, bones: np.ndarray | None = None,
                      variation: np.ndarray | None = None) -> np.ndarray:
    """``(B,)`` bool: clips ``(B, T, J, 3)`` metres whose skeleton deforms slowly throughout, as drifting joints make it.

    A bone's length varies by more than ``tolerance`` (std / mean, the rigid-skeleton step's test), and the
    varying bones (weighted by their variation) keep their deviation from frame to frame (lag-1 autocorrelation
    at least :data:`DRIFT_AUTOCORRELATION`) and are off their median by :data:`DRIFT_OFF` in at least
    :data:`DRIFT_SHARE` of the frames: noise varies from frame to frame, a wrong pose blended over one transition
    shortens bones in part of the clip only (calibration subjects 9-10, severity 2: of the seeded clips 100 % of
    drift, 0 % of jitter, 10 % of wrong anchors pass; no clean clip, whose bones are rigid). ``bones``: boolean mask
    of the bones judged (default all; as :func:`~refiner.core.skeletons.rigid_skeleton`'s). ``variation``: the clips'
    worst variation ``(B,)`` as :func:`~refiner.core.skeletons.rigid_skeleton` returns it, when known: clips under
    ``tolerance`` are rigid and not judged again (a batch of mocap costs nothing)."""
    x = np.asarray(joints, np.float32)
    if x.ndim != 4 or x.shape[-1] != 3:
        raise ValueError(f"`joints` must be (B, T, J, 3); got shape {x.shape}.")
    if variation is not None:
        out, todo = np.zeros(len(x), bool), np.asarray(variation) > tolerance
        if todo.any():
            out[todo] = drifting_skeleton(x[todo], skeleton, tolerance, bones=bones)
        return out
    lengths = bone_lengths(x, skeleton)  # (B, T, n_bones)
    if bones is not None:
        lengths = lengths[..., np.asarray(bones, bool)]
    if lengths.shape[-1] == 0 or x.shape[1] < 2:  # no bone judged, or no motion: nothing drifts
        return np.zeros(len(x), bool)
    variation = lengths.std(1) / np.maximum(lengths.mean(1), 1e-9)
    dev = lengths - np.median(lengths, axis=1, keepdims=True)
    rho = (dev[:, 1:] * dev[:, :-1]).sum(1) / np.maximum((dev * dev).sum(1), 1e-18)
    weight = variation / np.maximum(variation.sum(-1, keepdims=True), 1e-18)
    share = (np.abs(dev) > DRIFT_OFF).mean(1)
    return (((variation > tolerance).mean(-1) >= DRIFT_BONES) & ((rho * weight).sum(-1) >= DRIFT_AUTOCORRELATION)
            & ((share * weight).sum(-1) >= DRIFT_SHARE))


def prior_posed(refiner, clips: np.ndarray, reports: list, drifting: np.ndarray,
                noisy: np.ndarray | None = None, *, generated: np.ndarray | None = None) -> np.ndarray:
    """The pose-prior step, last: in the ``drifting (B,)`` clips of ``clips (B, T, J, 3)`` (:func:`drifting_skeleton`
    of the input), the frames the refiner's ``pose_prior`` would move further than ``threshold_`` corrected
    (:meth:`PosePrior.posed`), in the ``noisy (B,)`` ones (found noisy throughout by the noise step: a generator's
    texture) those it would move further than ``texture_threshold_``, in the ``generated (B,)`` ones (known to be a
    generator's, after the texture filter) at ``threshold_`` as drifting ones; then every frame put on the lengths of the
    corrected clip (the medians of all its frames, drawn toward the refiner's bone proportions where it uses them):
    the prior's poses hold truer lengths than drifted ones. Like the other steps that judge a clip as a whole (rigid
    skeleton, amplitude, noise throughout) it runs in every mode: a drift covers anchors and transitions alike. One
    report entry (step ``"pose"``) per run of corrected frames, one ``"skeleton"`` entry for the frames the refit moved."""
    prior = getattr(refiner, "pose_prior", None)
    drifting = np.asarray(drifting, bool)
    generated = np.zeros_like(drifting) if generated is None else np.asarray(generated, bool) & ~drifting
    strict = drifting | generated
    noisy = np.zeros_like(drifting) if noisy is None else np.asarray(noisy, bool) & ~strict
    todo = np.flatnonzero(strict | noisy)
    if prior is None or getattr(refiner, "posing", "prior") != "prior" or not todo.size:
        return clips
    threshold = np.where(strict[todo], prior.threshold_, prior.texture_threshold_)
    posed, level = prior.posed(clips[todo], threshold)
    out = clips.copy()
    proportions = refiner.bone_proportions if refiner.rigid_lengths == "proportions" else None
    for k, b in enumerate(todo):
        runs, n_runs = label(prior.weight(level[k : k + 1], threshold[k : k + 1])[0] > 0)
        keep = runs > 0
        if not keep.any():
            continue
        y = np.where(keep[:, None, None], posed[k], clips[b])
        out[b] = rigid_skeleton(y, refiner.skeleton, 0.0, proportions=proportions)[0]
        why = ("the skeleton deforms slowly throughout (drifting joints)" if drifting[b] else
               "the clip is a generator's (texture='all'), after the texture filter" if generated[b] else
               "the clip is noisy throughout (a generator's texture)")
        refit = (out[b] != clips[b]).reshape(len(keep), -1).any(-1) & ~keep
        if refit.any():  # the new lengths move the other frames too
            frames = np.flatnonzero(refit)
            moved = 100 * float(np.linalg.norm(out[b][frames] - clips[b][frames], axis=-1).mean())
            reports[b].changes.append({
                "start": int(frames[0]), "stop": int(frames[-1] + 1), "step": "skeleton", "reason":
                    f"{why}: every frame put back on the bone lengths of the clip the pose prior corrected "
                    f"({len(frames)} frames outside them moved {moved:.2f} cm on average)"})
        for r in range(1, n_runs + 1):
            frames = np.flatnonzero(runs == r)
            moved = 100 * float(np.linalg.norm(out[b][frames] - clips[b][frames], axis=-1).mean())
            reports[b].changes.append({
                "start": int(frames[0]), "stop": int(frames[-1] + 1), "step": "pose", "repair": "pose_prior",
                "reason": f"{why}; the pose prior's correction reached {100 * float(level[k, frames].max()):.2f} cm "
                          f"(threshold {100 * float(threshold[k]):.2f} cm, over {prior.window} frames): corrected by "
                          f"it and put back on rigid bones (moved {moved:.2f} cm on average)"})
    return out
