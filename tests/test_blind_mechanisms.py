"""Blind flaw mechanisms: shapes, purity, determinism, exact bone lengths and a local, visible change."""
from __future__ import annotations

import numpy as np
import pytest

from refiner.core.skeletons import bone_lengths, get_skeleton
from refiner.evaluation.blind_mechanisms import MECHANISMS

SKEL = get_skeleton("humanact12")


def _rigid_clip(n_frames: int, seed: int = 0) -> np.ndarray:
    """A synthetic rigid-skeleton walk-like clip: smoothly swinging bones of fixed length, a moving root."""
    rng = np.random.default_rng(seed)
    rest = np.array([[0, 0, 0], [.06, .09, 0], [-.06, .09, 0], [0, -.11, 0], [0, .38, 0], [0, .38, 0],
                     [0, -.13, 0], [0, .40, 0], [0, .40, 0], [0, -.06, 0], [0, .05, -.12], [0, .05, -.12],
                     [0, -.23, 0], [.08, -.12, 0], [-.08, -.12, 0], [0, -.1, 0], [.1, .02, 0], [-.1, .02, 0],
                     [0, .26, 0], [0, .26, 0], [0, .25, 0], [0, .25, 0], [0, .09, 0], [0, .09, 0]], float)
    t = np.arange(n_frames)[:, None, None] / 20.0
    phase, freq = rng.uniform(0, 2 * np.pi, (1, 24, 3)), rng.uniform(0.3, 1.5, (1, 24, 3))
    dirs = rest / np.maximum(np.linalg.norm(rest, axis=-1, keepdims=True), 1e-9)
    dirs = dirs + 0.5 * np.sin(2 * np.pi * freq * t + phase)
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    x = np.zeros((n_frames, 24, 3))
    x[:, 0] = np.stack([0.1 * np.sin(t[:, 0, 0]), 0.02 * np.sin(6 * t[:, 0, 0]), -1.2 * t[:, 0, 0]], -1)
    for j, p in enumerate(SKEL.parents):
        if p >= 0:
            x[:, j] = x[:, p] + np.linalg.norm(rest[j]) * dirs[:, j]
    return (x - x[:1, :1]).astype(np.float32)


@pytest.mark.parametrize("name", sorted(MECHANISMS))
@pytest.mark.parametrize("n_frames", [40, 97, 200])
def test_shape_purity_and_bones(name, n_frames):
    clip = _rigid_clip(n_frames, seed=n_frames)
    before = clip.copy()
    clip.flags.writeable = False
    for seed in range(5):
        for severity in (0.5, 1.0, 2.0):
            out = MECHANISMS[name](clip, np.random.default_rng(seed), severity)
            assert out.shape == clip.shape and out.dtype == np.float32 and np.isfinite(out).all()
            assert out is not clip and np.array_equal(clip, before)
            err = np.abs(bone_lengths(out, SKEL) - bone_lengths(clip, SKEL)).max()
            assert err < 1e-5


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_deterministic_for_a_seed(name):
    clip = _rigid_clip(80)
    a = MECHANISMS[name](clip, np.random.default_rng(7))
    b = MECHANISMS[name](clip, np.random.default_rng(7))
    assert np.array_equal(a, b)
    others = [MECHANISMS[name](clip, np.random.default_rng(s)) for s in range(8, 12)]
    assert any(not np.array_equal(a, o) for o in others)


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_change_is_local_and_visible(name):
    clip = _rigid_clip(120, seed=3)
    for seed in range(10):
        out = MECHANISMS[name](clip, np.random.default_rng(seed))
        disp = np.linalg.norm(out - clip, axis=-1)
        changed = np.flatnonzero(disp.max(1) > 1e-5)
        assert changed.size and changed[0] >= 1
        assert changed[-1] - changed[0] + 1 <= 30
        assert disp.max() > 0.03


def test_float64_input_and_zero_severity():
    clip = _rigid_clip(60).astype(np.float64)
    for fn in MECHANISMS.values():
        out = fn(clip, np.random.default_rng(0), 0.0)
        assert out.dtype == np.float32
        assert np.abs(out - clip).max() < 1e-5


def test_each_frame_keeps_its_own_bone_lengths():
    clip = _rigid_clip(70, seed=5) + np.random.default_rng(1).normal(0, 0.005, (70, 24, 3)).astype(np.float32)
    for fn in MECHANISMS.values():
        for seed in range(4):
            out = fn(clip, np.random.default_rng(seed))
            assert np.abs(bone_lengths(out, SKEL) - bone_lengths(clip, SKEL)).max() < 1e-5
