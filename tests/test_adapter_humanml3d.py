"""HumanML3D features shared by MotionDiffuse and MoGenTS: recover_from_ric, the feature builder, 22 -> 24 / 18."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from refiner.adapters import humanml3d as h3d
from refiner.core.rotations import yup_to_ydown


def yup_clip(motion):
    """A real HumanAct12 clip (y down) as HumanML3D-style y-up 22 joints."""
    return yup_to_ydown(motion.numpy())[:, :22]


def test_recover_from_ric_follows_the_spec():
    """§5.2 by hand: constant yaw step w (half-angle) and forward speed v give root(t) = sum R_y(-2a) (0,0,v).

    R_y(phi) is the quaternion (cos phi/2, 0, sin phi/2, 0) acting as HumanML3D's ``qrot``:
    (x, y, z) -> (x cos phi + z sin phi, y, -x sin phi + z cos phi).
    """
    t, w, v = 30, 0.02, 0.05
    feats = np.zeros((t, 263))
    feats[:, 0] = w
    feats[:, 2] = v
    feats[:, 3] = 0.9
    feats[:, 4:7] = [0.1, 1.0, 0.0]  # joint 1 at +x in the heading frame
    joints = h3d.recover_from_ric(feats)
    a = w * np.arange(t)  # a(t) = sum_{s<t} w
    step = np.stack([-np.sin(2 * a) * v, np.zeros(t), np.cos(2 * a) * v], -1)
    step[0] = 0
    root = np.cumsum(step, 0)
    np.testing.assert_allclose(joints[:, 0, [0, 2]], root[:, [0, 2]], atol=1e-12)
    np.testing.assert_allclose(joints[:, 0, 1], 0.9)
    np.testing.assert_allclose(joints[:, 1] - joints[:, 0] * [1, 0, 1],
                               np.stack([0.1 * np.cos(2 * a), np.ones(t), 0.1 * np.sin(2 * a)], -1), atol=1e-12)


@pytest.mark.real_data
def test_features_built_from_known_joints_recover_them(humanact12):
    """joints -> 263 features -> recover_from_ric gives the joints back up to one yaw + ground translation."""
    for i in (3, 640):
        joints = yup_clip(humanact12.motions[i])
        before = joints.copy()
        feats = h3d.joints_to_features(joints)
        assert feats.shape == (len(joints) - 1, 263)
        np.testing.assert_array_equal(joints, before)
        rec = h3d.recover_from_ric(feats)
        truth = joints[:-1]
        np.testing.assert_allclose(rec[..., 1], truth[..., 1], atol=1e-9)  # heights untouched
        # one rigid motion about +y for the whole clip (Kabsch on all points), independent of the builder
        a = truth.reshape(-1, 3) - truth.reshape(-1, 3).mean(0)
        b = rec.reshape(-1, 3) - rec.reshape(-1, 3).mean(0)
        rot, rssd = Rotation.align_vectors(b, a)
        assert rssd / np.sqrt(len(a)) < 1e-9
        axis = rot.as_rotvec()
        assert np.abs(axis[[0, 2]]).max() < 1e-9  # a yaw
        # frame 0: root at x = z = 0, facing +z (shoulders and hips across -x)
        np.testing.assert_allclose(rec[0, 0, [0, 2]], 0.0, atol=1e-12)
        across = rec[0, 2] - rec[0, 1] + rec[0, 17] - rec[0, 16]
        assert abs(across[2]) < 1e-9 and across[0] < 0
        # the root velocity dims agree with a finite difference of the recovered joints
        np.testing.assert_allclose(feats[:-1, 193:196], _local_root_velocity(rec), atol=1e-9)


def _local_root_velocity(rec):
    """Root displacement t -> t+1 rotated into frame t's heading frame (dims 193-195 of frame t)."""
    r_hip, l_hip, r_sdr, l_sdr = 2, 1, 17, 16
    across = rec[:, r_hip] - rec[:, l_hip] + rec[:, r_sdr] - rec[:, l_sdr]
    fwd = np.cross([0.0, 1.0, 0.0], across)
    theta = np.arctan2(fwd[:, 0], fwd[:, 2])
    d = rec[1:, 0] - rec[:-1, 0]
    c, s = np.cos(-theta[:-1]), np.sin(-theta[:-1])
    return np.stack([c * d[:, 0] + s * d[:, 2], d[:, 1], -s * d[:, 0] + c * d[:, 2]], -1)


