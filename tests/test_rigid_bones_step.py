"""Rigid bones: stretched bones put back within the lengths real motion gives them, feet held, nothing else touched."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import shared_data_dir, shared_dir
from refiner.core.contact import foot_joints
from refiner.core.skeletons import get_skeleton
from refiner.evaluation.physics import bone_length_variation
from refiner.refinement.motion_refiner import MotionRefiner
from refiner.refinement.steps.base import clip_ground, harms, window_figures
from refiner.refinement.steps.rigid_bones import RigidBonesStep, bone_bands, held_joints


def _stretched(clip, rng, metres=0.015):
    """``clip`` with every joint off by its own smooth noise (``metres`` std), as a generator that regresses joint
    positions one by one stretches bones."""
    knots = rng.normal(size=(len(clip) // 5 + 1, *clip.shape[1:])) * metres
    t = np.linspace(0, len(knots) - 1, len(clip))
    return clip + np.stack([np.interp(t, np.arange(len(knots)), k) for k in knots.reshape(len(knots), -1).T], -1).reshape(clip.shape)


@pytest.mark.real_data
def test_stretched_bones_come_back_rigid_with_the_feet_held(humanact12):
    clean = np.asarray([m for m in humanact12.split("test") if m.n_frames >= 60][3].joints[:60], np.float64)
    flawed = _stretched(clean, np.random.default_rng(0))
    given = flawed.copy()
    step = RigidBonesStep("humanact12")
    out, changes, prob = step.refine(flawed[None])
    np.testing.assert_array_equal(flawed, given)
    assert prob is None and changes[0] and all(e["step"] == "rigid_bones" and e["reason"] for e in changes[0])
    kept = np.zeros(60, bool)
    for e in changes[0]:
        kept[e["start"]:e["stop"]] |= e["kept"]
    assert kept.mean() > 0.5
    assert bone_length_variation(out[0][kept]) < 0.25 * bone_length_variation(flawed[kept])
    np.testing.assert_array_equal(out[0][~kept], flawed[~kept])
    feet = list(foot_joints("humanact12"))
    np.testing.assert_array_equal(out[0][:, feet], flawed[:, feet])  # each foot's lowest joint never moves
    err = lambda x: np.linalg.norm(x - clean, axis=-1).mean()
    assert err(out[0]) < 0.95 * err(flawed)  # the noise along the bones is gone


@pytest.mark.real_data
def test_real_clips_are_left_exactly_as_given(humanact12):
    clips = np.stack([m.joints[:40] for m in humanact12.split("test") if m.n_frames >= 40][:16]).astype(np.float64)
    out, changes, _ = RigidBonesStep("humanact12").refine(clips)
    np.testing.assert_array_equal(out, clips)
    assert not any(changes)


@pytest.mark.real_data
def test_bands_are_learnt_from_real_motion(humanact12):
    """SMPL-fitted HumanAct12 bones are rigid; CMU's processed hand and toe bones bend, its limbs do not."""
    from refiner.io.datasets import load_cmu_mocap

    bands = bone_bands([m.joints for m in humanact12.split("train")][:200], "humanact12", floor=0.002)
    np.testing.assert_array_equal(bands, 0.002)
    cmu = load_cmu_mocap(shared_data_dir() / "cmu_mocap" / "cmu_mocap_labeled_joints.npz").split("train")
    skel = get_skeleton("cmu_mocap")
    bands = dict(zip((skel.joint_names[c] for _, c in skel.bones), bone_bands([m.joints for m in cmu], skel)))
    assert bands["left_toe"] > 0.02 and bands["right_hand"] > 0.02
    assert bands["left_knee"] == bands["right_elbow"] == 0.002


def test_held_joints_are_the_feet_on_the_ground(tiny_clip):
    clip = tiny_clip.astype(np.float64)
    held = held_joints(clip, "humanact12", clip_ground(clip, "humanact12"))
    skel = get_skeleton("humanact12")
    assert held[:, list(foot_joints(skel))].all()
    assert not held[:, skel.index("head")].any() and not held[:, skel.index("left_wrist")].any()


def test_bands_of_the_wrong_length_and_unknown_presets_are_value_errors():
    with pytest.raises(ValueError, match="one value per bone"):
        RigidBonesStep("humanact12", bands=np.full(5, 0.01))
    with pytest.raises(ValueError, match="unknown preset 'studio'"):
        MotionRefiner.pretrained("humanact12", preset="studio")


@pytest.mark.real_data
def test_real_generator_output_gets_rigid_bones_and_no_worse_figure():
    """Action2Motion's xyz samples (real generator output): bones vary 4-5 %; refined with the generator preset,
    under 1 %, and no physical figure of any clip is worse."""
    from refiner.plugins.manager import convert

    raw = np.load(shared_dir() / "samples" / "action2motion" / "humanact12_xyz_vae_samples.npy")[:8]
    clips = np.stack([m.joints for m in convert("action2motion", raw, representation="xyz", recenter=True)])
    out, reports = MotionRefiner.pretrained("humanact12", preset="generator").refine(clips, return_report=True)
    mocap = MotionRefiner.pretrained("humanact12").refine(clips)  # the default preset leaves bones as given
    np.testing.assert_allclose(bone_length_variation(mocap), bone_length_variation(clips), atol=1e-6)
    assert bone_length_variation(clips).mean() > 0.03
    assert bone_length_variation(out).mean() < 0.01
    for given, new, r in zip(clips.astype(np.float64), out.astype(np.float64), reports):
        assert any(c["step"] == "rigid_bones" for c in r.changes)
        ground = clip_ground(given, "humanact12")
        assert not harms(window_figures(given, 0, len(given), "humanact12", ground),
                         window_figures(new, 0, len(new), "humanact12", ground), jerk_share=0.05, slack_m=0.0)
