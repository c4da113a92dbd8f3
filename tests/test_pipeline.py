"""refine() and the concepts method's Refiner: a tiny pipeline trained on real clips, splicing, do-no-harm, input kinds,
errors; the default method (the motion model) through refine()."""
import json
import os
import numpy as np
import pytest
import torch

from refiner import Motion
from refiner.core.skeletons import bone_lengths, get_skeleton
from refiner.refinement.motion_refiner import MotionRefiner
from refiner.refinement.pipeline import Refiner, project_bone_lengths, refine, splice

pytestmark = pytest.mark.real_data


@pytest.fixture(scope="session")
def tiny_refiner(humanact12, tmp_path_factory):
    """The whole pipeline trained with the tiny configuration on 36 real clips (3 per action)."""
    from refiner.refinement.train_refiner import train_refiner

    pick = [i for a in range(12) for i in np.flatnonzero(humanact12.actions == a)[:3]]
    out = tmp_path_factory.mktemp("tiny_refiner")
    refiner = train_refiner(humanact12.subset(pick), out, config="tiny", device="cpu", half=False)
    return refiner, out


def test_tiny_pipeline_trains_and_refines(tiny_refiner, humanact12):
    refiner, out = tiny_refiner
    clip = humanact12[500]
    before = clip.numpy()
    result, report = refiner.refine(clip, return_report=True)
    assert isinstance(result, Motion) and result.joints.shape == clip.joints.shape
    np.testing.assert_array_equal(clip.joints, before)
    assert report.anchors[0] == 0 and report.anchors[-1] == clip.n_frames - 1
    assert len(report.anchor_scores) == len(report.anchors)
    changed = report.changed_frames
    np.testing.assert_array_equal(result.joints[~changed], clip.joints[~changed])  # do no harm
    # reloading the saved refiner gives the same refinement
    again = Refiner.load(out).refine(clip)
    np.testing.assert_allclose(again.joints, result.joints, atol=1e-5)
    counts = refiner.n_parameters()
    assert counts["total"] == sum(v for k, v in counts.items() if k != "total") > 0


@pytest.mark.parametrize("variant", [
    {},  # the measured defaults: pose quality, posterior anchors, concept re-timing
    {"quality": "encoder", "anchor_method": "concept", "transition_method": "network"},  # the paper's
])
def test_forced_refinement_is_continuous_and_keeps_bones(tiny_refiner, humanact12, variant):
    """Flag everything: changed windows meet kept frames without position or velocity jumps."""
    base, _ = tiny_refiner
    parts = {k: getattr(base, k) for k in ("recognizer", "anchor_refiner", "transition_generator",
                                           "transition_refiner", "anchor_concepts", "anchor_quality")}
    manifest = {**base.manifest, "calibration": {"anchor_threshold": np.inf, "transition_threshold": -1.0}}
    refiner = Refiner(**parts, action_names=base.action_names, manifest=manifest, **variant)
    clip = humanact12[700]
    saved = base.recognizer.threshold_, base.transition_refiner.threshold_
    try:
        base.recognizer.threshold_, base.transition_refiner.threshold_ = np.inf, -1.0
        out, report = refiner.refine(clip, return_report=True)
    finally:
        base.recognizer.threshold_, base.transition_refiner.threshold_ = saved
    assert report.refined_anchors and report.flagged_transitions
    assert len(report.flagged_anchors) == len(report.anchors)
    np.testing.assert_allclose(bone_lengths(out.joints, "humanact12"), bone_lengths(clip.joints, "humanact12"), atol=1e-5)
    changed = report.changed_frames
    assert np.abs(out.joints - clip.joints).max() > 1e-3
    if changed.all():
        return
    vel = np.diff(out.joints, axis=0)
    acc = np.linalg.norm(np.diff(vel, axis=0), axis=-1).max(-1)
    real = np.linalg.norm(np.diff(np.diff(np.concatenate([m.joints for m in humanact12.motions[::10]]), axis=0), axis=0), axis=-1)
    edges = np.flatnonzero(np.diff(changed.astype(int)))
    assert len(edges)
    for e in edges:
        assert acc[max(e - 1, 0) : e + 2].max() < np.percentile(real.max(-1), 99.9)


