"""Planted feet, the skating statistic and the skating step: small generated inputs and real clips."""
import numpy as np
import pytest
from conftest import shared_data_dir

import refiner.refinement.skating as skating_step
from refiner.core.contact import (PLANTED_SPEED, SKATING_WINDOW, contact_joints, foot_joints, glide_steps, heights,
                                  on_ground_as, planted_feet, skating)
from refiner.core.skeletons import get_skeleton
from refiner.evaluation.flaws import corrupt
from refiner.io.datasets import load_cmu_mocap
from refiner.refinement.pipeline import Refiner
from refiner.refinement.report import RefinementReport
from refiner.refinement.skating import SKATING_KEY, calibrate_skating, deskated, skating_threshold

SKEL = get_skeleton("humanact12")


def _err(a, b):
    return 100 * float(np.linalg.norm(a - b, axis=-1).mean())


def _feet_clip(heights_cm, steps_cm):
    """A (T, 24, 3) HumanAct12 clip whose feet sit ``heights_cm (T, 2)`` above the ground and move ``steps_cm (T-1,)``
    along x each frame (both feet); every other joint at the root."""
    t = len(heights_cm)
    x = np.zeros((t, 24, 3))
    feet = list(foot_joints(SKEL))
    x[:, feet, 1] = -np.asarray(heights_cm) / 100  # y down
    x[1:, feet, 0] = np.cumsum(steps_cm)[:, None] / 100
    return x


def test_planted_feet_reads_the_local_ground_and_leaves_swinging_feet_out():
    t = 120
    floor = np.linspace(0.0, 8.0, t)  # the ground rises 8 cm over the clip (a slope, mocap drift)
    x = _feet_clip(np.stack([floor, floor], 1), np.full(t - 1, 0.2))
    assert planted_feet(x, SKEL).all()  # resting on the local ground, slipping 2 mm per frame
    assert not planted_feet(x, SKEL, window=None)[-20:].any()  # the clip's lowest point misses the end
    fast = _feet_clip(np.zeros((t, 2)), np.full(t - 1, 100 * PLANTED_SPEED + 1.0))
    assert not planted_feet(fast, SKEL).any()  # a foot skimming the ground at walking swing speed
    assert planted_feet(fast, SKEL, speed=None).all()
    assert planted_feet(x[None].repeat(3, 0), SKEL).shape == (3, t, 2)  # batch dimensions


def test_glide_and_skating_on_a_gliding_body():
    t = 60
    x = _feet_clip(np.zeros((t, 2)), np.zeros(t - 1))
    glide = np.zeros(t)
    glide[20:40] = 0.2 * np.sin(np.pi * np.arange(20) / 19) ** 2  # out and back by 20 cm
    moved = x.copy()
    moved[..., 0] += glide[:, None]  # root and feet alike
    steps = glide_steps(moved, SKEL)
    np.testing.assert_allclose(steps[:, 0], np.diff(glide), atol=1e-12)
    assert 0.15 < skating(moved, SKEL).max() < 0.2 + 1e-9 and skating(x, SKEL).max() == 0
    feet_only = x.copy()
    feet_only[:, list(foot_joints(SKEL)), 0] += glide[:, None]  # the feet slip, the root stays: not a glide
    assert np.abs(glide_steps(feet_only, SKEL)).max() == 0
    assert skating(moved[None].repeat(2, 0), SKEL).shape == (2, t - 1)


def test_threshold_option_and_calibration_are_checked():
    assert skating_threshold({}, None) == 0.0
    assert skating_threshold({"learned": {SKATING_KEY: 0.1}}, None) == 0.1
    assert skating_threshold({"learned": {SKATING_KEY: 0.1}}, 0.0) == 0.0
    for bad in (-0.1, float("nan"), True):
        with pytest.raises(ValueError, match="skating"):
            skating_threshold({}, bad)
    with pytest.raises(ValueError, match="longer than"):
        calibrate_skating([np.zeros((SKATING_WINDOW, 24, 3))], "humanact12")


