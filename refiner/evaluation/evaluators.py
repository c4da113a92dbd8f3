"""Action2Motion's pretrained GRU action recognisers: the feature extractor of FID, accuracy and diversity.

The network (``generator_formats.md`` §8.2) is ``GRU(J*3, 128, 2 layers)`` over the frames, the top
layer's output at the last frame -> ``Linear(128, 30)`` -> ``tanh`` (the **30-d feature** used by FID,
diversity and multimodality) -> ``Linear(30, C)`` (class logits; accuracy takes the argmax).

Input preprocessing (§8.3): joint positions in metres in the dataset's **native frame** (HumanAct12:
y down, facing -z), the **root of the first frame of the crop subtracted** (the trajectory is kept; no
per-frame centring, no scaling, no normalisation), **60-frame crops** (100 for CMU-Mocap); clips shorter
than that are padded by repeating their last frame. Frames are flattened joint-major
``[j0x, j0y, j0z, j1x, ...]``.

The original draws the GRU's initial hidden state from N(0, 1) afresh on every call, so its metrics are
random even for a fixed input set. :class:`ActionRecognizer` reproduces that (``hidden="random"``,
the default) from an explicit, seeded generator, and offers two deterministic modes (``"fixed"``,
``"zeros"``); see :class:`ActionRecognizer`.
"""
from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np
import torch
from torch import nn

from refiner.core.motion import Motion
from refiner.core.skeletons import get_skeleton
from refiner.core.validation import check_joints, check_random_state
from refiner.io.datasets import _CMU_UNIT_METRES, CMU_ACTIONS, HUMANACT12_ACTIONS, default_data_dir

__all__ = [
    "RecognizerConfig",
    "ActionRecognizer",
    "RECOGNIZERS",
    "HIDDEN_MODES",
    "HUMANACT12_FINE_CODES",
    "load_recognizer",
    "load_recognizer_state",
    "evaluators_dir",
    "crop_clip",
    "prepare_clips",
]

#: Fine HumanAct12 classes of ``humanact12_fine``: the 34 fine codes ``AAff`` in sorted order (the
#: recogniser scores 99 % on real clips with this order).
HUMANACT12_FINE_CODES = (
    "0101", "0102", "0103", "0104", "0105", "0106", "0107", "0201", "0301", "0401", "0402", "0501",
    "0502", "0503", "0504", "0505", "0601", "0602", "0603", "0604", "0605", "0701", "0801", "0802",
    "0803", "0901", "1001", "1002", "1101", "1102", "1103", "1104", "1201", "1202",
)

#: The three ways of choosing the GRU's initial hidden state (see :class:`ActionRecognizer`).
HIDDEN_MODES = ("random", "fixed", "zeros")

_CROPS = ("random", "start", "center")


@dataclass(frozen=True)
class RecognizerConfig:
    """Architecture and input protocol of one recogniser (JSON-serialisable).

    Parameters
    ----------
    n_joints : int
        J; the GRU reads ``J * 3`` values per frame.
    n_classes : int
        C, the number of logits.
    name : str, default="custom"
    skeleton : str, default="humanact12"
        Registered skeleton whose native frame the inputs must be in.
    n_frames : int, default=60
        Crop length the recogniser was trained and evaluated on.
    input_scale : float, default=1.0
        Factor applied to the root-centred positions (in metres) before the GRU. 1 for HumanAct12 and
        NTU13; for CMU-Mocap the recogniser expects raw CMU units / 20, i.e. metres x 0.886.
    class_names : tuple of str, default=()
        Names of the C classes, in logit order (empty when unknown).
    hidden_size, n_layers, feature_size : int
        128, 2 and 30 in every Action2Motion recogniser.
    """

    n_joints: int
    n_classes: int
    name: str = "custom"
    skeleton: str = "humanact12"
    n_frames: int = 60
    input_scale: float = 1.0
    class_names: tuple[str, ...] = field(default_factory=tuple)
    hidden_size: int = 128
    n_layers: int = 2
    feature_size: int = 30

    def to_dict(self) -> dict:
        return asdict(self)