def test_input_kinds_and_no_mutation(tiny_refiner, humanact12):
    refiner, _ = tiny_refiner
    x = humanact12[10].numpy()
    before = x.copy()
    out = refiner.refine(x, action="warm_up")
    assert isinstance(out, np.ndarray) and out.shape == x.shape and out.dtype == np.float32
    np.testing.assert_array_equal(x, before)
    batch = np.stack([humanact12[i].joints[:40] for i in (1, 2, 3)])
    outs, reports = refiner.refine(batch, action=[0, 1, 2], return_report=True)
    assert outs.shape == batch.shape and len(reports) == 3 and [r.action for r in reports] == [0, 1, 2]
    t = torch.tensor(x)
    out_t = refiner.refine(t)
    assert isinstance(out_t, torch.Tensor) and out_t.dtype == torch.float32
    np.testing.assert_allclose(out_t.numpy(), refiner.refine(x), atol=1e-6)
    short = refiner.refine(x[:5], return_report=True)
    np.testing.assert_array_equal(short[0], x[:5])
    assert "unchanged" in short[1].note
    for mode in ("anchor", "transition"):
        assert refiner.refine(x, mode=mode).shape == x.shape


@pytest.mark.parametrize("bad, kwargs, match", [
    (np.full((30, 24, 3), np.nan), {}, "NaN"),
    (np.zeros((30, 22, 3)), {}, "J=24"),
    (np.zeros((1, 24, 3)), {}, "at least 2 frames"),
    (np.zeros((30, 24, 3)), {"action": "dance"}, "unknown action"),
    (np.zeros((30, 24, 3)), {"action": 12}, "0..11"),
    (np.zeros((30, 24, 3)), {"mode": "magic"}, "unknown mode"),
])
def test_bad_input(tiny_refiner, bad, kwargs, match):
    refiner, _ = tiny_refiner
    with pytest.raises(ValueError, match=match):
        refine(bad, refiner=refiner, **kwargs)


def test_unknown_skeleton_and_corrupt_weights(tiny_refiner, tmp_path):
    with pytest.raises(ValueError, match="unknown skeleton"):
        refine(np.zeros((30, 24, 3)), skeleton="smpl99")
    refiner, out = tiny_refiner
    copy = tmp_path / "copy"
    refiner.save(copy)
    data = bytearray((copy / "recognizer.safetensors").read_bytes())
    data[-100] ^= 0xFF  # flip one weight byte
    (copy / "recognizer.safetensors").write_bytes(bytes(data))
    with pytest.raises(ValueError, match="sha256"):
        Refiner.load(copy)


def test_splice_is_c1_continuous(rng):
    t = np.linspace(0, 2 * np.pi, 60)
    original = np.stack([np.sin(t), np.cos(t), t / 10], -1)[:, None, :].repeat(3, 1).astype(np.float32)
    # a smooth proposal that starts 0.3 m away: pasting it in directly would jump by 0.3 m
    proposal = original + 0.3 + 0.1 * np.sin(3 * t)[:, None, None].astype(np.float32)
    out = splice(original, proposal, 20, 40, blend=4)
    np.testing.assert_array_equal(out[:20], original[:20])
    np.testing.assert_array_equal(out[40:], original[40:])
    assert np.abs(out[20:40] - original[20:40]).max() > 0.05  # it did change something
    # velocity just inside each kept edge matches the original's (zero-slope taper)
    for edge in (19, 39):
        dv = np.abs((out[edge + 1] - out[edge]) - (original[edge + 1] - original[edge])).max()
        assert dv < 0.05, dv


def test_project_bone_lengths(rng):
    skel = get_skeleton("humanact12")
    reference = np.cumsum(rng.normal(size=(5, 24, 3)), axis=1).astype(np.float32)
    moved = reference + rng.normal(scale=0.05, size=reference.shape).astype(np.float32)
    frames = np.array([False, True, True, False, True])
    lengths = np.zeros((5, 24))
    lengths[:, skel.bones[:, 1]] = bone_lengths(reference, skel)
    out = project_bone_lengths(moved, lengths, frames, skel)
    np.testing.assert_allclose(bone_lengths(out[frames], skel), bone_lengths(reference[frames], skel), rtol=1e-5)
    np.testing.assert_array_equal(out[~frames], moved[~frames])
    np.testing.assert_array_equal(out[frames][:, 0], moved[frames][:, 0])  # root kept


