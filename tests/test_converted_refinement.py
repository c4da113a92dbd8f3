"""Skeletons without weights of their own are refined through the HumanAct12 weights (refiner.refinement.converted_refinement)."""
import numpy as np
import pytest
import torch

import refiner
from refiner import Motion
from refiner.core.skeletons import Skeleton, bone_lengths, convert, get_skeleton, joint_bone_lengths, with_bone_lengths
from refiner.evaluation.flaws import frozen_transition
from refiner.refinement.converted_refinement import FLEXIBLE_BONES, ConvertedRefiner
from refiner.refinement.pipeline import Refiner


@pytest.fixture(scope="module")
def held_out(humanact12):
    return [m for m in humanact12.split("test").motions if m.n_frames >= 40][:40:5]  # 8 clips of subjects 11-12


@pytest.mark.real_data
@pytest.mark.parametrize("skeleton", ["uestc", "cmu_mocap", "humanml3d"])
def test_clean_clips_come_back_exactly_and_say_how(held_out, skeleton):
    # the noise filter's last step is calibrated to touch 3 % of clean clips (one of these 8 is among them,
    # natively too): off here, where the conversion path itself must return every frame exactly
    if skeleton in {w["skeleton"] for w in Refiner.shipped()}:  # weights of its own (CMU): the conversion path explicitly
        model = ConvertedRefiner(Refiner.pretrained("humanact12", split="train", rigid_tolerance=float("inf"),
                                                    denoising="flagged"), skeleton)
    else:
        model = Refiner.pretrained(skeleton, split="train", denoising="flagged")
    assert isinstance(model, ConvertedRefiner) and model.skeleton == skeleton
    default = None if skeleton == "cmu_mocap" else Refiner.pretrained(skeleton, split="train")  # noise step on
    touched = 0
    for m in held_out:
        x = convert(m.joints, "humanact12", skeleton).astype(np.float32)
        before = x.copy()
        out, report = model.refine(x, return_report=True)
        np.testing.assert_array_equal(x, before)  # input untouched
        np.testing.assert_array_equal(out, x)
        assert report.changes == [] and "through refiner.core.skeletons.convert" in report.notes[-1]
        if default is not None:
            out = default.refine(x)
            touched += not np.array_equal(out, x)
            assert np.linalg.norm(out - x, axis=-1).mean() < 0.003  # metres
    assert touched <= 1


@pytest.mark.real_data
def test_a_stalled_uestc_clip_is_repaired_and_kinds_are_kept(held_out):
    fixed, flawed_err, clips = [], [], []
    for i, m in enumerate(held_out):
        c = frozen_transition(m, 2, random_state=i)
        clean = convert(m.joints, "humanact12", "uestc")
        x = convert(c.motion.joints, "humanact12", "uestc").astype(np.float32)
        out, report = refiner.refine(x, skeleton="uestc", return_report=True)
        reported = np.zeros(len(x), bool)
        for change in report.changes:
            reported[change["start"] : change["stop"]] = True
        assert (out == x).all((-1, -2))[~reported].all()  # frames outside the reported changes exactly as given
        flawed_err.append(np.linalg.norm(x - clean, axis=-1).mean())
        fixed.append(np.linalg.norm(out - clean, axis=-1).mean())
        clips.append(x[:40])
    assert np.mean(fixed) < 0.9 * np.mean(flawed_err)
    batch = np.stack(clips)
    out_batch = refiner.refine(batch, skeleton="uestc")
    for b, clip in enumerate(clips):
        np.testing.assert_array_equal(out_batch[b], refiner.refine(clip, skeleton="uestc"))
    t = refiner.refine(torch.from_numpy(batch), skeleton="uestc")
    assert isinstance(t, torch.Tensor) and t.shape == batch.shape
    motion = Motion(clips[0], skeleton="uestc")
    back = refiner.refine(motion, skeleton="uestc")
    assert isinstance(back, Motion) and back.skeleton == "uestc"


