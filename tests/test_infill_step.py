"""The motion model's step on small inputs: flags from probabilities, in-fill only where flagged, bones kept."""
import numpy as np
import pytest
import torch

from refiner.core.skeletons import bone_lengths, get_skeleton
from refiner.refinement.motion_model import MotionModel, joints_from_features, motion_features
from refiner.refinement.networks.motion_net import MotionNet, MotionNetConfig
from refiner.refinement.steps.base import dilated, harms, runs, window_figures
from refiner.refinement.steps.infill import InfillConfig, InfillStep, _joined_root, clip_scores, flagged_parts


@pytest.fixture(scope="module")
def tiny_model():
    torch.manual_seed(0)
    model = MotionModel("humanact12", ("a", "b"), MotionNetConfig(n_bones=23, n_actions=2, width=16, dilations=(1, 2)))
    return model.set_network(MotionNet(model.config))


def test_runs_and_dilation():
    m = np.array([0, 1, 1, 0, 0, 1, 0], bool)
    assert runs(m) == [(1, 3), (5, 6)]
    assert dilated(m, 1).tolist() == [1, 1, 1, 1, 1, 1, 1]
    assert dilated(m, 0, 1).tolist() == [0, 1, 1, 1, 0, 1, 1]


def test_flags_need_min_run_frames_above_threshold():
    p = np.zeros((20, 3))
    p[5, 0] = 0.9            # one frame: not a run
    p[10:13, 1] = 0.9        # three frames: flagged, widened by 2
    flagged = flagged_parts(p, InfillConfig(threshold=0.5, min_run=2, margin=2))
    assert not flagged[:, 0].any() and not flagged[:, 2].any()
    assert np.flatnonzero(flagged[:, 1]).tolist() == list(range(8, 15))
    assert clip_scores(p[None], 2)[0] == pytest.approx(0.9)
    assert clip_scores(p[None, :, :1], 2)[0] == 0.0
    batch = np.random.default_rng(0).random((3, 20, 3))  # a batch is flagged clip by clip
    config = InfillConfig(threshold=0.6, min_run=3, margin=1)
    np.testing.assert_array_equal(flagged_parts(batch, config), np.stack([flagged_parts(b, config) for b in batch]))


def test_features_round_trip(rng):
    x = rng.normal(size=(2, 9, 24, 3))
    feats, root, lengths = motion_features(x, "humanact12")
    assert feats.shape == (2, 9, 72) and feats.dtype == np.float32
    np.testing.assert_allclose(joints_from_features(feats, root[:, 0], lengths, "humanact12"), x, atol=1e-5)


def test_joined_root_keeps_the_frames_outside_the_run(rng):
    root = np.cumsum(rng.normal(size=(20, 3)) * 0.02, axis=0)
    hidden = np.zeros(20, bool)
    hidden[6:11] = True
    out = _joined_root(root, rng.normal(size=(20, 3)) * 0.05, hidden)
    np.testing.assert_array_equal(out[~hidden], root[~hidden])
    assert not np.allclose(out[hidden], root[hidden])


def test_propose_changes_flagged_frames_only_on_the_clips_bones(tiny_model, rng):
    x = rng.normal(size=(2, 16, 24, 3)) * 0.3
    step = InfillStep(tiny_model, InfillConfig(threshold=0.5))
    flagged = np.zeros((2, 16, 24), bool)
    flagged[0, 5:9, 15:18] = True  # three bones of clip 0
    out = step.propose(x, [0, None], flagged)
    np.testing.assert_array_equal(out[1], x[1])
    np.testing.assert_array_equal(out[0, :5], x[0, :5])
    np.testing.assert_array_equal(out[0, 9:], x[0, 9:])
    assert not np.allclose(out[0, 5:9], x[0, 5:9])
    np.testing.assert_allclose(bone_lengths(out, "humanact12"), bone_lengths(x, "humanact12"), atol=1e-9)


def test_verify_refuses_a_change_that_adds_jerk(tiny_model, rng):
    t = np.linspace(0, 1, 30)[:, None, None]
    x = np.broadcast_to(rng.normal(size=(1, 24, 3)) * 0.3, (30, 24, 3)) + 0.05 * t
    noisy = x + rng.normal(size=x.shape) * 0.03 * ((t > 0.3) & (t < 0.6))
    assert "jerk" in harms(window_figures(x, 9, 18, "humanact12", 0.0), window_figures(noisy, 9, 18, "humanact12", 0.0),
                           jerk_share=0.05, ground_tolerance_m=0.01, slide_pairs=0)
    step = InfillStep(tiny_model, InfillConfig(threshold=0.5))
    flagged = np.zeros((1, 30, 24), bool)
    flagged[0, 9:18] = True
    prob = np.ones((1, 30, 24))
    kept, changes = step.verify(x[None], noisy[None], [None], flagged, prob)
    np.testing.assert_array_equal(kept, x[None])
    assert changes[0][0]["kept"] is False and "jerk" in changes[0][0]["worse"]


def test_every_step_takes_the_no_harm_suites_tolerances():
    from refiner.evaluation.bench_noharm import TOLERANCES
    tol = {name: value for name, _, value in TOLERANCES}
    from refiner.refinement.steps.ground import GlideConfig, GroundConfig
    for config in (InfillConfig(threshold=0.5), GroundConfig(), GlideConfig()):
        assert config.jerk_share == tol["jerk"] and config.slide_pairs == 0 and tol["foot_skating"] < 1e-6
        assert config.ground_tolerance_m == pytest.approx(tol["penetration_cm"] / 100) == tol["floating_cm"] / 100


def test_penetration_is_worse_only_beyond_the_tolerance_per_frame(rng):
    x = np.broadcast_to(rng.normal(size=(1, 24, 3)) * 0.3, (30, 24, 3)).copy()
    from refiner.core.contact import foot_joints, heights
    ground = float(heights(x[:, list(foot_joints("humanact12"))], "humanact12").min())
    figures = window_figures(x, 9, 18, "humanact12", ground)
    assert figures.penetration == 0.0
    for depth, worse in ((0.0003, False), (0.002, True)):
        sunk = x.copy()
        sunk[12:15] -= 5 * depth * get_skeleton("humanact12").up_vector  # 3 of the window's 15 frames: a mean of depth
        after = window_figures(sunk, 9, 18, "humanact12", ground)
        assert after.penetration == pytest.approx(figures.penetration + depth, abs=1e-9)
        assert ("penetration" in harms(figures, after, jerk_share=1e9, ground_tolerance_m=5e-4, slide_pairs=0)) is worse