def test_shipped_weights_refine_a_60_frame_clip(humanact12):
    """The default refine() on a fresh install: shipped weights, CPU, one call, a real clip barely moves; the default
    is the motion model, the concepts method is one argument away."""
    import refiner

    clip = humanact12[100].crop(0, 60)
    out, report = refiner.refine(clip, return_report=True)
    assert out.joints.shape == (60, 24, 3) and report.action == clip.action
    assert 100 * np.linalg.norm(out.joints - clip.joints, axis=-1).mean() < 1.0
    assert report.threshold_quantity == "flaw_probability" and len(report.flaw_probability) == 60
    np.testing.assert_array_equal(out.joints, MotionRefiner.pretrained("humanact12").refine(clip).joints)
    concepts, creport = refiner.refine(clip, method="concepts", return_report=True)
    assert creport.threshold_quantity == "anchor_scores" and creport.anchors
    np.testing.assert_array_equal(concepts.joints, Refiner.pretrained("humanact12").refine(clip).joints)
    assert 100 * np.linalg.norm(concepts.joints - clip.joints, axis=-1).mean() < 1.0
    model = Refiner.pretrained("humanact12")
    assert model.manifest["split"] == "all" and "non-commercial" in model.manifest["licence"] and model.method == "concepts"
    bench = Refiner.pretrained("humanact12", split="train")
    assert bench.manifest["subjects"] == list(range(1, 11))
    assert set(bench.manifest["calibration"]) >= {"anchor_threshold", "transition_thresholds"}
    with pytest.raises(ValueError, match="no concepts weights"):
        Refiner.pretrained("humanact12", split="test")
    for skeleton in ("uestc", "humanml3d"):  # the default method converts them; the concepts method has no weights
        with pytest.raises(ValueError, match=r"supports humanact12 and cmu_mocap only.*method='motion'"):
            Refiner.pretrained(skeleton)


def test_refine_methods_and_modes_are_checked(humanact12):
    clip = humanact12[100].joints[:40]
    with pytest.raises(ValueError, match="unknown method 'learned'; known: motion, concepts"):
        refine(clip, method="learned")
    for mode in ("anchor", "transition"):  # the concepts method's modes
        with pytest.raises(ValueError, match=f"mode='{mode}' belongs to method='concepts'"):
            refine(clip, mode=mode)
        with pytest.raises(ValueError, match="belongs to method='concepts'"):
            refine(clip, mode=mode, refiner=MotionRefiner.pretrained("humanact12"))
        assert refine(clip, mode=mode, method="concepts").shape == clip.shape
    concepts = Refiner.pretrained("humanact12")  # a given refiner brings its own method
    np.testing.assert_array_equal(refine(clip, mode="anchor", refiner=concepts), concepts.refine(clip, mode="anchor"))
    with pytest.raises(ValueError, match="method='concepts' only"):
        Refiner.pretrained("humanact12", method="motion")
    from refiner.core.skeletons import Skeleton, register_skeleton

    register_skeleton(Skeleton("toy_unknown_layout", ("root", "a", "b"), (-1, 0, 1), up="-y", forward="-z"),
                      overwrite=True)
    with pytest.raises(ValueError, match="no motion model for skeleton 'toy_unknown_layout'"):
        refine(np.zeros((30, 3, 3)), skeleton="toy_unknown_layout")