#: The four published recognisers: config, ``.safetensors`` file and original ``.tar`` file, all in
#: :func:`evaluators_dir`. Accuracies on real clips (60-frame crops; CMU 100 frames) are in the README
#: of the shared data folder: humanact12 99.9 %, humanact12_fine 99 %, cmu_mocap 93.6 %.
RECOGNIZERS: dict[str, tuple[RecognizerConfig, str, str]] = {
    "humanact12": (
        RecognizerConfig(24, 12, "humanact12", "humanact12", 60, 1.0, HUMANACT12_ACTIONS),
        "humanact12_gru.safetensors", "action_recognition_model_humanact12.tar",
    ),
    "humanact12_fine": (
        RecognizerConfig(24, 34, "humanact12_fine", "humanact12", 60, 1.0, HUMANACT12_FINE_CODES),
        "humanact12_fine_gru.safetensors", "action_recognition_model_humanact12_fineG.tar",
    ),
    "ntu13": (
        RecognizerConfig(18, 13, "ntu13", "uestc", 60, 1.0, ()),
        "ntu13_vibe_gru.safetensors", "action_recognition_model_vibe_v2.tar",
    ),
    "cmu_mocap": (
        # Action2Motion feeds raw CMU units / 20; our CMU motions are in metres (refiner.io.datasets).
        RecognizerConfig(20, 8, "cmu_mocap", "cmu_mocap", 100, 1.0 / (_CMU_UNIT_METRES * 20.0), CMU_ACTIONS),
        "cmu_mocap_gru.safetensors", "action_recognition_model_mocap_new.tar",
    ),
}


