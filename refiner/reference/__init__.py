"""Five reference generators trained on HumanAct12, so the refiner can be measured on real generator output.

- :class:`LieVAEGenerator` (``"a2m"``, :mod:`refiner.reference.lie_vae`) follows Action2Motion
  (Guo et al. 2020): a conditional GRU VAE with a learned prior that emits, frame by frame, the root
  position and 23 axis-angle vectors (the Lie layout of generator_formats.md §2.1). Its output is
  decoded into joints by the ``action2motion`` adapter (``representation="lie"``).
- :class:`TransformerCVAEGenerator` (``"actor"``, :mod:`refiner.reference.transformer_cvae`) follows
  ACTOR (Petrovich et al. 2021): a transformer CVAE with per-action distribution tokens in the
  encoder and time queries in the decoder. It emits joint positions directly (converted by the
  ``action2motion`` adapter's ``representation="xyz"`` path, i.e. passed through and re-centred).
- :class:`MotionDiffusionGenerator` (``"mdm"``, :mod:`refiner.reference.diffusion`) follows MDM
  (Tevet et al. 2023): a transformer denoiser predicting the clean clip, classifier-free guidance,
  50 DDIM steps; joint positions like ``actor``. Trained about 100 minutes on CPU (676 epochs, then
  800 more from those weights with a decaying learning rate; docs/decisions.md D13).

``"a2m-large"`` and ``"actor-large"`` are the first two designs larger and trained far longer
(:data:`~refiner.reference.loading.KIND_PARAMETERS`: 110 and 98 minutes on one CPU thread); the large actor
samples its latent from a Gaussian per action fitted to the training posteriors (``prior="fitted"``) with
latent guidance 1 (their figures: docs/decisions.md D13).

The small two (:mod:`refiner.reference.base`) are trained on 60-frame crops (first-frame root at the origin,
native y-down frame) of HumanAct12 subjects 1-10 for a fixed number of epochs with early stopping
(about 8 minutes each on one CPU thread; an optional time limit), and reach the adapter only through
the plugin contract. They are honest small models, and their flaws are whatever such training
leaves: the shipped ``a2m`` jitters (joint speed about 1.7 times the real one) and its first frame is
often off, the shipped ``actor`` is over-smoothed (about a third of the real joint speed); the
HumanAct12 recogniser names the sampled action for 40-48 % of their samples (real clips: 99 %). The
shipped weights (float16 safetensors, :mod:`refiner.reference.loading`) live in
``refiner/weights/generators`` with a manifest; HumanAct12 is for academic, non-commercial use only,
and so are they.
"""
from __future__ import annotations

from refiner.core.rotations import unwrap_rotvecs
from refiner.reference.base import JointsGenerator, ReferenceGenerator, training_crops
from refiner.reference.diffusion import MotionDenoiser, MotionDenoiserConfig, MotionDiffusionGenerator
from refiner.reference.lie_vae import LieVAE, LieVAEConfig, LieVAEGenerator, lie_targets
from refiner.reference.loading import (
    GENERATOR_KINDS,
    KIND_PARAMETERS,
    LICENCE,
    WEIGHTS_DIR,
    load_reference_generator,
    train_reference_generator,
)
from refiner.reference.transformer_cvae import TransformerCVAE, TransformerCVAEConfig, TransformerCVAEGenerator

__all__ = [
    "GENERATOR_KINDS",
    "JointsGenerator",
    "KIND_PARAMETERS",
    "MotionDenoiser",
    "MotionDenoiserConfig",
    "MotionDiffusionGenerator",
    "LICENCE",
    "LieVAE",
    "LieVAEConfig",
    "LieVAEGenerator",
    "ReferenceGenerator",
    "TransformerCVAE",
    "TransformerCVAEConfig",
    "TransformerCVAEGenerator",
    "WEIGHTS_DIR",
    "lie_targets",
    "load_reference_generator",
    "train_reference_generator",
    "training_crops",
    "unwrap_rotvecs",
]