@pytest.mark.parametrize("skeleton", ["humanact12", "uestc", "humanml3d"])
def test_default_refiner_keeps_unflagged_frames_and_reports_each_change(humanact12, skeleton):
    """Held-out clips in each layout the default serves: the input is never modified, frames outside the reported
    changes come back bit-identical; forced to flag and keep everything but the first and last frames (every gate
    off), the changes are reported, the kept frames are exact and HumanAct12's changed frames keep their bones."""
    from refiner.core.skeletons import convert

    clips = [m for m in humanact12.split("test").motions if m.n_frames >= 40][:40:5]
    forced = MotionRefiner.pretrained(skeleton, threshold=0.0, still_m=0.0, min_gain=-1.0, jerk_share=1e9,
                                      ground_tolerance_m=1e9, slide_pairs=1e9)
    assert forced.skeleton == skeleton and forced.method == "motion" and forced.action_names
    for m in clips:
        x = (m.joints if skeleton == "humanact12" else convert(m.joints, "humanact12", skeleton)).astype(np.float32)
        before = x.copy()
        out, report = refine(x, skeleton=skeleton, action=m.action, return_report=True)
        np.testing.assert_array_equal(x, before)
        assert (out == x).all((-1, -2))[~report.changed_frames].all()
        assert 100 * np.linalg.norm(out - x, axis=-1).mean() < 1.0
        out, report = forced.refine(x, action=m.action, return_report=True)
        np.testing.assert_array_equal(x, before)
        assert report.changes and all(set(c) == {"step", "start", "stop", "parts", "kept", "reason"} and c["kept"] for c in report.changes)
        changed = report.changed_frames
        assert not changed[0] and not changed[-1] and changed.sum() > len(x) // 2
        np.testing.assert_array_equal(out[~changed], x[~changed])
        assert np.abs(out[changed] - x[changed]).max() > 1e-4
        if skeleton == "humanact12":  # changed frames stay on the clip's own bones
            np.testing.assert_allclose(bone_lengths(out[changed], skeleton), bone_lengths(x[changed], skeleton), atol=1e-4)


@pytest.mark.real_data
@pytest.mark.parametrize("change, match", [
    (lambda x: x * 100.0, "metres"),                         # centimetres
    (lambda x: x + 1e20, "coordinates up to"),               # finite but absurd
    (lambda x: x.astype(np.complex64) + 1j, "real numbers"),  # an imaginary part would be dropped
])
def test_inputs_that_cannot_be_metres_are_refused(humanact12, change, match):
    clip = humanact12[100].joints[:40]
    with pytest.raises(ValueError, match=match):
        refine(change(clip))
    with pytest.raises(ValueError, match="unknown mode ''"):
        refine(clip, mode="", method="concepts")  # an empty mode is a mistake, not "full"
    with pytest.raises(ValueError, match="mode='' belongs to method='concepts'"):
        refine(clip, mode="")


def test_threads_auto_one_for_small_batches_more_for_large_and_restored():
    import torch

    from refiner.refinement.inputs import AUTO_THREADS_BATCH, auto_threads
    from refiner.refinement.pipeline import Refiner

    assert auto_threads(np.zeros((60, 24, 3))) == 1
    assert auto_threads(np.zeros((AUTO_THREADS_BATCH - 1, 60, 24, 3))) == 1
    big = auto_threads(np.zeros((AUTO_THREADS_BATCH, 60, 24, 3)))
    assert 1 <= big <= 4 and (big > 1 or len(os.sched_getaffinity(0)) == 1)
    for bad in (0, -1, 1.5, True, "all"):
        with pytest.raises(ValueError, match="threads"):
            Refiner.pretrained("humanact12", split="train", threads=bad)
    model = Refiner.pretrained("humanact12", split="train")
    assert model.threads_for(np.zeros((60, 24, 3))) == 1 and model.threads_for(np.zeros((64, 60, 24, 3))) == big
    assert Refiner.pretrained("humanact12", split="train", threads=3).threads_for(np.zeros((60, 24, 3))) == 3
    before = torch.get_num_threads()
    Refiner.pretrained("humanact12", split="train").refine(np.zeros((40, 30, 24, 3), np.float32) + 0.1 * np.arange(24)[:, None])
    assert torch.get_num_threads() == before


def test_pretrained_gives_independent_copies(humanact12):
    """Calibrating or editing one pretrained refiner changes no other, nor what refine() uses."""
    import refiner

    a, b = Refiner.pretrained("humanact12", split="train"), Refiner.pretrained("humanact12", split="train")
    assert a is not b and a.anchor_quality is not b.anchor_quality and a.manifest is not b.manifest
    before = b.anchor_quality.threshold_, [list(t) for t in b.transition_retimer.thresholds_]
    clips = [humanact12[i].joints for i in range(0, 120, 6)]
    a.calibrate(clips, [humanact12[i].action for i in range(0, 120, 6)])
    a.recognizer.threshold_ = 1e-6
    assert a.anchor_quality.threshold_ != before[0]
    assert (b.anchor_quality.threshold_, b.transition_retimer.thresholds_) == before
    again = Refiner.pretrained("humanact12", split="train")
    assert again.anchor_quality.threshold_ == before[0] and again.recognizer.threshold_ == b.recognizer.threshold_
    clip = humanact12[100].crop(0, 60)
    np.testing.assert_array_equal(refiner.refine(clip, method="concepts").joints,
                                  Refiner.pretrained("humanact12").refine(clip).joints)


