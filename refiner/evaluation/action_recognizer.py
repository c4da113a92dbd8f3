"""Action2Motion's GRU action recogniser (``MotionDiscriminator``): the network and its hidden-state modes.

The network (``generator_formats.md`` §8.2) is ``GRU(J*3, 128, 2 layers)`` over the frames, the top
layer's output at the last frame -> ``Linear(128, 30)`` -> ``tanh`` (the **30-d feature** used by FID,
diversity and multimodality) -> ``Linear(30, C)`` (class logits; accuracy takes the argmax). Its input
protocol (crops, root subtraction, scale) is :mod:`refiner.evaluation.recognizer_input`; the published
recognisers and their loading are :mod:`refiner.evaluation.evaluators`.

The original draws the GRU's initial hidden state from N(0, 1) afresh on every call, so its metrics are
random even for a fixed input set. :class:`ActionRecognizer` reproduces that (``hidden="random"``,
the default) from an explicit, seeded generator, and offers two deterministic modes (``"fixed"``,
``"zeros"``); see :class:`ActionRecognizer`.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from torch import nn

from refiner.core.validation import check_random_state
from refiner.evaluation.recognizer_input import prepare_clips

__all__ = ["RecognizerConfig", "ActionRecognizer", "HIDDEN_MODES"]

#: The three ways of choosing the GRU's initial hidden state (see :class:`ActionRecognizer`).
HIDDEN_MODES = ("random", "fixed", "zeros")


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
          :func:`refiner.evaluation.protocol.evaluate`'s 20 replications need a new draw each.
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
    >>> from refiner.evaluation.evaluators import load_recognizer
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
