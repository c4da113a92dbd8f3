"""Physical plausibility metrics on constructed clips with known answers."""
from __future__ import annotations

import numpy as np
import pytest

from refiner.core.motion import Motion
from refiner.evaluation.physics import (
    acceleration,
    acceleration_error,
    bone_length_variation,
    boundary_velocity_jump,
    contact_joints,
    floating,
    foot_joints,
    foot_skate_distance,
    foot_skating_ratio,
    ground_height,
    heights,
    jerk,
    penetration,
)


@pytest.fixture(scope="module")
def pose(humanact12):
    """A real standing HumanAct12 pose, y down, with its feet as the lowest joints."""
    return humanact12.motions[0].joints[0].astype(np.float64)


def _standing(pose, n_frames=40):
    return np.repeat(pose[None], n_frames, axis=0)


def _horizontal_line(n_frames, speed, fps=20.0):
    """x offsets (T, 1, 3) moving along +x at ``speed`` m/s."""
    t = np.arange(n_frames) / fps
    return np.stack([speed * t, 0 * t, 0 * t], -1)[:, None, :]


def test_heights_follow_the_skeleton_up_axis(pose):
    assert heights(np.array([[0.0, -1.0, 0.0]]), "humanact12")[0] == 1.0  # y down
    assert heights(np.array([[0.0, -1.0, 0.0]]), "humanml3d")[0] == -1.0  # y up
    h = heights(pose, "humanact12")
    assert h[15] > h[0] > h[10]  # head above pelvis above foot
    assert foot_joints("humanact12") == (10, 11) and foot_joints("cmu_mocap") == (15, 19)
    assert set(foot_joints("humanact12")) <= set(contact_joints("humanact12"))
    assert ground_height(_standing(pose)) == pytest.approx(h[list(contact_joints("humanact12"))].min())


def test_constant_acceleration_and_cubic_jerk():
    fps = 20.0
    t = np.arange(50) / fps
    clip = np.zeros((50, 24, 3))
    clip[..., 0] = (0.5 * 3.0 * t**2)[:, None]  # 3 m/s² along x
    assert acceleration(clip, fps=fps) == pytest.approx(3.0)
    assert jerk(clip, fps=fps) == pytest.approx(0.0, abs=1e-6)
    clip[..., 2] = (0.7 * t**3)[:, None]  # jerk 6 * 0.7 = 4.2 m/s³ along z
    assert jerk(clip, fps=fps) == pytest.approx(4.2, rel=1e-6)
    assert jerk(Motion(clip, fps=fps)) == pytest.approx(4.2, rel=1e-3)  # float32 joints
    assert acceleration(clip, fps=2 * fps) > acceleration(clip, fps=fps)  # units follow fps
    still = np.zeros((50, 24, 3))
    still[..., 0] = (1.5 * t)[:, None]  # constant velocity
    assert acceleration_error(clip, still, fps=fps) > 3.0
    assert acceleration_error(still, still, fps=fps) == 0.0
    batch = np.stack([clip, still])
    np.testing.assert_allclose(acceleration(batch, fps=fps), [acceleration(clip, fps=fps), 0.0], atol=1e-9)


def test_sliding_standing_body_is_skating(pose):
    standing = _standing(pose, 40)
    assert foot_skating_ratio(standing) == 0.0
    fast = standing + _horizontal_line(40, 1.0)  # 1 m/s > 0.5 m/s, feet on the ground
    assert foot_skating_ratio(fast) == 1.0
    assert foot_skate_distance(fast) == pytest.approx(1.0 / 20.0)  # 5 cm per frame
    slow = standing + _horizontal_line(40, 0.3)
    assert foot_skating_ratio(slow) == 0.0
    # lifted 20 cm above the ground of the standing clip: no contact, no skating
    lifted = fast + np.array([0.0, -0.2, 0.0])
    assert foot_skating_ratio(lifted, ground=ground_height(standing)) == 0.0


def test_half_of_the_clip_sliding(pose):
    standing = _standing(pose, 41)
    offset = np.zeros((41, 1, 3))
    offset[20:, 0, 0] = np.arange(21) * 0.05  # 1 m/s from frame 20 on
    ratio = foot_skating_ratio(standing + offset)
    # 20 of 40 frame pairs move; each is fast itself and its zero-padded 5-pair mean is >= 0.6 m/s,
    # while the still pairs are slow themselves, so exactly the 20 moving pairs count
    assert ratio == pytest.approx(20 / 40)