def test_thresholds_live_in_the_steps_and_travel_with_them(tiny_refiner, humanact12, tmp_path):
    """A manifest's calibrated thresholds go to the steps (the given parts stay as they are); saving writes
    each step's threshold once, and loading gives the same ones back."""
    base, _ = tiny_refiner
    parts = {k: getattr(base, k) for k in ("recognizer", "anchor_refiner", "transition_generator",
                                           "transition_refiner", "anchor_concepts", "anchor_quality")}
    own = base.anchor_quality.threshold_
    hand = Refiner(**parts, action_names=base.action_names,
                   manifest={"calibration": {"anchor_threshold": own - 5.0, "transition_threshold": 0.01}})
    assert hand.anchor_quality.threshold_ == own - 5.0 and base.anchor_quality.threshold_ == own
    assert hand.transition_retimer.threshold(7) == hand.transition_retimer.threshold(200) == 0.01
    hand.save(tmp_path / "saved")
    manifest = json.loads((tmp_path / "saved" / "manifest.json").read_text())
    assert manifest["calibration"] == {"transition_thresholds": [[float("inf"), 0.01]]}  # the anchor's is in its file
    back = Refiner.load(tmp_path / "saved")
    assert back.anchor_quality.threshold_ == own - 5.0 and back.transition_retimer.thresholds_ == [[float("inf"), 0.01]]
    clip = humanact12[700]
    np.testing.assert_array_equal(back.refine(clip).joints, hand.refine(clip).joints)


def test_shipped_weights_list_skeleton_split_and_licence():
    shipped = {w["folder"]: w for w in Refiner.shipped()}
    assert {"humanact12", "humanact12-train"} <= set(shipped)
    for w in shipped.values():
        assert w["licence"] and w["skeleton"] and w["split"] in ("all", "train") and w["parts"]
    assert "non-commercial" in shipped["humanact12"]["licence"]
    for w in shipped.values():  # the concepts method's parts only
        assert set(w["parts"]) <= {"recognizer", "anchor_refiner", "transition_generator", "transition_refiner",
                                   "anchor_concepts", "anchor_quality"}
    with pytest.raises(ValueError, match=r"no concepts weights for skeleton 'humanact12', split 'test'; shipped: .*humanact12 \(humanact12, all\)"):
        Refiner.pretrained("humanact12", split="test")


def test_cmu_clips_through_the_default_refiner():
    """CMU's own motion model, once it ships (``refiner/weights/cmu_mocap-motion/``): real held-out CMU clips, single and
    batched, with reports; clean ones barely move and frames outside the reported changes come back as given."""
    from conftest import shared_data_dir

    from refiner.io.datasets import load_cmu_mocap
    from refiner.refinement.motion_refiner import _WEIGHTS

    if not (_WEIGHTS / "cmu_mocap-motion" / "manifest.json").is_file():
        with pytest.raises(ValueError, match="no motion model for skeleton 'cmu_mocap'"):
            MotionRefiner.pretrained("cmu_mocap")
        pytest.skip("no motion model for skeleton 'cmu_mocap' yet (refiner/weights/cmu_mocap-motion/ is not shipped)")
    test = load_cmu_mocap(shared_data_dir() / "cmu_mocap" / "cmu_mocap_labeled_joints.npz").split("test")
    clips = [m.with_joints(m.joints[:80]) for m in test if m.n_frames >= 80][:12:4]
    one, report = refine(clips[0], skeleton="cmu_mocap", return_report=True)  # with its CMU action
    assert one.skeleton == "cmu_mocap" and report.action == clips[0].action
    batch = np.stack([m.joints for m in clips])
    out, reports = refine(batch, skeleton="cmu_mocap", return_report=True)  # action unknown
    assert out.shape == batch.shape and len(reports) == len(clips)
    assert 100 * np.linalg.norm(out - batch, axis=-1).mean() < 0.3  # clean held-out clips: under 0.3 cm
    for o, x, r in zip(out, batch, reports):
        assert (o == x).all((-1, -2))[~r.changed_frames].all()
