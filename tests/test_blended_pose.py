"""A wrong pose blended into mocap is read from how it shortens and stretches the clip's exact bones and taken out."""
import numpy as np
import pytest

import refiner
import refiner.refinement.blended_pose as blended_pose
from refiner.core.signal import smoothstep
from refiner.core.skeletons import bone_lengths, convert, get_skeleton, joint_bone_lengths, with_bone_lengths
from refiner.refinement.blended_pose import blend_windows, exact_bones, fit_blend, one_chain, unblended_pose
from refiner.refinement.pipeline import Refiner


def _walk(humanact12):
    """A held-out walking clip (subject 11, 109 frames)."""
    i = int(np.flatnonzero((humanact12.subjects == 11) & (humanact12.actions == 1))[0])
    return humanact12[i]


def _with_pose(x, donor_frame, a, b, weight=0.8, joints=slice(1, None)):
    """``x`` with the pose of ``donor_frame`` (about the root) blended in over frames ``a..b`` (smoothstep tent)."""
    t = np.arange(len(x), dtype=float)
    u = np.clip(1 - np.abs(t - (a + b) / 2) / ((b - a) / 2), 0, 1)
    delta = np.zeros_like(x[0])
    mid = (a + b) // 2
    delta[joints] = (x[donor_frame, joints] - x[donor_frame, :1]) - (x[mid, joints] - x[mid, :1])
    return x + weight * smoothstep(u)[:, None, None] * delta


def test_windows_are_runs_off_the_core_inside_the_clip():
    off = np.zeros(40, bool)
    off[5:15] = True  # 10 frames
    off[16:19] = True  # a gap of one frame: the same window
    off[25:29] = True  # too few frames
    assert blend_windows(off) == [(4, 20)]
    off[:3] = True  # a run from the clip's first frame: drift, not a blend
    off[36:] = True
    assert blend_windows(off) == [(4, 20)]
    assert blend_windows(np.zeros(10, bool)) == []


def test_exact_bones_are_back_on_their_first_length_in_the_last_frame():
    off = np.zeros((40, 3), bool)
    off[1:39, 0] = True  # a blend's window: all but the first and last frames
    off[1:, 1] = True  # a bone that varies in every frame (CMU's hands and toes)
    off[30:, 2] = True  # drifting to the clip's end
    assert exact_bones(off).tolist() == [True, False, False]
    assert exact_bones(np.stack([off, np.zeros_like(off)])).tolist() == [[True, False, False], [True] * 3]


@pytest.mark.real_data
def test_a_clip_with_too_few_exact_bones_is_left_and_a_chance_bone_is_left_out(humanact12):
    x = _walk(humanact12).joints.astype(np.float64)
    bad = _with_pose(x, 80, 20, 50)
    err = lambda y: float(np.linalg.norm(y - x, axis=-1).mean())  # noqa: E731
    report = lambda: type("Report", (), {"changes": []})()  # noqa: E731
    model = type("Model", (), {"skeleton": "humanact12"})()
    reports = [report()]
    given = bad[None].copy()
    out = blended_pose.unblended_poses(model, given, reports, "full")
    np.testing.assert_array_equal(given, bad[None])  # the input is not modified
    assert err(out[0]) < 0.02 * err(bad) and len(reports[0].changes) == 1
    skel = get_skeleton("humanact12")
    wobble = 1 + 0.01 * np.sin(np.arange(len(x)) * 2.1)
    wobble[-1] = 1.0  # varies in every frame but the last, back on its first length by chance
    tips = [skel.index(n) for n in ("left_hand", "right_hand", "left_foot", "right_foot", "head")]
    lengths = joint_bone_lengths(bad, "humanact12").copy()
    lengths[:, tips] *= wobble[:, None]
    varying = with_bone_lengths(bad, lengths, "humanact12")
    reports = [report()]
    out = blended_pose.unblended_poses(model, varying[None], reports, "full")
    assert len(reports[0].changes) == 1 and err(out[0]) < 0.2 * err(bad)  # read again without the chance bones
    lengths = joint_bone_lengths(bad, "humanact12").copy()
    lengths[:, 5:] *= wobble[:, None]  # too few bones stay steady
    few = with_bone_lengths(bad, lengths, "humanact12")
    out = blended_pose.unblended_poses(model, few[None], [report()], "full")
    assert np.array_equal(out[0], few)


def test_one_limb_is_one_chain_and_two_are_not():
    skel = get_skeleton("humanact12")
    child = {int(c): k for k, (_, c) in enumerate(skel.bones)}
    bones = lambda *names: np.isin(np.arange(len(skel.bones)), [child[skel.index(n)] for n in names])  # noqa: E731
    assert one_chain(skel, bones("right_elbow", "right_wrist", "right_hand"))
    assert one_chain(skel, bones("right_collar", "right_shoulder", "right_elbow", "right_wrist", "right_hand"))
    assert not one_chain(skel, bones("right_elbow", "right_wrist", "left_elbow"))  # two limbs
    assert not one_chain(skel, bones("spine3", "left_collar", "right_collar"))  # a branch
    assert one_chain(skel, bones())


def test_the_fit_finds_a_blend_of_known_bones():
    rng = np.random.default_rng(0)
    n, n_bones = 30, 6
    direction = rng.normal(size=(n, n_bones, 3))
    lengths = rng.uniform(0.1, 0.4, n_bones)
    true = direction / np.linalg.norm(direction, axis=-1, keepdims=True) * lengths[:, None]
    w = np.sin(np.linspace(0, np.pi, n)) ** 2
    delta = rng.normal(scale=0.1, size=(n_bones, 3))
    fitted_w, fitted_delta, rms = fit_blend(true + w[:, None, None] * delta, lengths)
    assert rms < 1e-8
    np.testing.assert_allclose(fitted_w[:, None, None] * fitted_delta, w[:, None, None] * delta, atol=1e-6)