@pytest.mark.real_data
def test_stretching_uestc_bones_come_back_rigid_but_bending_chains_stay_free(held_out):
    m = held_out[0]
    x = convert(m.joints, "humanact12", "uestc")
    skel = get_skeleton("uestc")
    lengths = joint_bone_lengths(x, skel)
    wave = 1 + 0.08 * np.sin(np.linspace(0, 6, len(x)))[:, None]
    elbow = skel.joint_names.index("left_wrist")
    lengths[:, elbow] *= wave[:, 0]  # the left forearm stretches by up to 8 %
    stretched = with_bone_lengths(x, lengths, skel).astype(np.float32)
    out, report = refiner.refine(stretched, skeleton="uestc", return_report=True)
    assert report.changes[0]["step"] == "skeleton"
    model = Refiner.pretrained("uestc")
    got = bone_lengths(out, skel)
    cv = got.std(0) / got.mean(0)
    assert cv[model.rigid_bones].max() < 0.005
    names = [frozenset((skel.joint_names[a], skel.joint_names[b])) for a, b in skel.bones]
    flexible = [names.index(frozenset(p)) for p in FLEXIBLE_BONES["uestc"]]
    assert not model.rigid_bones[flexible].any() and model.rigid_bones.sum() == len(names) - len(flexible)


def test_skeletons_the_conversion_cannot_reach_still_have_no_weights():
    from refiner.core.skeletons import register_skeleton

    register_skeleton(Skeleton("toy_unconvertible", ("root", "a", "b"), (-1, 0, 1), up="-y", forward="-z"),
                      overwrite=True)
    with pytest.raises(ValueError, match="no shipped weights"):
        Refiner.pretrained("toy_unconvertible")


@pytest.mark.real_data
def test_refined_generator_on_uestc_with_real_ntu13_samples():
    from conftest import shared_data_dir

    samples = np.load(shared_data_dir().parent / "samples" / "action2motion" / "ntu13_xyz_vae_samples.npy")

    class Ntu13Samples:
        def sample(self, action, n=1, random_state=None):
            return samples[:n].copy()

    gen = refiner.RefinedGenerator(Ntu13Samples(), adapter="action2motion", skeleton="uestc",
                                   adapter_options={"representation": "xyz", "skeleton": "uestc"})
    motions = gen.sample(None, n=3)
    assert [m.skeleton for m in motions] == ["uestc"] * 3 and motions[0].joints.shape == (60, 18, 3)
    from refiner.evaluation.physics import bone_length_variation
    from refiner.plugins.manager import convert as adapter_convert

    raw = adapter_convert("action2motion", samples[:3], representation="xyz", skeleton="uestc")
    assert np.mean([bone_length_variation(m) for m in motions]) < 0.5 * np.mean([bone_length_variation(m) for m in raw])


@pytest.mark.real_data
def test_own_labels_refine_action_agnostic_short_clips_stay_and_errors_name_the_clip(held_out):
    model = Refiner.pretrained("uestc")
    u = convert(held_out[0].joints, "humanact12", "uestc").astype(np.float32)
    _, report = model.refine(Motion(u, skeleton="uestc", action=35), return_report=True)  # a UESTC label
    assert "refined action-agnostic" in report.notes[-1]
    _, report = model.refine(u, action="walk", return_report=True)  # a HumanAct12 name is used
    assert report.action == list(model.action_names).index("walk") and not any("agnostic" in n for n in report.notes)
    short = u[:5] + np.random.default_rng(0).normal(0, 0.01, u[:5].shape).astype(np.float32)  # stretching bones
    out, report = model.refine(short, return_report=True)
    np.testing.assert_array_equal(out, short)
    assert report.changes == [] and "returned unchanged" in report.note
    with pytest.raises(ValueError, match=r"^`seq` has bones .* metres"):
        model.refine(u * 100)
    with pytest.raises(ValueError, match=r"^clip 1 of 2: `seq` has bones"):
        model.refine(np.stack([u, u * 100]))
    with pytest.raises(ValueError, match="rigid_tolerance"):
        Refiner.pretrained("uestc", rigid_tolerance=None)
    assert model.threads_for(u) == 1 and model.threads == "auto"


