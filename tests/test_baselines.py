"""Baseline refiners: one interface, known filter properties, and how much they move clean clips."""
from __future__ import annotations

import numpy as np
import pytest

from refiner.evaluation.baselines import (
    FLAW_REFINERS,
    GaussianRefiner,
    IdentityRefiner,
    SavgolRefiner,
    SplineFitRefiner,
    clean_clip_change,
)
from refiner.core.motion import Motion
from refiner.evaluation.physics import acceleration

BASELINES = [IdentityRefiner, SavgolRefiner, GaussianRefiner, SplineFitRefiner]


@pytest.mark.parametrize("cls", BASELINES, ids=lambda c: c.__name__)
def test_interface_keeps_length_skeleton_fps_and_action(cls, tiny_clip):
    m = Motion(tiny_clip, fps=30.0, action=3)
    before = m.numpy()
    out = cls().refine(m, action=3)
    assert isinstance(out, Motion)
    assert out.joints.shape == m.joints.shape and (out.skeleton, out.fps, out.action) == ("humanact12", 30.0, 3)
    np.testing.assert_array_equal(m.joints, before)
    arr_out = cls().refine(tiny_clip)  # an array is taken as a HumanAct12 clip
    np.testing.assert_allclose(arr_out.joints, out.joints, atol=1e-6)
    assert cls().get_params() == type(cls())(**cls().get_params()).get_params()


def test_identity_is_exact(tiny_clip):
    m = Motion(tiny_clip)
    assert IdentityRefiner().refine(m) == m


def test_savgol_keeps_quadratics_and_removes_jitter(rng):
    t = np.linspace(0, 2, 50)[:, None, None]
    quad = np.broadcast_to(0.3 * t**2 - 0.2 * t + 1.0, (50, 24, 3)).copy()
    out = SavgolRefiner().refine(Motion(quad))
    np.testing.assert_allclose(out.joints, quad, atol=1e-5)  # order-2 polynomials pass unchanged
    noisy = quad + rng.normal(0, 0.01, quad.shape)
    assert acceleration(SavgolRefiner().refine(Motion(noisy))) < 0.5 * acceleration(noisy)
    assert acceleration(GaussianRefiner().refine(Motion(noisy))) < 0.5 * acceleration(noisy)


def test_gaussian_keeps_constants_and_straight_lines_inside():
    line = np.broadcast_to(np.linspace(0, 1, 30)[:, None, None], (30, 24, 3)).copy()
    out = GaussianRefiner(sigma=1.0).refine(Motion(line)).joints
    np.testing.assert_allclose(out[4:-4], line[4:-4], atol=1e-6)  # symmetric kernel keeps a line
    const = np.ones((10, 24, 3))
    np.testing.assert_allclose(GaussianRefiner().refine(Motion(const)).joints, const, atol=1e-6)


def test_spline_fit_reconstructs_piecewise_cubics(tiny_clip):
    out = SplineFitRefiner().refine(Motion(tiny_clip)).joints
    assert np.abs(out - tiny_clip).max() < 1e-4


def test_short_clips_pass_through():
    short = np.random.default_rng(0).normal(size=(3, 24, 3))
    for cls in BASELINES:
        out = cls().refine(Motion(short)).joints
        assert out.shape == (3, 24, 3)
    np.testing.assert_allclose(SplineFitRefiner().refine(Motion(short)).joints, short, atol=1e-5)
    np.testing.assert_allclose(SavgolRefiner(window_length=5, polyorder=2).refine(Motion(short)).joints, short,
                               atol=1e-5)


def test_bad_hyper_parameters_raise_on_use(tiny_clip):
    with pytest.raises(ValueError, match="window_length"):
        SavgolRefiner(window_length=4).refine(tiny_clip)
    with pytest.raises(ValueError, match="polyorder"):
        SavgolRefiner(window_length=5, polyorder=5).refine(tiny_clip)
    with pytest.raises(ValueError, match="sigma"):
        GaussianRefiner(sigma=0).refine(tiny_clip)
    with pytest.raises(ValueError, match="penalty"):
        SplineFitRefiner(penalty=-1).refine(tiny_clip)
    with pytest.raises(ValueError, match="Motion"):
        IdentityRefiner().refine(np.zeros((10, 22, 3)))


def test_registry_factories():
    assert list(FLAW_REFINERS)[:4] == ["identity", "savgol", "gaussian", "spline_fit"]
    assert list(FLAW_REFINERS)[4:] == ["ours_full", "ours_anchor", "ours_transition", "ours_concepts",
                                       "ours_concept_snap"]
    for name in ("identity", "savgol", "gaussian", "spline_fit"):
        assert hasattr(FLAW_REFINERS[name](), "refine")
    assert FLAW_REFINERS["ours_full"]().method == "motion"  # the default refiner
    for name, mode in (("ours_anchor", "anchor"), ("ours_transition", "transition"), ("ours_concepts", "full")):
        try:
            refiner = FLAW_REFINERS[name]()
        except (ImportError, ValueError):
            continue  # pipeline or its held-out weights not available yet: the bench skips it
        assert refiner.mode == mode and refiner.refiner_.method == "concepts"


@pytest.mark.real_data
def test_clean_clip_change_on_real_clips(humanact12):
    clips = humanact12.split("test").motions[::20]
    assert clean_clip_change(IdentityRefiner(), clips) == 0.0
    savgol = clean_clip_change(SavgolRefiner(), clips)
    gauss = clean_clip_change(GaussianRefiner(), clips)
    spline = clean_clip_change(SplineFitRefiner(), clips)
    # measured on subjects 11-12: savgol ~0.36 cm, gaussian ~0.53 cm, spline refit ~1.1 cm
    assert 0.1 < savgol < gauss < spline < 2.0
    with pytest.raises(ValueError, match="empty"):
        clean_clip_change(IdentityRefiner(), [])
