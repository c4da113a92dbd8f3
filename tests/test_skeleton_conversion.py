"""Skeleton conversion (refiner.core.skeletons.convert, Motion.to) on real HumanAct12 and CMU clips."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import shared_data_dir
from refiner import Motion
from refiner.core.skeletons import convert, estimated_joints, get_skeleton

CONVERTIBLE = ("humanact12", "humanml3d", "uestc", "cmu_mocap")


@pytest.fixture(scope="module")
def ha12_frames(humanact12):
    """Every 8th held-out clip (subjects 11-12), frames concatenated: (F, 24, 3) metres, y down."""
    clips = humanact12.split("test").motions[::8]
    return np.concatenate([m.joints for m in clips]).astype(np.float64)


@pytest.fixture(scope="module")
def cmu_frames():
    from refiner.io.datasets import load_cmu_mocap

    data = load_cmu_mocap(shared_data_dir() / "cmu_mocap" / "cmu_mocap_labeled_joints.npz")
    return np.concatenate([m.joints for m in data.motions[::50]]).astype(np.float64)


def _mean_error(a, b):
    return np.linalg.norm(a - b, axis=-1).mean(axis=0)  # (J,) metres


@pytest.mark.real_data
@pytest.mark.parametrize("middle", ["uestc", "cmu_mocap", "humanml3d"])
def test_humanact12_round_trip_keeps_shared_joints(ha12_frames, middle):
    """24 -> J -> 24 gives the shared joints back exactly and the estimated ones within a few cm."""
    back = convert(convert(ha12_frames, "humanact12", middle), middle, "humanact12")
    names = get_skeleton("humanact12").joint_names
    est = set(estimated_joints(middle, "humanact12"))
    shared = [i for i, n in enumerate(names) if n not in est]
    np.testing.assert_allclose(back[:, shared], ha12_frames[:, shared], atol=1e-6)
    err = dict(zip(names, _mean_error(back, ha12_frames)))
    # measured: spine 2.1-2.4 cm, collars 3.6, feet 2.3-2.9 (uestc), hands 2.5-2.8; head exact
    # (its nose / head-top estimates are inverted)
    for name in est:
        assert err[name] < 0.045, (name, err[name])
    if middle == "uestc":
        assert err["head"] < 1e-6
        assert est == {"spine1", "spine2", "spine3", "left_foot", "right_foot", "left_collar",
                       "right_collar", "head", "left_hand", "right_hand"}


@pytest.mark.real_data
def test_uestc_estimates_near_ntu_vibe_bone_lengths(ha12_frames):
    """Nose, head top and heels (mesh points) are placed near NTU-VIBE's bone lengths (§1.2)."""
    out = convert(ha12_frames, "humanact12", "uestc")
    assert estimated_joints("humanact12", "uestc") == ("nose", "left_heel", "right_heel", "head_top")
    lengths = dict(zip(np.array(get_skeleton("uestc").joint_names)[get_skeleton("uestc").bones[:, 1]],
                       get_skeleton("uestc").bone_lengths(out).mean(0)))
    assert abs(lengths["nose"] - 0.203) < 0.03 and abs(lengths["head_top"] - 0.191) < 0.03
    assert abs(lengths["left_heel"] - 0.067) < 0.01 and abs(lengths["right_heel"] - 0.070) < 0.01
    assert (out[:, 17, 1] < out[:, 8, 1]).mean() > 0.98  # head top above the nose (y down)