class ActionRecognizer(nn.Module):
    """Action2Motion's GRU action recogniser (``MotionDiscriminator``) with its input protocol.

    Parameters
    ----------
    config : RecognizerConfig
    hidden : {"random", "fixed", "zeros"}, default="random"
        Initial hidden state of the GRU, ``(n_layers, B, hidden_size)``:

        - ``"random"`` (default, faithful): fresh N(0, 1) noise on every call, as the original. The
          noise (and any random crop) comes from the call's ``random_state`` when one is passed, else
          from this object's own stream, seeded once from ``random_state``, so a new recogniser
          replays the same sequence of draws. This is the default because every published
          HumanAct12 / NTU13 figure (Action2Motion, ACTOR, MLD, the paper) includes this noise, and
          :func:`refiner.evaluation.metrics.evaluate`'s 20 replications need a new draw each.
        - ``"fixed"``: the same N(0, 1) draw on every call (the stream is re-seeded from
          ``random_state`` each call), so the same inputs always give the same outputs. Clip ``i``
          gets the same noise whatever the batch size. Use it to compare refiners clip by clip.
        - ``"zeros"``: zero hidden state; deterministic, but not the distribution the GRU was trained
          with (accuracy on real HumanAct12 is unchanged, features move by about 9 % of their norm).
    random_state : int, default=0
        Seed of the hidden-state noise and of random crops.

    Attributes
    ----------
    recurrent : torch.nn.GRU
    linear1 : torch.nn.Linear
        128 -> 30, followed by tanh: the feature layer.
    linear2 : torch.nn.Linear
        30 -> C logits.

    Examples
    --------
    >>> rec = load_recognizer("humanact12")                       # doctest: +SKIP
    >>> rec.predict(dataset.motions[:4]).tolist()                 # doctest: +SKIP
    [1, 1, 1, 1]
    """

    def __init__(self, config: RecognizerConfig, *, hidden: str = "random", random_state: int = 0) -> None:
        super().__init__()
        if hidden not in HIDDEN_MODES:
            raise ValueError(f"`hidden` must be one of {', '.join(HIDDEN_MODES)}; got {hidden!r}.")
        if isinstance(random_state, (bool, np.bool_)) or not isinstance(random_state, (int, np.integer)):
            raise ValueError(f"`random_state` must be an int seed; got {random_state!r}.")
        self.config = config
        self.hidden = hidden
        self.random_state = int(random_state)
        self.recurrent = nn.GRU(config.n_joints * 3, config.hidden_size, config.n_layers)
        self.linear1 = nn.Linear(config.hidden_size, config.feature_size)
        self.linear2 = nn.Linear(config.feature_size, config.n_classes)
        self._stream = np.random.default_rng(self.random_state)
        self.eval()

    def forward(self, x: torch.Tensor, h0: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Features and logits of preprocessed clips.

        Parameters
        ----------
        x : Tensor of shape (B, T, J*3), float32
            Preprocessed frames, batch first.
        h0 : Tensor of shape (n_layers, B, hidden_size), float32

        Returns
        -------
        features : Tensor of shape (B, feature_size)
            ``tanh(linear1(top GRU output at the last frame))``, in (-1, 1).
        logits : Tensor of shape (B, n_classes)
        """
        out, _ = self.recurrent(x.transpose(0, 1), h0)  # the GRU is sequence-first: (T, B, H)
        features = torch.tanh(self.linear1(out[-1]))
        return features, self.linear2(features)

    # ------------------------------------------------------------------ public API

    def reset(self) -> "ActionRecognizer":
        """Re-seed the own stream used in ``"random"`` mode from ``random_state``; returns self."""
        self._stream = np.random.default_rng(self.random_state)
        return self

    def initial_hidden(self, batch_size: int, *, random_state=None) -> torch.Tensor:
        """Initial hidden state for ``batch_size`` clips under this recogniser's ``hidden`` mode.

        Parameters
        ----------
        batch_size : int
        random_state : None, int or numpy Generator, optional
            Overrides the mode's own source of noise for this call.

        Returns
        -------
        Tensor of shape (n_layers, batch_size, hidden_size), float32
        """
        return self._hidden(batch_size, self._call_rng(random_state))

    def prepare(self, motions, *, crop: str = "random", random_state=None) -> np.ndarray:
        """Preprocess clips into the recogniser's input (§8.3), without running it.

        Parameters
        ----------
        motions : Motion, sequence of Motion, or array-like of shape (B, T, J, 3) or (T, J, 3)
            Joint positions in metres in the native frame of ``config.skeleton``.
        crop : {"random", "start", "center"}, default="random"
            Where to take the ``n_frames`` crop of a longer clip. ``"random"`` is the
            Action2Motion protocol for real clips.
        random_state : None, int or numpy Generator, optional
            Source of random crops; default as for the hidden state (see the class docstring).

        Returns
        -------
        ndarray of shape (B, n_frames, J, 3), float32
            Crops with the crop's first-frame root at the origin, times ``config.input_scale``.
        """
        return prepare_clips(motions, self.config, crop=crop, random_state=self._call_rng(random_state))

    @torch.no_grad()
    def features_and_logits(
        self, motions, *, crop: str = "random", random_state=None, batch_size: int = 1024
    ) -> tuple[np.ndarray, np.ndarray]:
        """Features and logits from one draw of the hidden state (and of the crops).

        Parameters
        ----------
        motions : Motion, sequence of Motion, or array-like of shape (B, T, J, 3)
            See :meth:`prepare`. Arrays with ``T == n_frames`` are used as they are (root subtracted).
        crop : {"random", "start", "center"}, default="random"
        random_state : None, int or numpy Generator, optional
            See the class docstring.
        batch_size : int, default=1024
            Clips per forward pass; results do not depend on it.

        Returns
        -------
        features : ndarray of shape (B, 30), float32
        logits : ndarray of shape (B, C), float32
        """
        if not isinstance(batch_size, (int, np.integer)) or batch_size < 1:
            raise ValueError(f"`batch_size` must be a positive int; got {batch_size!r}.")
        rng = self._call_rng(random_state)
        clips = prepare_clips(motions, self.config, crop=crop, random_state=rng)
        x = torch.from_numpy(clips.reshape(len(clips), clips.shape[1], -1))
        h0 = self._hidden(len(clips), rng)
        device = next(self.parameters()).device
        feats, logits = [], []
        for start in range(0, len(x), batch_size):
            f, lg = self(x[start : start + batch_size].to(device), h0[:, start : start + batch_size].to(device))
            feats.append(f.cpu())
            logits.append(lg.cpu())
        return torch.cat(feats).numpy(), torch.cat(logits).numpy()

    def features(self, motions, *, crop: str = "random", random_state=None, batch_size: int = 1024) -> np.ndarray:
        """The 30-d recogniser features used by FID, diversity and multimodality.

        Parameters and preprocessing as :meth:`features_and_logits`.

        Returns
        -------
        ndarray of shape (B, 30), float32
            ``tanh`` activations, each in (-1, 1).
        """
        return self.features_and_logits(motions, crop=crop, random_state=random_state, batch_size=batch_size)[0]

    def predict_logits(self, motions, *, crop: str = "random", random_state=None, batch_size: int = 1024) -> np.ndarray:
        """Class logits ``(B, C)``, float32 (see :meth:`features_and_logits`)."""
        return self.features_and_logits(motions, crop=crop, random_state=random_state, batch_size=batch_size)[1]

    def predict(self, motions, *, crop: str = "random", random_state=None, batch_size: int = 1024) -> np.ndarray:
        """Predicted class of every clip.

        Returns
        -------
        ndarray of shape (B,), int64
            Argmax of the logits; index into ``config.class_names``.
        """
        return self.predict_logits(motions, crop=crop, random_state=random_state, batch_size=batch_size).argmax(1)

    def extra_repr(self) -> str:
        return f"name={self.config.name!r}, skeleton={self.config.skeleton!r}, hidden={self.hidden!r}"

    # ------------------------------------------------------------------ helpers

    def _call_rng(self, random_state) -> np.random.Generator:
        """The numpy stream for one call: the caller's, the own stream, or a fresh seeded one."""
        if random_state is not None:
            return check_random_state(random_state)
        if self.hidden == "random":
            return self._stream
        return np.random.default_rng(self.random_state)

    def _hidden(self, batch_size: int, rng: np.random.Generator) -> torch.Tensor:
        cfg = self.config
        if self.hidden == "zeros":
            return torch.zeros(cfg.n_layers, batch_size, cfg.hidden_size)
        gen = torch.Generator().manual_seed(int(rng.integers(2**63 - 1)))
        # Drawn clip-major, so clip i's noise does not depend on how many clips follow it.
        noise = torch.randn(batch_size, cfg.n_layers, cfg.hidden_size, generator=gen)
        return noise.transpose(0, 1).contiguous()


def crop_clip(joints, n_frames: int = 60, start: int = 0) -> np.ndarray:
    """Frames ``start : start + n_frames`` of a clip, padded with its last frame when too short.

    Parameters
    ----------
    joints : ndarray of shape (T, J, 3)
    n_frames : int, default=60
    start : int, default=0
        First frame; clipped to ``[0, max(T - n_frames, 0)]``.

    Returns
    -------
    ndarray of shape (n_frames, J, 3), a new array (no root subtraction).
    """
    x = np.asarray(joints)
    start = int(min(max(start, 0), max(len(x) - n_frames, 0)))
    out = x[start : start + n_frames]
    if len(out) < n_frames:
        out = np.concatenate([out, np.repeat(out[-1:], n_frames - len(out), axis=0)])
    return np.array(out, copy=True)


def prepare_clips(motions, config: RecognizerConfig, *, crop: str = "random", random_state=None) -> np.ndarray:
    """Crop, pad, centre and scale clips for a recogniser (§8.3); see :meth:`ActionRecognizer.prepare`.

    Returns
    -------
    ndarray of shape (B, config.n_frames, J, 3), float32
    """
    if crop not in _CROPS:
        raise ValueError(f"`crop` must be one of {', '.join(_CROPS)}; got {crop!r}.")
    rng = check_random_state(random_state)
    skel = get_skeleton(config.skeleton)
    clips = _as_clip_list(motions, skel.name)
    out = np.empty((len(clips), config.n_frames, skel.n_joints, 3), dtype=np.float32)
    for i, clip in enumerate(clips):
        extra = len(clip) - config.n_frames
        if extra <= 0 or crop == "start":
            start = 0
        elif crop == "center":
            start = extra // 2
        else:
            start = int(rng.integers(extra + 1))
        c = crop_clip(clip, config.n_frames, start)
        out[i] = (c - c[:1, skel.root : skel.root + 1]) * config.input_scale
    return out


def _as_clip_list(motions, skeleton: str) -> list[np.ndarray]:
    """Validated ``(T, J, 3)`` float32 arrays from a Motion, Motions or a (B, T, J, 3) array."""
    if isinstance(motions, Motion):
        motions = [motions]
    if isinstance(motions, (np.ndarray, torch.Tensor)):
        arr = np.asarray(motions.detach().cpu() if isinstance(motions, torch.Tensor) else motions)
        if arr.ndim == 3:
            arr = arr[None]
        return list(check_joints(arr, name="motions", skeleton=skeleton, min_frames=1, batched=True))
    clips = []
    items = list(motions) if isinstance(motions, Iterable) else None
    if items is None:
        raise ValueError(f"`motions` must be a Motion, a sequence of Motion or a (B, T, J, 3) array; "
                         f"got {type(motions).__name__}.")
    if not items:
        raise ValueError("`motions` is empty.")
    for i, m in enumerate(items):
        if isinstance(m, Motion):
            if m.skeleton != skeleton:
                raise ValueError(f"clip {i} of {len(items)} is on skeleton {m.skeleton!r}; this recogniser reads "
                                 f"{skeleton!r} (convert it with an adapter first).")
            clips.append(m.joints)
        else:
            try:
                clips.append(check_joints(m, name="motions", skeleton=skeleton, min_frames=1))
            except ValueError as e:
                raise ValueError(f"clip {i} of {len(items)}: {e}") from e
    return clips


def evaluators_dir() -> Path:
    """The folder holding the recogniser weights: ``default_data_dir().parent / "evaluators"``."""
    return default_data_dir().parent / "evaluators"


def load_recognizer_state(path: str | os.PathLike) -> dict[str, torch.Tensor]:
    """Read a recogniser state dict from a ``.safetensors`` file or an original ``.tar`` checkpoint.

    Parameters
    ----------
    path : path
        ``.safetensors`` (the tensors themselves), or Action2Motion's ``.tar`` / ``.pt`` / ``.pth``
        (a legacy ``torch.save`` dict with the state dict under ``"model"``), read with
        ``torch.load(weights_only=True)`` so that no code from the file runs.

    Returns
    -------
    dict of str to Tensor
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"no recogniser weights at {str(path)!r}.")
    if path.suffix == ".safetensors":
        from refiner.core.serialization import load_state

        tensors, _ = load_state(path)
        return {k: torch.from_numpy(np.array(v)) for k, v in tensors.items()}
    if path.suffix in (".tar", ".pt", ".pth"):
        try:
            ckpt = torch.load(path, map_location="cpu", weights_only=True)
        except Exception as e:  # pickle and zip errors have many types
            raise ValueError(f"{str(path)!r} is not a readable torch checkpoint of tensors: {e}") from e
        if not isinstance(ckpt, dict) or "model" not in ckpt:
            raise ValueError(f"{str(path)!r} must hold a dict with the state dict under 'model'.")
        return dict(ckpt["model"])
    raise ValueError(f"unsupported recogniser file {str(path)!r}: expected .safetensors or .tar.")


def load_recognizer(
    name_or_path: str | os.PathLike = "humanact12",
    *,
    hidden: str = "random",
    random_state: int = 0,
    directory: str | os.PathLike | None = None,
) -> ActionRecognizer:
    """Load a pretrained Action2Motion recogniser.

    Parameters
    ----------
    name_or_path : str or path, default="humanact12"
        A name in :data:`RECOGNIZERS` (``humanact12``, ``humanact12_fine``, ``ntu13``, ``cmu_mocap``),
        read from ``directory`` (the ``.safetensors`` file, else the original ``.tar``), or a path to
        either kind of file. For a path the recogniser is identified by its weight shapes. Without
        ``directory``, ``humanact12`` is the copy shipped in the package (the same tensors,
        :mod:`refiner.evaluation.evaluator_weights`).
    hidden : {"random", "fixed", "zeros"}, default="random"
        Initial hidden-state mode, see :class:`ActionRecognizer`.
    random_state : int, default=0
    directory : path, optional
        Default the shipped copy for ``humanact12``, else :func:`evaluators_dir`.

    Returns
    -------
    ActionRecognizer
        In eval mode, on the CPU.

    Raises
    ------
    ValueError
        Unknown name, missing file, or weights that match no known recogniser.
    """
    name = str(name_or_path)
    if name in RECOGNIZERS:
        from refiner.evaluation.evaluator_weights import packaged_recognizer

        config, st_file, tar_file = RECOGNIZERS[name]
        path = packaged_recognizer(name) if directory is None else None
        if path is None:
            folder = Path(directory) if directory is not None else evaluators_dir()
            path = folder / st_file if (folder / st_file).is_file() else folder / tar_file
        if not path.is_file():
            from refiner.io.data_sources import missing_message

            raise ValueError(f"recogniser {name!r} not found: " + missing_message("evaluators", folder, (st_file, tar_file)))
        state = load_recognizer_state(path)
    else:
        path = Path(name_or_path)
        if not path.suffix:
            raise ValueError(f"unknown recogniser {name!r}; known: {', '.join(RECOGNIZERS)} (or pass a file path).")
        state = load_recognizer_state(path)
        config = _config_from_state(path, state)
    model = ActionRecognizer(config, hidden=hidden, random_state=random_state)
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError as e:
        raise ValueError(f"{str(path)!r} does not fit recogniser {config.name!r}: {e}") from e
    return model.eval()


def _config_from_state(path: Path, state: dict) -> RecognizerConfig:
    """The known recogniser whose weight shapes match ``state``."""
    try:
        n_in = state["recurrent.weight_ih_l0"].shape[1]
        n_classes = state["linear2.weight"].shape[0]
    except KeyError as e:
        raise ValueError(f"{str(path)!r} is not an Action2Motion recogniser state dict (missing {e}).") from None
    for config, _, _ in RECOGNIZERS.values():
        if (config.n_joints * 3, config.n_classes) == (n_in, n_classes):
            return config
    known = ", ".join(f"{n} ({c.n_joints * 3} inputs, {c.n_classes} classes)" for n, (c, _, _) in RECOGNIZERS.items())
    raise ValueError(f"{str(path)!r} has {n_in} inputs and {n_classes} classes, matching no known recogniser; "
                     f"known: {known}.")
