"""The texture filter: turns and moves with the clip, refuses bad input, survives saving, runs on the clips
``texture`` names and no others, reports each, and, shipped, smooths a rough real clip while the default refiner
leaves clean clips alone; the wrapper around a generator filters every clip."""
import copy

import numpy as np
import pytest

from refiner.core.skeletons import bone_lengths
from refiner.core.validation import NotFittedError
from refiner.nn.training import TrainSchedule
from refiner.refinement.pipeline import Refiner
from refiner.refinement.report import RefinementReport
from refiner.refinement.texture_filter import TextureFilter, filtered_texture

TINY = TrainSchedule(n_epochs=1, steps_per_epoch=2, batch_size=4, device="cpu")


def _turned(x, angle):
    """``x (..., J, 3)`` turned by ``angle`` about HumanAct12's up axis (y)."""
    c, s = np.cos(angle), np.sin(angle)
    return x @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], np.float32).T


@pytest.fixture(scope="module")
def tiny(humanact12):
    clips = [m.joints for m in humanact12.motions[:30]]
    return TextureFilter(channels=8, dilations=(1,), crop=16, schedule=TINY).fit(clips), clips


@pytest.mark.real_data
def test_filter_turns_and_moves_with_the_clip_and_keeps_its_input(tiny):
    part, clips = tiny
    x = clips[0][None, :30].copy()
    given = x.copy()
    y = part.filtered(x)
    assert y.shape == x.shape and y.dtype == np.float32 and np.array_equal(x, given)
    assert not np.allclose(y, x)  # an untrained-ish network still corrects
    np.testing.assert_allclose(part.filtered(_turned(x, 0.9)), _turned(y, 0.9), atol=2e-5)
    shift = np.array([0.7, 0.0, -1.3], np.float32)
    np.testing.assert_allclose(part.filtered(x + shift), y + shift, atol=2e-5)


@pytest.mark.real_data
def test_saved_filter_gives_the_same_clips_and_bad_input_is_refused(tiny, tmp_path):
    part, clips = tiny
    x = clips[1][None, :24]
    part.save(tmp_path / "t.safetensors", half=True)
    again = TextureFilter.load(tmp_path / "t.safetensors")
    np.testing.assert_allclose(again.filtered(x), part.filtered(x), atol=5e-4)
    with pytest.raises(ValueError, match="24, 3"):
        part.filtered(np.zeros((1, 20, 18, 3), np.float32))
    with pytest.raises(ValueError):
        part.filtered(np.full((1, 20, 24, 3), np.nan, np.float32))
    with pytest.raises(NotFittedError):
        TextureFilter().filtered(x)
    with pytest.raises(ValueError, match="passes"):
        TextureFilter(passes=0, schedule=TINY).fit([c for c in clips[:3]])


@pytest.mark.real_data
def test_step_runs_on_the_clips_texture_names_and_reports_them(tiny):
    part, clips = tiny
    x = np.stack([c[:24] for c in clips[:3]]).astype(np.float32)
    noisy = np.array([False, True, False])

    def run(texture):
        refiner = type("R", (), {"texture_filter": part, "texture": texture, "skeleton": "humanact12"})()
        reports = [RefinementReport(mode="full", n_frames=24) for _ in x]
        return filtered_texture(refiner, x, reports, noisy), reports

    out, reports = run("auto")
    assert np.array_equal(out[[0, 2]], x[[0, 2]]) and not np.allclose(out[1], x[1])
    assert [len(r.changes) for r in reports] == [0, 1, 0]
    assert reports[1].changes[0]["step"] == "texture" and "noisy throughout" in reports[1].changes[0]["reason"]
    out, reports = run("all")
    assert all(not np.allclose(o, c) for o, c in zip(out, x)) and all(r.changes[0]["step"] == "texture" for r in reports)
    out, reports = run("off")
    assert out is x and not any(r.changes for r in reports)


def test_unknown_texture_is_refused():
    with pytest.raises(ValueError, match="texture"):
        Refiner.pretrained("humanact12", texture="everything")


@pytest.mark.real_data
def test_shipped_filter_takes_noise_off_held_out_clips_and_only_generated_ones_by_default(humanact12):
    from refiner.refinement.refined_generator import _default_refiner

    test = humanact12.split("test")
    clips = np.stack([m.joints[:48] for m in test.motions if m.n_frames >= 48][:12]).astype(np.float32)
    rough = clips + np.random.default_rng(0).normal(0, 0.015, clips.shape).astype(np.float32)
    refiner = Refiner.pretrained("humanact12", split="train")
    assert refiner.texture == "off" and refiner.texture_filter.passes == 3
    before = np.linalg.norm(rough - clips, axis=-1).mean()
    after = np.linalg.norm(refiner.texture_filter.filtered(rough) - clips, axis=-1).mean()
    assert after < 0.7 * before  # 1.5 cm white noise on people it never saw: 40 % of it off (the filter alone)
    _, reports = refiner.refine(clips[:4], return_report=True)
    assert not any(c["step"] == "texture" for r in reports for c in r.changes)  # clean mocap: not a generator's
    generated = _default_refiner("humanact12")
    assert generated.texture == "all"
    out, reports = generated.refine(rough[:2], return_report=True)
    assert all([c["step"] for c in r.changes].count("texture") == 1 for r in reports)
    from refiner.reference import load_reference_generator

    a2m = load_reference_generator("a2m").sample_motions(3, 8, random_state=5)  # its rigid, jittering clips
    _, reports = generated.refine(np.stack([m.joints for m in a2m]), action=3, return_report=True)
    posed = [any(c["step"] == "pose" and "after the texture filter" in c["reason"] for c in r.changes) for r in reports]
    assert 0 < sum(posed) < len(posed)  # the poses the filter left off real motion, where there are such poses
    assert bone_lengths(out, "humanact12").std(1).max() < 1e-4  # back on rigid bones after the filter


@pytest.mark.real_data
def test_rotation_jitter_keeps_bones_and_carries_each_turn_down_the_limb(humanact12):
    """The ``rotation_share`` option's corruption: bone lengths exact, the root still, hands moved more than hips."""
    from refiner.refinement.texture_filter import _turned_bones

    x = np.stack([m.joints[:20] for m in humanact12.motions[:4]]).astype(np.float64)
    y = _turned_bones(x, np.full((4, 1, 1, 1), 0.02), "humanact12", np.random.default_rng(0))
    np.testing.assert_allclose(bone_lengths(y, "humanact12"), bone_lengths(x, "humanact12"), atol=1e-9)
    move = np.linalg.norm(y - x, axis=-1).mean((0, 1))  # (J,) metres
    assert move[0] == 0 and move[[22, 23]].mean() > 4 * move[[1, 2]].mean()  # hands against hips
    assert np.array_equal(_turned_bones(x, np.zeros((4, 1, 1, 1)), "humanact12", np.random.default_rng(0)), x)
    spoiled = TextureFilter(rotation_share=1.0, clean_probability=0.0)
    spoiled.skeleton_ = "humanact12"
    z = spoiled._rough(x.astype(np.float32), np.random.default_rng(1))
    np.testing.assert_allclose(bone_lengths(z, "humanact12"), bone_lengths(x, "humanact12"), atol=1e-5)
    with pytest.raises(ValueError, match="rotation_share"):
        TextureFilter(rotation_share=1.5, schedule=TINY).fit([m.joints for m in humanact12.motions[:3]])
