"""Tests of refiner.io.bvh: exact round trips on real and rigid synthetic motions, the reader's conventions, errors."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from refiner.core.motion import Motion
from refiner.core.skeletons import get_skeleton, list_skeletons
from refiner.io.bvh import bvh_frame, load_bvh, load_bvh_motion, save_bvh


def _rigid_motion(skeleton: str, n_frames: int, rng) -> np.ndarray:
    """Joint positions from forward kinematics of random rigid bones: every skeleton, branching joints included."""
    skel = get_skeleton(skeleton)
    offsets = rng.normal(size=(skel.n_joints, 3)) * 0.15
    t = np.linspace(0.0, 1.0, n_frames)[:, None]
    rotvecs = rng.normal(size=(skel.n_joints, 3)) * 1.2 * t[:, :, None] + rng.normal(size=(skel.n_joints, 3)) * 0.3
    pos = np.zeros((n_frames, skel.n_joints, 3))
    glob = np.zeros((n_frames, skel.n_joints, 3, 3))
    for j, p in enumerate(skel.parents):
        rot = Rotation.from_rotvec(rotvecs[:, j]).as_matrix()
        if p < 0:
            pos[:, j] = np.array([0.3, -0.9, 2.5]) + t * np.array([0.5, 0.0, -0.4])
            glob[:, j] = rot
        else:
            pos[:, j] = pos[:, p] + glob[:, p] @ offsets[j]
            glob[:, j] = glob[:, p] @ rot
    return pos.astype(np.float32)


@pytest.mark.real_data
def test_real_humanact12_roundtrip(humanact12, tmp_path):
    for i in (0, 250, 700, 1190):
        motion = humanact12[i]
        path = tmp_path / f"clip{i}.bvh"
        err = save_bvh(motion, path)
        joints, names = load_bvh(path)
        assert names == list(motion.skeleton_info.joint_names)
        assert joints.shape == motion.joints.shape
        dist = np.linalg.norm(joints - motion.joints, axis=-1)
        assert dist.max() < 1e-3  # the acceptance: 1 mm
        assert dist.max() < 5e-5  # measured: about 5e-6 m (float32 data, 6 written decimals)
        assert abs(err - dist.max()) < 1e-5  # the reported error is the reload error
        again = load_bvh_motion(path)
        assert again.skeleton == "humanact12" and again.fps == motion.fps
        np.testing.assert_allclose(again.joints, motion.joints, atol=1e-3)


@pytest.mark.parametrize("skeleton", list_skeletons())
def test_rigid_roundtrip_every_skeleton(skeleton, tmp_path, rng):
    joints = _rigid_motion(skeleton, 25, rng)
    before = joints.copy()
    err = save_bvh(Motion(joints, skeleton=skeleton, fps=30.0), tmp_path / "m.bvh")
    np.testing.assert_array_equal(joints, before)
    assert err < 2e-5
    back, names = load_bvh(tmp_path / "m.bvh")
    assert names == list(get_skeleton(skeleton).joint_names)
    np.testing.assert_allclose(back, joints, atol=2e-5)
    assert load_bvh_motion(tmp_path / "m.bvh").fps == 30.0


def test_file_is_y_up_and_depth_first(tmp_path):
    """The file uses the BVH convention: Y up, facing +Z; joints listed depth first."""
    np.testing.assert_array_equal(bvh_frame("humanact12"), np.diag([1.0, -1.0, -1.0]))
    np.testing.assert_array_equal(bvh_frame("humanml3d"), np.eye(3))
    clip = np.zeros((3, 24, 3), dtype=np.float32)
    clip[:] = np.array([0.0, 0.0, 2.0])
    skel = get_skeleton("humanact12")
    going_up = {"spine1", "spine2", "spine3", "neck", "left_collar", "right_collar", "head"}
    for j in range(1, 24):  # every child 10 cm from its parent: spine and head up (-y), legs and arms down
        step = [0.02 * (j % 3 - 1), -0.1 if skel.joint_names[j] in going_up else 0.1, 0.0]
        clip[:, j] = clip[:, skel.parents[j]] + np.array(step, dtype=np.float32)
    save_bvh(Motion(clip), tmp_path / "s.bvh")
    raw, names = load_bvh(tmp_path / "s.bvh", skeleton=None)
    assert names[:5] == ["pelvis", "left_hip", "left_knee", "left_ankle", "left_foot"]
    np.testing.assert_allclose(raw, clip[:, [skel.index(n) for n in names]] @ bvh_frame("humanact12").T, atol=1e-5)
    head, pelvis = raw[0, names.index("head")], raw[0, names.index("pelvis")]
    assert head[1] > pelvis[1] + 0.3  # up is +Y in the file
    text = (tmp_path / "s.bvh").read_text()
    assert text.startswith("HIERARCHY\nROOT pelvis\n") and "Frame Time: 0.05000000" in text
    assert text.count("End Site") == 5  # feet, hands and head keep their names as joints


def test_reader_conventions(tmp_path):
    """A hand-written file: position channels replace the root offset, rotations compose in listed order."""
    path = tmp_path / "hand.bvh"
    path.write_text(
        "HIERARCHY\nROOT hips\n{\n  OFFSET 5 5 5\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        "  JOINT arm\n  {\n    OFFSET 0 1 0\n    CHANNELS 3 Xrotation Yrotation Zrotation\n"
        "    End Site\n    {\n      OFFSET 0 2 0\n    }\n  }\n}\n"
        "MOTION\nFrames: 2\nFrame Time: 0.1\n"
        "1 2 3 0 0 0 0 0 0\n"
        "1 2 3 90 0 0 0 0 0\n"
    )
    joints, names = load_bvh(path)  # matches no registered skeleton: file order and frame
    assert names == ["hips", "arm"] and joints.dtype == np.float32
    np.testing.assert_allclose(joints[0], [[1, 2, 3], [1, 3, 3]], atol=1e-6)
    np.testing.assert_allclose(joints[1], [[1, 2, 3], [0, 2, 3]], atol=1e-6)  # Rz(90) (0,1,0) = (-1,0,0)
    with pytest.raises(ValueError, match="no registered skeleton"):
        load_bvh_motion(path)


def test_drifting_bones_warn(tmp_path, rng):
    joints = _rigid_motion("humanact12", 20, rng)
    joints[:, 18:] *= 1.0 + 0.05 * np.linspace(0, 1, 20)[:, None, None]  # arms stretch over the clip
    with pytest.warns(UserWarning, match="fixed bone offsets"):
        err = save_bvh(joints, tmp_path / "d.bvh")
    back, _ = load_bvh(tmp_path / "d.bvh")
    assert err > 1e-3
    assert abs(np.linalg.norm(back - joints, axis=-1).max() - err) < 1e-5

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        err = save_bvh(joints, tmp_path / "e.bvh", translations=True)  # per-joint positions: exact again
    back, _ = load_bvh(tmp_path / "e.bvh")
    assert err < 2e-5
    np.testing.assert_allclose(back, joints, atol=2e-5)
    assert (tmp_path / "e.bvh").read_text().count("CHANNELS 6") == 24


def test_save_bad_input(tmp_path):
    with pytest.raises(ValueError, match="shape"):
        save_bvh(np.zeros((10, 23, 3)), tmp_path / "x.bvh")
    with pytest.raises(ValueError, match="shape"):
        save_bvh(np.zeros((10, 24)), tmp_path / "x.bvh")
    bad = np.zeros((10, 24, 3))
    bad[4, 2, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        save_bvh(bad, tmp_path / "x.bvh")
    with pytest.raises(ValueError, match="translations"):
        save_bvh(np.zeros((10, 24, 3)), tmp_path / "x.bvh", translations="yes")
    with pytest.raises(ValueError, match="tol"):
        save_bvh(np.zeros((10, 24, 3)), tmp_path / "x.bvh", tol=-1)
    with pytest.raises(ValueError, match="unknown skeleton"):
        save_bvh(np.zeros((10, 24, 3)), tmp_path / "x.bvh", skeleton="smpl99")
    assert not (tmp_path / "x.bvh").exists()


def test_load_bad_files(tmp_path, rng):
    with pytest.raises(ValueError, match="not found"):
        load_bvh(tmp_path / "missing.bvh")
    good = tmp_path / "g.bvh"
    save_bvh(Motion(_rigid_motion("uestc", 4, rng), skeleton="uestc"), good)
    text = good.read_text()
    with pytest.raises(ValueError, match="do not match skeleton 'humanact12'"):
        load_bvh(good, skeleton="humanact12")
    cases = {
        "no MOTION": text.replace("MOTION", "MOVE"),
        "HIERARCHY": text.replace("HIERARCHY", "HIER"),
        "values": text.rsplit("\n", 2)[0] + "\n",  # last frame dropped
        "NaN": text[: text.rindex(" ")] + " nan\n",
        "unclosed": text.replace("}\nMOTION", "MOTION", 1),
        "channel": text.replace("Zrotation", "Wrotation", 1),
        "Frames": text.replace("Frames:", "Frame count:"),
    }
    for match, broken in cases.items():
        path = tmp_path / "b.bvh"
        path.write_text(broken)
        with pytest.raises(ValueError, match=match):
            load_bvh(path)