@pytest.mark.real_data
def test_converted_layouts_rebuild_a_stretched_limb(held_out):
    """A uestc clip whose right arm stretches 10 % for 20 frames gets the arm's own lengths back, parents in place."""
    x = convert(held_out[0].joints, "humanact12", "uestc").astype(np.float64)
    skel = get_skeleton("uestc")
    arm = [skel.joint_names.index(n) for n in ("right_elbow", "right_wrist")]
    bump = np.zeros(len(x))
    bump[5:25] = np.sin(np.linspace(0, np.pi, 20)) ** 2
    scale = np.ones((len(x), len(skel.joint_names)))
    scale[:, arm] = 1 + 0.1 * bump[:, None]
    stretched = with_bone_lengths(x, joint_bone_lengths(x, "uestc") * scale, "uestc").astype(np.float32)
    err = lambda m: np.linalg.norm(Refiner.pretrained("uestc", split="train", **m).refine(stretched) - x, axis=-1).mean()  # noqa: E731
    flawed = np.linalg.norm(stretched - x, axis=-1).mean()
    assert err({}) < 0.1 * flawed < 0.1 * err({"rigid_core": False}), (err({}), flawed)


@pytest.mark.real_data
def test_converted_layouts_draw_drifting_bones_toward_their_own_proportions(held_out):
    """The HumanAct12 weights carry proportions of the layouts they serve; a drifting uestc bone is drawn back."""
    from refiner.core.skeletons import BoneProportions

    core = Refiner.pretrained("uestc", split="train")
    model = Refiner.pretrained("uestc", split="train", rigid_core=False)  # a clip with no rigid core
    assert model.proportions.mean.shape == (17,) and model.base.rigid_lengths == "proportions"
    assert Refiner.pretrained("humanml3d", split="train").proportions.mean.shape == (21,)
    median = Refiner.pretrained("uestc", split="train", rigid_lengths="median", rigid_core=False)
    assert median.proportions is None and median.base.rigid_lengths == "median"
    x = convert(held_out[0].joints, "humanact12", "uestc").astype(np.float64)
    wrist = get_skeleton("uestc").joint_names.index("right_wrist")
    drift = x.copy()
    drift[:, wrist] += np.linspace(0, 1, len(x))[:, None] * np.array([0.0, 0.06, 0.0])  # the forearm stretches by up to 6 cm
    err = {name: np.linalg.norm(m.refine(drift.astype(np.float32)) - x, axis=-1).mean() for name, m in
           (("proportions", model), ("median", median), ("core", core))}
    assert err["proportions"] < err["median"], err
    assert err["core"] < err["proportions"], err  # the drift starts late enough: its first frames hold the true lengths
    with pytest.raises(ValueError, match="one share per uestc bone"):
        ConvertedRefiner(model.base, "uestc", proportions=BoneProportions(np.ones(5) / 5, np.zeros(5)))


@pytest.mark.real_data
@pytest.mark.parametrize("skeleton", ["uestc", "humanml3d"])
def test_bones_that_jitter_in_the_clips_own_layout_are_denoised(held_out, skeleton, monkeypatch):
    """Converted to the 24 joints a clip is put on rigid bones, so the base never sees its noisy bones: the frames
    whose own-layout bones leave its rigid core roughly are denoised here, as the base's noise runs are."""
    from refiner.evaluation.flaws import transition_jitter
    from refiner.refinement import rigid_step

    model = Refiner.pretrained(skeleton, split="train")
    gained = []
    for i, m in enumerate(held_out):
        flaw = transition_jitter(m, 2, random_state=i)
        clean = convert(m.joints, "humanact12", skeleton)
        x = convert(flaw.motion.joints, "humanact12", skeleton).astype(np.float32)
        out, report = model.refine(x, return_report=True)
        monkeypatch.setattr(rigid_step, "NOISY_BONES", None)  # the classifier's noise runs alone (the release before)
        before = model.refine(x)
        monkeypatch.undo()
        runs = [c for c in report.changes if c["step"] == "noise" and "bones changed length roughly" in c["reason"]]
        changed = (out != before).any((1, 2))
        assert not (changed & ~flaw.mask).any() or runs  # only where the flaw is, or in a run it reports
        err = lambda y: float(np.linalg.norm(y - clean, axis=-1).mean())
        gained.append((err(before), err(out)))
    before, after = np.array(gained).T
    assert after.mean() < 0.95 * before.mean() and (after < before + 0.0005).all(), gained  # metres