def test_one_foot_sliding_counts_once(pose):
    standing = _standing(pose, 30)
    slide = standing.copy()
    slide[:, 10, 0] += np.arange(30) * 0.05  # only the left foot joint slides, 1 m/s
    assert foot_skating_ratio(slide) == 1.0
    assert foot_skate_distance(slide) == pytest.approx(0.05 / 2)  # one of two feet moves 5 cm per frame


def test_sunk_and_floating_bodies(pose):
    standing = _standing(pose, 30)
    ground = ground_height(standing)
    assert penetration(standing) == 0.0 and floating(standing) == 0.0
    sunk = standing + np.array([0.0, 0.05, 0.0])  # y down: +5 cm in y is 5 cm lower
    assert penetration(sunk, ground=ground) == pytest.approx(0.05)
    assert floating(sunk, ground=ground) == 0.0
    half = standing.copy()
    half[15:] += np.array([0.0, -0.10, 0.0])  # second half 10 cm up
    assert floating(half, ground=ground) == pytest.approx(0.5 * (0.10 - 0.005))
    assert penetration(half, ground=ground) == 0.0
    np.testing.assert_allclose(penetration(np.stack([standing, sunk]), ground=ground), [0.0, 0.05])
    # the same scene in a y-up skeleton gives the same numbers
    up = standing[:, :22] * np.array([1.0, -1.0, -1.0])
    sunk_up = up - np.array([0.0, 0.05, 0.0])
    assert penetration(sunk_up, skeleton="humanml3d", ground=ground_height(up, skeleton="humanml3d")) == \
        pytest.approx(0.05)


def test_bone_length_variation(pose):
    rigid = _standing(pose, 20) + _horizontal_line(20, 0.7)
    assert bone_length_variation(rigid) == pytest.approx(0.0, abs=1e-6)
    stretched = rigid.copy()
    # left hand (23) along its bone from the left wrist (21), alternately 10 % longer and shorter
    bone = pose[23] - pose[21]
    stretched[::2, 23] += 0.1 * bone
    stretched[1::2, 23] -= 0.1 * bone
    per_bone = bone_length_variation(stretched, per_bone=True)
    assert per_bone.shape == (23,)
    assert per_bone[22] == pytest.approx(0.1, rel=1e-6)  # bone 22 = (21, 23)
    assert np.delete(per_bone, 22).max() < 1e-6
    assert bone_length_variation(stretched) == pytest.approx(0.1 / 23, rel=1e-5)


def test_boundary_velocity_jump():
    fps = 20.0
    n = 40
    t = np.arange(n, dtype=np.float64)
    a = 0.001  # m per frame² everywhere: s(t) = a * fps = 0.02 m/s
    x = 0.5 * a * t**2
    kink = np.where(t > 20, (t - 20) * 0.01, 0.0)  # velocity +1 cm/frame after frame 20
    clip = np.zeros((n, 24, 3))
    clip[..., 0] = (x + kink)[:, None]
    mask = t > 20  # frames 21.. changed: boundary between frames 20 and 21
    res = boundary_velocity_jump(clip, mask, fps=fps)
    assert res.jump == pytest.approx((a + 0.01) * fps)
    assert res.reference == pytest.approx(a * fps)
    assert res.ratio == pytest.approx((a + 0.01) / a)
    smooth = boundary_velocity_jump(clip[..., :] * 0 + x[:, None, None], mask, fps=fps)
    assert smooth.ratio == pytest.approx(1.0)
    none = boundary_velocity_jump(clip, np.zeros(n, bool), fps=fps)
    assert np.isnan(none.jump) and np.isnan(none.ratio)
    with pytest.raises(ValueError, match="mask"):
        boundary_velocity_jump(clip, np.zeros(n - 1, bool))
    with pytest.raises(ValueError, match="mask"):
        boundary_velocity_jump(clip, np.zeros(n))


def test_inputs_are_checked_and_untouched(pose):
    clip = _standing(pose, 10)
    before = clip.copy()
    for fn in (acceleration, jerk, foot_skating_ratio, penetration, floating, bone_length_variation):
        fn(clip)
    np.testing.assert_array_equal(clip, before)
    with pytest.raises(ValueError, match="fps"):
        acceleration(clip, fps=0)
    with pytest.raises(ValueError, match="too short"):
        jerk(clip[:3])
    with pytest.raises(ValueError, match="J=24"):
        acceleration(clip[:, :22])
    with pytest.raises(ValueError, match="ground"):
        penetration(clip, ground=[0.0, 1.0])
