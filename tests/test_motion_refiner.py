"""The default refiner on real clips: what it returns, what it leaves alone, and what it refuses."""
import numpy as np
import pytest
import torch

from refiner.core.skeletons import bone_lengths
from refiner.refinement.training.mechanisms import MECHANISMS
from refiner.refinement.motion_refiner import MotionRefiner


@pytest.fixture(scope="module")
def model():
    return MotionRefiner.pretrained("humanact12")


@pytest.fixture(scope="module")
def held_out(humanact12):
    return [m for m in humanact12.split("test") if m.n_frames >= 60][:24]


@pytest.mark.real_data
def test_refined_clips_keep_their_bones_and_unchanged_frames(model, held_out):
    clips = np.stack([m.joints[:60] for m in held_out])
    flawed = np.stack([MECHANISMS["time_hold"](c, np.random.default_rng(i)) for i, c in enumerate(clips)])
    given = flawed.copy()
    out, reports = model.refine(flawed, action=[m.action for m in held_out], return_report=True)
    np.testing.assert_array_equal(flawed, given)
    assert out.shape == flawed.shape and out.dtype == np.float32
    for o, f, r in zip(out, flawed, reports):
        kept = ~r.changed_frames
        np.testing.assert_array_equal(o[kept], f[kept])
        np.testing.assert_allclose(bone_lengths(o, "humanact12"), bone_lengths(f, "humanact12"), atol=1e-4)
        assert all(c["step"] in {s.name for s in model.steps} and c["parts"] and c["reason"] for c in r.changes)
        assert len(r.flaw_probability) == 60


@pytest.mark.real_data
def test_held_pose_error_falls_on_held_out_subjects(model, held_out):
    """A frozen then jumping window on unseen people: the refiner repairs some clips and adds error to none."""
    clips = np.stack([m.joints[:60] for m in held_out]).astype(np.float64)
    flawed = np.stack([MECHANISMS["time_hold"](c, np.random.default_rng(i)) for i, c in enumerate(clips)])
    out = model.refine(flawed.astype(np.float32))
    before = np.linalg.norm(flawed - clips, axis=-1).mean((1, 2))
    after = np.linalg.norm(out - clips, axis=-1).mean((1, 2))
    assert after.sum() < before.sum()
    assert (after < before - 1e-4).sum() >= 2


@pytest.mark.real_data
def test_clean_clips_are_left_almost_alone(model, held_out):
    clips = np.stack([m.joints[:60] for m in held_out])
    out = model.refine(clips)
    touched = np.abs(out - clips).max((1, 2, 3)) > 0
    assert touched.mean() <= 0.25
    assert np.linalg.norm(out - clips, axis=-1).mean() < 0.005


def test_kinds_come_back_as_given(model, rng):
    x = (rng.normal(size=(20, 24, 3)) * 0.2).astype(np.float32)
    assert isinstance(model.refine(torch.from_numpy(x)), torch.Tensor)
    assert model.refine(x.astype(np.float64)).dtype == np.float64
    np.testing.assert_array_equal(model.refine(x[:5]), x[:5])  # too short: as given


@pytest.mark.parametrize("bad, words", [
    (np.full((30, 24, 3), np.nan, np.float32), "NaN"),
    (np.zeros((30, 23, 3), np.float32), "J=24"),
    (np.zeros((30, 24), np.float32), "shape"),
])
def test_bad_input_is_a_value_error(model, bad, words):
    with pytest.raises(ValueError, match=words):
        model.refine(bad)


def test_unknown_model_and_mode_are_value_errors(model):
    with pytest.raises(ValueError, match="unknown motion model"):
        MotionRefiner.pretrained("humanact12", model="fold7")
    with pytest.raises(ValueError, match="concepts"):
        model.refine(np.zeros((30, 24, 3), np.float32), mode="anchor")


@pytest.mark.real_data
def test_converted_skeleton_changes_only_the_refined_frames(held_out):
    from refiner.core.skeleton_conversion import convert

    refiner = MotionRefiner.pretrained("humanml3d")
    clips = np.stack([convert(m.joints[:60], "humanact12", "humanml3d") for m in held_out[:8]]).astype(np.float32)
    flawed = np.stack([MECHANISMS["time_hold"](c, np.random.default_rng(i), skeleton="humanml3d")
                       for i, c in enumerate(clips)])
    out, reports = refiner.refine(flawed, return_report=True)
    assert out.shape == flawed.shape
    for o, f, r in zip(out, flawed, reports):
        np.testing.assert_array_equal(o[~r.changed_frames], f[~r.changed_frames])


def test_too_long_is_a_value_error(model):
    from refiner.refinement.motion_refiner import MAX_FRAMES

    with pytest.raises(ValueError, match="too long"):
        model.refine(np.zeros((MAX_FRAMES + 1, 24, 3), np.float32))