@pytest.mark.real_data
def test_shipped_thresholds_pass_few_clean_clips(humanact12):
    model = Refiner.pretrained("humanact12", split="train")
    assert 0.05 < model.skating < 0.2
    assert Refiner.pretrained("humanact12", split="train", skating=0).skating == 0
    assert 0.05 < Refiner.pretrained("cmu_mocap", split="train").skating < 0.2
    test = humanact12.split("test")
    peaks = np.array([skating(m.joints, SKEL).max() for m in test.motions if m.n_frames > 2 * SKATING_WINDOW])
    assert np.mean(peaks > model.skating) < 0.03  # held-out subjects' clean clips


@pytest.fixture(scope="module")
def cmu_test():
    data = load_cmu_mocap(shared_data_dir() / "cmu_mocap" / "cmu_mocap_labeled_joints.npz")
    return [m.with_joints(m.joints[:120]) for m in data.split("test") if m.n_frames >= 120]


@pytest.mark.real_data
def test_the_step_moves_a_gliding_body_back_and_leaves_clean_clips(cmu_test):
    """The CMU weights' detectors, which never saw the body move sideways, miss these glides; the step does not."""
    on = Refiner.pretrained("cmu_mocap", split="train")
    off = Refiner.pretrained("cmu_mocap", split="train", skating=0)
    clips = cmu_test[::2]  # the bench's CMU row: 53 clips
    flawed = np.stack([corrupt(m, "foot_sliding", 2, random_state=i).motion.joints for i, m in enumerate(clips)])
    truth = np.stack([m.joints for m in clips])
    refined, reports = on.refine(flawed, return_report=True)
    moved = sum(any("glides" in c.get("reason", "") for c in r.changes) for r in reports)
    assert moved >= 20
    added = _err(flawed, truth)
    assert _err(refined, truth) < 0.75 * added  # 40 % removed (the bench's row); 4 % without the step
    assert _err(off.refine(flawed), truth) > 0.9 * added
    clean_on, clean_off = on.refine(truth), off.refine(truth)
    assert _err(clean_on, clean_off) < 0.01  # clean clips: as without the step


@pytest.mark.real_data
def test_a_correction_that_roughens_the_root_is_refused(cmu_test, monkeypatch):
    """A CMU walk whose anchor pose is wrong slips its planted foot while the root walks on; moving the body back
    by that slip stops the walk (the root's path gets rougher): refused, so the step does no harm there."""
    walks = [m for m in cmu_test if m.action == 0][:12]
    flawed = np.stack([corrupt(m, "wrong_anchor", 2, random_state=i).motion.joints for i, m in enumerate(walks)])
    truth = np.stack([m.joints for m in walks])

    class Stub:
        skeleton, blend, skating = "cmu_mocap", 4, 0.08

    def run():
        reports = [RefinementReport(mode="full", n_frames=120) for _ in walks]
        return deskated(Stub(), flawed.copy(), reports, "full"), reports

    checked, _ = run()
    monkeypatch.setattr(skating_step, "SMOOTHER_ROOT", False)
    unchecked, reports = run()
    harmed = [_err(u, t) - _err(f, t) for u, f, t in zip(unchecked, flawed, truth)]
    assert max(harmed) > 0.3 and sum(bool(r.changes) for r in reports) >= 3  # unchecked, it moves walks and harms
    assert all(_err(c, t) <= _err(f, t) + 0.05 for c, f, t in zip(checked, flawed, truth))
    assert deskated(Stub(), flawed, [RefinementReport(mode="anchor", n_frames=120)] * len(walks), "anchor") is flawed


def test_on_ground_as_keeps_each_frames_lowest_foot_where_it_was(rng):
    like = rng.normal(0, 0.3, (2, 30, 24, 3))
    edited = like + rng.normal(0, 0.05, like.shape)  # a pose edited about the root: feet off their ground
    out = on_ground_as(edited, like, "humanact12")
    low = lambda a: heights(a[..., list(contact_joints("humanact12")), :], "humanact12").min(-1)  # noqa: E731
    np.testing.assert_allclose(low(out), low(like), atol=1e-9)
    moved = out - edited  # only along the up axis, one shift per frame
    np.testing.assert_allclose(moved - (moved @ SKEL.up_vector)[..., None] * SKEL.up_vector, 0, atol=1e-12)
    assert np.ptp(moved, axis=-2).max() < 1e-12
    assert out.dtype == edited.dtype and np.array_equal(on_ground_as(like, like, "humanact12"), like)