@pytest.mark.real_data
def test_cmu_round_trip_and_frame(cmu_frames):
    """CMU (y up) -> HumanAct12 (y down) -> CMU is exact; the head ends above the pelvis in y-down."""
    h = convert(cmu_frames, "cmu_mocap", "humanact12")
    assert estimated_joints("cmu_mocap", "humanact12") == ("spine1", "spine2", "left_collar", "right_collar")
    assert (h[:, 15, 1] < h[:, 0, 1]).mean() > 0.99 and (cmu_frames[:, 3, 1] > cmu_frames[:, 0, 1]).mean() > 0.99
    np.testing.assert_allclose(convert(h, "humanact12", "cmu_mocap"), cmu_frames, atol=1e-6)
    # through 18 joints: the spine (SMPL spine3) and toes (SMPL feet) are estimates
    back = convert(convert(cmu_frames, "cmu_mocap", "uestc"), "uestc", "cmu_mocap")
    names = get_skeleton("cmu_mocap").joint_names
    est = set(estimated_joints("uestc", "cmu_mocap"))
    shared = [i for i, n in enumerate(names) if n not in est]
    np.testing.assert_allclose(back[:, shared], cmu_frames[:, shared], atol=1e-6)
    assert _mean_error(back, cmu_frames).max() < 0.12  # toes 9 cm: CMU's toe is not SMPL's toe base


@pytest.mark.parametrize("name", CONVERTIBLE)
def test_identity_is_an_equal_copy(rng, name):
    x = rng.normal(size=(5, get_skeleton(name).n_joints, 3)).astype(np.float32)
    out = convert(x, name, name)
    np.testing.assert_array_equal(out, x)
    assert out is not x and not np.shares_memory(out, x)


@pytest.mark.parametrize("source", CONVERTIBLE)
@pytest.mark.parametrize("target", CONVERTIBLE)
def test_batch_dims_uniform_and_input_untouched(rng, source, target):
    x = rng.normal(size=(2, 3, 7, get_skeleton(source).n_joints, 3))
    before = x.copy()
    out = convert(x, source, target)
    assert out.shape == (2, 3, 7, get_skeleton(target).n_joints, 3)
    np.testing.assert_array_equal(x, before)
    np.testing.assert_allclose(out[1, 2], convert(x[1, 2], source, target), atol=1e-12)
    np.testing.assert_allclose(out[0, 1, 3], convert(x[0, 1, 3], source, target), atol=1e-12)


def test_errors_name_the_known_skeletons():
    x = np.zeros((4, 24, 3))
    with pytest.raises(ValueError, match=r"unknown skeleton 'smplx'; known: cmu_mocap, humanact12"):
        convert(x, "humanact12", "smplx")
    with pytest.raises(ValueError, match=r"unknown skeleton 'kinect'"):
        Motion(x, skeleton="humanact12").to("kinect")
    with pytest.raises(ValueError, match=r"\(\.\.\., 18, 3\) for skeleton 'uestc'; got \(4, 24, 3\)"):
        convert(x, "uestc", "humanact12")
    bad = x.copy()
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        convert(bad, "humanact12", "uestc")


def test_unmapped_registered_skeleton_is_refused():
    from refiner.core.skeletons import Skeleton

    two = Skeleton("two_joints_test", ("a", "b"), (-1, 0))  # not registered: a Skeleton is accepted as is
    with pytest.raises(ValueError, match="no joint mapping for skeleton 'two_joints_test'; convertible: cmu_mocap"):
        convert(np.zeros((3, 24, 3)), "humanact12", two)
    assert convert(np.ones((3, 2, 3)), two, two).shape == (3, 2, 3)


@pytest.mark.real_data
def test_motion_to(humanact12):
    m = humanact12.motions[100]
    frozen = m.joints.copy()
    u = m.to("uestc")
    assert (u.skeleton, u.n_joints, u.fps, u.action, u.n_frames) == ("uestc", 18, m.fps, m.action, m.n_frames)
    back = u.to("humanact12")
    shared = [i for i, n in enumerate(get_skeleton("humanact12").joint_names)
              if n not in estimated_joints("uestc", "humanact12")]
    np.testing.assert_allclose(back.joints[:, shared], m.joints[:, shared], atol=1e-6)
    same = m.to("humanact12")
    assert same == m and same is not m
    np.testing.assert_array_equal(m.joints, frozen)
