"""Synthetic flaws: masks are honest, seeds are deterministic, severities grow, each family does what it says."""
from __future__ import annotations

import numpy as np
import pytest

from refiner.concepts.segmentation import segment
from refiner.core.motion import Motion
from refiner.evaluation.flaws import FLAW_FAMILIES, SEVERITIES, Corruption, corrupt
from refiner.evaluation.physics import foot_skating_ratio, heights


@pytest.fixture(scope="module")
def clips(humanact12):
    """16 held-out clips (subjects 11-12) of at least 30 frames, with segmentations and same-action donors."""
    test = [m for m in humanact12.split("test").motions if m.n_frames >= 30][::8][:16]
    segs = [segment(m.joints) for m in test]
    donors = [[d for d in humanact12.split("test").motions if d.action == m.action and d is not m][:4] for m in test]
    return test, segs, donors


def _timeline(n_frames=41):
    """A clip whose x coordinate is the frame index / 100, so the source time of every frame can be read back."""
    x = np.zeros((n_frames, 24, 3), np.float32)
    x[..., 0] = np.arange(n_frames, dtype=np.float32)[:, None] / 100.0
    x[..., 1] = np.linspace(-0.9, 0.9, 24, dtype=np.float32)[None, :]  # a vertical line of joints
    return Motion(x)


@pytest.mark.real_data
@pytest.mark.parametrize("family", list(FLAW_FAMILIES))
def test_masks_determinism_and_monotone_severity(family, clips):
    test, segs, donors = clips
    errors = {s: [] for s in SEVERITIES}
    for i, m in enumerate(test):
        before = m.numpy()
        for s in SEVERITIES:
            c = corrupt(m, family, s, random_state=i, segmentation=segs[i], donors=donors[i])
            assert isinstance(c, Corruption)
            bad, mask = c
            assert mask.dtype == bool and mask.shape == (m.n_frames,) and mask.any()
            assert (bad.skeleton, bad.fps, bad.action, bad.n_frames) == (m.skeleton, m.fps, m.action, m.n_frames)
            np.testing.assert_array_equal(bad.joints[~mask], m.joints[~mask])  # untouched outside the mask
            assert not np.array_equal(bad.joints, m.joints)
            errors[s].append(np.linalg.norm(bad.joints - m.joints, axis=-1).mean())
            again = corrupt(m, family, s, random_state=i, donors=donors[i])  # recomputes the segmentation
            np.testing.assert_array_equal(again.motion.joints, bad.joints)
            np.testing.assert_array_equal(again.mask, mask)
        np.testing.assert_array_equal(m.joints, before)
    means = [np.mean(errors[s]) for s in SEVERITIES]
    assert means[0] < means[1] < means[2], means
    # another seed gives another corruption (except where a clip leaves no choice, e.g. one long transition)
    differ = [len({corrupt(m, family, 2, random_state=seed, segmentation=segs[i], donors=donors[i])
                   .motion.joints.tobytes() for seed in range(4)}) > 1 for i, m in enumerate(test)]
    assert np.mean(differ) >= 0.5, differ


@pytest.mark.real_data
def test_wrong_anchor_keeps_the_root_path_and_changes_the_pose(clips):
    test, segs, donors = clips
    for i, m in enumerate(test[:6]):
        bad, mask = corrupt(m, "wrong_anchor", 3, random_state=i, segmentation=segs[i], donors=donors[i])
        np.testing.assert_allclose(bad.joints[:, 0], m.joints[:, 0], atol=1e-6)
        frames = np.flatnonzero(mask)
        assert frames[0] - 1 in segs[i].anchors and frames[-1] + 1 in segs[i].anchors
        worst = np.linalg.norm(bad.joints - m.joints, axis=-1).mean(-1).max()
        assert worst > 0.05  # the anchor's pose moved by more than 5 cm per joint on average


@pytest.mark.real_data
def test_jitter_leaves_anchors_and_drift_starts_at_zero(clips):
    test, segs, _ = clips
    for i, m in enumerate(test[:6]):
        jit, jmask = corrupt(m, "transition_jitter", 3, random_state=i, segmentation=segs[i])
        np.testing.assert_array_equal(jit.joints[segs[i].anchors], m.joints[segs[i].anchors])
        assert not jmask[segs[i].anchors].any()
        drift, dmask = corrupt(m, "anchor_drift", 3, random_state=i, segmentation=segs[i])
        assert not dmask[0] and dmask[1:].all()
        np.testing.assert_array_equal(drift.joints[0], m.joints[0])


def test_retiming_families_on_a_timeline():
    clip = _timeline(41)  # one cubic: a single transition 0..40
    read = lambda c: c.motion.joints[:, 0, 0] * 100.0  # source time of each frame
    frozen = corrupt(clip, "frozen_transition", 2, random_state=0)
    src = read(frozen)
    assert np.allclose(src[: round(0.6 * 40) + 1], 0.0, atol=1e-4) and src[-1] == pytest.approx(40.0)
    rev = corrupt(clip, "reversed_transition", 2, random_state=0)
    steps = np.diff(read(rev))
    assert (steps < -1e-3).any() and read(rev)[-1] == pytest.approx(40.0)  # plays backwards for a while
    warp = corrupt(clip, "time_warp", 3, random_state=0)
    steps = np.diff(read(warp))
    assert (steps > -1e-4).all() and steps.max() > 1.5 and steps.min() < 0.5  # monotone, uneven speed


@pytest.mark.real_data
def test_foot_sliding_is_horizontal_and_skates(clips):
    test, segs, _ = clips
    before, after = [], []
    for i, m in enumerate(test):
        bad, mask = corrupt(m, "foot_sliding", 3, random_state=i)
        np.testing.assert_allclose(heights(bad), heights(m), atol=1e-5)  # only horizontal motion
        offset = bad.joints - m.joints
        np.testing.assert_allclose(offset, offset[:, :1].repeat(24, axis=1), atol=1e-6)  # whole body moves
        assert np.linalg.norm(offset[:, 0], axis=-1).max() == pytest.approx(0.4, abs=0.01)
        assert mask.sum() <= 18
        before.append(foot_skating_ratio(m))
        after.append(foot_skating_ratio(bad))
    assert np.mean(after) > np.mean(before) + 0.05


def test_errors_are_clear(tiny_clip):
    m = Motion(tiny_clip, action=1)
    with pytest.raises(ValueError, match="unknown flaw family"):
        corrupt(m, "teleport")
    with pytest.raises(ValueError, match="severity"):
        corrupt(m, "time_warp", 4)
    with pytest.raises(ValueError, match="too short"):
        corrupt(m.crop(0, 5), "time_warp")
    with pytest.raises(ValueError, match="segmentation"):
        corrupt(m, "time_warp", segmentation=segment(tiny_clip[:30]))
    with pytest.raises(ValueError, match="action"):
        corrupt(m, "wrong_anchor", donors=[Motion(tiny_clip, action=2)])
    out = corrupt(tiny_clip, "wrong_anchor", 1)  # arrays are taken as HumanAct12 clips
    assert out.motion.n_frames == len(tiny_clip)