@pytest.mark.real_data
def test_a_blended_pose_is_taken_out_and_nothing_else_is_touched(humanact12):
    x = _walk(humanact12).joints.astype(np.float64)
    err = lambda y: float(np.linalg.norm(y - x, axis=-1).mean())  # noqa: E731
    for joints in (slice(1, None), [4, 5, 7, 8, 10, 11]):  # the whole pose, both legs
        bad = _with_pose(x, 80, 20, 50, joints=joints).astype(np.float32)
        given = bad.copy()
        out, blends = unblended_pose(bad, "humanact12")
        np.testing.assert_array_equal(bad, given)  # the input is not modified
        assert len(blends) == 1 and 19 <= blends[0]["start"] and blends[0]["stop"] <= 52, blends
        assert out.dtype == np.float32 and err(out) < 0.02 * err(bad), (err(out), err(bad))
    assert unblended_pose(_with_pose(x, 80, 20, 50, joints=[18, 20, 22]), "humanact12")[1] == []  # one arm: one chain
    clean = humanact12[0].joints
    assert unblended_pose(clean, "humanact12") == (clean, [])
    noisy = x + np.where((np.arange(len(x)) >= 20) & (np.arange(len(x)) < 50), 1.0, 0.0)[:, None, None] * \
        np.random.default_rng(0).normal(scale=0.01, size=x.shape)
    assert unblended_pose(noisy, "humanact12")[1] == []  # noise is no blend
    stretched = _with_pose(x, 80, 20, 50) * (1 + 0.02 * np.sin(np.arange(len(x))))[:, None, None]
    assert unblended_pose(stretched, "humanact12")[1] == []  # no exact core (a generator's bones)
    drifting = _with_pose(x, 80, 60, len(x) + 40)  # the weight still rising at the clip's end
    assert unblended_pose(drifting, "humanact12")[1] == []
    scale = np.ones(x.shape[:2])
    scale[20:50, [18, 20, 22]] = 1.1  # one arm stretched: the rigid step's, though a blend of the arm meets it too
    stretched = with_bone_lengths(x, joint_bone_lengths(x, "humanact12") * scale, "humanact12")
    assert unblended_pose(stretched, "humanact12")[1] == []


@pytest.mark.real_data
def test_refine_takes_a_wrong_pose_out_and_reports_it(humanact12, monkeypatch):
    clip = _walk(humanact12)
    x = clip.joints.astype(np.float64)
    bad = _with_pose(x, 80, 20, 50).astype(np.float32)
    err = lambda y: float(np.linalg.norm(y - x, axis=-1).mean())  # noqa: E731
    model = Refiner.pretrained("humanact12", split="train")
    out, report = model.refine(bad, action=clip.action, return_report=True)
    assert err(out) < 0.1 * err(bad), (err(out), err(bad))
    change = next(c for c in report.changes if c.get("repair") == "unblended_pose")
    assert change["step"] == "anchor" and "blended in" in change["reason"]
    assert not any(c.get("repair") == "unblended_pose" for c in model.refine(bad, mode="transition", return_report=True)[1].changes)
    monkeypatch.setattr(blended_pose, "UNBLEND", False)
    assert err(model.refine(bad, action=clip.action)) > 0.5 * err(bad)  # off: the rigid step alone cannot


@pytest.mark.real_data
def test_a_converted_layout_is_unblended_in_its_own_bones(humanact12):
    x = _walk(humanact12).joints.astype(np.float64)
    bad = _with_pose(x, 80, 20, 50)
    for skeleton, share in (("humanml3d", 0.05), ("uestc", 0.7)):  # UESTC's upper body hangs on bending chains
        truth, given = convert(x, "humanact12", skeleton), convert(bad, "humanact12", skeleton).astype(np.float32)
        out, report = refiner.refine(given, skeleton=skeleton, return_report=True)
        err = lambda y: float(np.linalg.norm(y - truth, axis=-1).mean())  # noqa: E731
        assert err(out) < share * err(given), (skeleton, err(out), err(given))
        assert report.changes[0]["repair"] == "unblended_pose"
    transition_only = Refiner.pretrained("uestc", split="train", mode="transition")  # an anchor step: not there
    _, report = transition_only.refine(given, return_report=True)
    assert not any(c.get("repair") == "unblended_pose" for c in report.changes)



@pytest.mark.real_data
def test_cmu_clips_are_unblended_in_the_bones_they_hold_exact():
    from conftest import shared_data_dir

    from refiner.io.datasets import load_cmu_mocap

    cmu = load_cmu_mocap(shared_data_dir() / "cmu_mocap" / "cmu_mocap_labeled_joints.npz").split("test")
    x = next(m for m in cmu.motions if len(m.joints) >= 100).joints[:100].astype(np.float64)
    bad = _with_pose(x, 85, 30, 60).astype(np.float32)
    err = lambda y: float(np.linalg.norm(y - x, axis=-1).mean())  # noqa: E731
    out, report = refiner.refine(bad, skeleton="cmu_mocap", return_report=True)
    assert err(out) < 0.2 * err(bad), (err(out), err(bad))
    assert any(c.get("repair") == "unblended_pose" for c in report.changes)
    lengths = bone_lengths(x, "cmu_mocap")
    assert (lengths.std(0) / lengths.mean(0)).max() > 1e-3  # CMU's hands and toes vary: no clip-wide exact core
