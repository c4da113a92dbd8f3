"""Flaw mechanisms: every one changes a window of the clip, leaves the input alone, is seeded, and keeps the bones
exact where it works in joint angles; the folds split every family."""
import numpy as np
import pytest

from refiner.core.bone_directions import from_bone_directions
from refiner.core.skeletons import bone_lengths
from refiner.refinement.training.mechanisms import FAMILIES, MECHANISMS, envelope, mechanisms_of


def _walk(n=60, joints=24, seed=0):
    """A rigid clip: fixed bone lengths, every bone swinging smoothly."""
    r = np.random.default_rng(seed)
    skeleton = "humanact12" if joints == 24 else "cmu_mocap"
    t = np.arange(n)[:, None, None] / 20.0
    dirs = r.normal(size=(1, joints - 1, 3)) + 0.5 * np.sin(2 * np.pi * t + r.uniform(0, 6, size=(1, joints - 1, 3)))
    root = np.concatenate([0.3 * t[:, 0], np.zeros((n, 2))], -1)
    return from_bone_directions(root, dirs, r.uniform(0.1, 0.4, joints - 1), skeleton).astype(np.float32)


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_mechanism_changes_a_window_only(name):
    clip = _walk()
    given = clip.copy()
    out = MECHANISMS[name](clip, np.random.default_rng(3))
    np.testing.assert_array_equal(clip, given)
    assert out.shape == clip.shape and out.dtype == np.float32
    moved = np.linalg.norm(out - clip, axis=-1).max(-1) > 1e-6
    assert 0 < moved.sum() <= 32 and not moved[:2].any()
    np.testing.assert_array_equal(MECHANISMS[name](clip, np.random.default_rng(3)), out)


@pytest.mark.parametrize("name", [k for k, m in MECHANISMS.items() if m.family in ("angle", "root") or k in ("time_hold", "time_reverse", "time_skip")])
def test_rigid_mechanisms_keep_every_bone(name):
    clip = _walk()
    out = MECHANISMS[name](clip, np.random.default_rng(5))
    np.testing.assert_allclose(bone_lengths(out, "humanact12"), bone_lengths(clip, "humanact12"), atol=1e-5)


def test_mechanisms_run_on_another_skeleton():
    clip = _walk(joints=20)
    for name, m in MECHANISMS.items():
        assert m(clip, np.random.default_rng(1), skeleton="cmu_mocap").shape == clip.shape, name


def test_every_family_has_mechanisms_in_both_folds():
    for family in FAMILIES:
        assert {m.fold for m in MECHANISMS.values() if m.family == family} == {0, 1}
    assert set(mechanisms_of(0)) | set(mechanisms_of(1)) == set(MECHANISMS)
    assert not set(mechanisms_of(0)) & set(mechanisms_of(1))


def test_envelope_ramps_in_and_out():
    w = envelope(40, 10, 30, 5)
    assert w[:10].max() == 0 and w[30:].max() == 0 and w[18:22].min() == 1.0
    assert np.all(np.diff(w[10:20]) >= 0)