@pytest.mark.real_data
def test_to_humanact12_adds_hands_and_flips_to_y_down(humanact12):
    real = humanact12.motions[10].numpy()
    j22 = yup_clip(humanact12.motions[10])
    out = h3d.to_humanact12(j22)
    assert out.shape == (len(real), 24, 3)
    # (x, y, z) -> (x, -y, -z) then frame-0 root at the origin: the original y-down clip, recentred
    np.testing.assert_allclose(out[:, :22], real[:, :22] - real[:1, :1], atol=1e-5)
    for hand, wrist, elbow in ((22, 20, 18), (23, 21, 19)):
        np.testing.assert_allclose(np.linalg.norm(out[:, hand] - out[:, wrist], axis=-1), 0.08, atol=1e-9)
        fore = out[:, wrist] - out[:, elbow]
        cos = np.sum((out[:, hand] - out[:, wrist]) * fore, -1) / np.linalg.norm(fore, axis=-1) / 0.08
        np.testing.assert_allclose(cos, 1.0, atol=1e-9)
    assert (out[:, 15, 1] < out[:, 0, 1]).all()  # head above the pelvis means smaller y
    # the real HumanAct12 hands lie close to the extrapolated ones (same forearm direction)
    assert np.linalg.norm(out[:, 22] - (real[:, 22] - real[:1, :1]), axis=-1).mean() < 0.05


@pytest.mark.real_data
def test_to_uestc_heuristic_keypoints_are_plausible(humanact12):
    """Direct correspondences exact; nose, heels and head top near NTU-VIBE's bone lengths (§1.2)."""
    stats = []
    for i in range(0, 1191, 60):
        j22 = yup_clip(humanact12.motions[i])
        out = h3d.to_uestc(j22)
        assert out.shape == (len(j22), 18, 3)
        ref = yup_to_ydown(j22)
        ref = ref - ref[:1, :1]
        np.testing.assert_allclose(out[:, [1, 2, 4, 5, 7, 9, 11, 12, 14]], ref[:, [12, 17, 21, 16, 20, 2, 8, 1, 7]], atol=1e-9)
        stats.append([
            np.linalg.norm(out[:, 8] - out[:, 1], axis=-1).mean(),   # neck -> nose, NTU 0.203
            np.linalg.norm(out[:, 17] - out[:, 8], axis=-1).mean(),  # nose -> head top, NTU 0.191
            np.linalg.norm(out[:, 15] - out[:, 14], axis=-1).mean(),  # l ankle -> heel, NTU 0.067
            (out[:, 17, 1] < out[:, 8, 1]).mean(),                    # head top above the nose (y down)
            (out[:, 15, 1] > out[:, 14, 1]).mean(),                   # heel below the ankle
        ])
    s = np.mean(stats, 0)
    assert abs(s[0] - 0.203) < 0.03 and abs(s[1] - 0.191) < 0.03 and abs(s[2] - 0.067) < 0.01
    assert s[3] > 0.98 and s[4] > 0.98


def test_features_to_motions_errors(rng):
    feats = rng.normal(size=(2, 20, 263))
    with pytest.raises(ValueError, match="`mean` is needed"):
        h3d.features_to_motions(feats, std=np.ones(263))
    with pytest.raises(ValueError, match="`std` is needed"):
        h3d.features_to_motions(feats, mean=np.zeros(263))
    with pytest.raises(ValueError, match=r"`mean` must have shape \(263,\)"):
        h3d.features_to_motions(feats, mean=np.zeros(251), std=np.ones(263))
    with pytest.raises(ValueError, match=r"\(T, 263\) or \(B, T, 263\)"):
        h3d.features_to_motions(np.zeros((2, 20, 251)), denormalized=True)
    with pytest.raises(ValueError, match=r"lengths\[1\]"):
        h3d.features_to_motions(feats, denormalized=True, lengths=[20, 30])
    with pytest.raises(ValueError, match="'humanact12' or 'uestc'"):
        h3d.features_to_motions(feats, denormalized=True, skeleton="humanml3d")
    with pytest.raises(ValueError, match="does not exist"):
        h3d.features_to_motions(feats, mean="/nonexistent/mean.npy", std=np.ones(263))
    with pytest.raises(ValueError, match=r"\(T, 22, 3\)"):
        h3d.joints_to_features(np.zeros((10, 24, 3)))
