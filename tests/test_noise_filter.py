"""The learned noise filter: fitted on real clips, it removes white noise better than smoothing, leaves clean
clips alone, survives float16 storage, refuses bad input, and runs as the refiner's noise steps."""
import copy

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from refiner.core.validation import NotFittedError
from refiner.evaluation.flaws import corrupt
from refiner.refinement.noise_filter import NOISE_LOW, NOISE_PROBABILITY, NOISE_RUN, NoiseFilter, noise_run_frames, window_features
from refiner.refinement.pipeline import Refiner


def _error(y, x):
    return float(np.linalg.norm(np.asarray(y, np.float64) - x, axis=-1).mean())


@pytest.fixture(scope="module")
def fitted(humanact12):
    train = [m.joints for m in humanact12.motions[:900:10]]
    held = [m.joints for m in humanact12.motions[900:1190:5]]
    return NoiseFilter(copies=1).fit(train), held


def test_window_features_are_displacements_and_pose():
    import torch

    x = torch.arange(2 * 5 * 2 * 3, dtype=torch.float32).reshape(2, 5, 2, 3)
    f = window_features(x, 1)
    assert f.shape == (2, 5, 3 * 6)
    np.testing.assert_allclose(f[0, 2, :6].numpy(), (x[0, 1] - x[0, 2]).reshape(-1).numpy())  # frame before
    np.testing.assert_allclose(f[0, 0, :6].numpy(), 0.0)  # the first frame's "before" repeats it
    np.testing.assert_allclose(f[0, 2, 12:].numpy(), (x[0, 2] - x[0, 2, :1]).reshape(-1).numpy())  # pose from the root


@pytest.mark.real_data
def test_filter_removes_white_noise_better_than_smoothing(fitted, rng):
    nf, held = fitted
    assert np.all(np.diff(nf.level_rms_) >= 0) and nf.level_rms_[-1] > 3 * nf.level_rms_[0]
    before, after, smooth, levels, clean_levels = [], [], [], [], []
    for x in held[:30]:
        x = x.astype(np.float64)
        y = (x + 0.01 * rng.normal(size=x.shape)).astype(np.float32)
        out = nf.denoise(y[None])[0]
        before.append(_error(y, x)), after.append(_error(out, x))
        smooth.append(_error(gaussian_filter1d(y, 1.0, axis=0, mode="nearest"), x))
        levels.append(np.median(nf.noise_level(y[None])))
        clean_levels.append(np.median(nf.noise_level(x[None])))
    assert np.mean(after) < 0.75 * np.mean(before), (np.mean(before), np.mean(after))
    assert np.mean(after) < np.mean(smooth), (np.mean(smooth), np.mean(after))
    assert 0.006 < np.median(levels) < 0.015 and np.median(clean_levels) < 0.004
    still = np.repeat(held[0][:1], 30, axis=0)[None] + np.float32(1e-3)  # running sums of zeros: no NaN
    calibrated = copy.deepcopy(nf)
    assert calibrated.calibrate(held[30:40], clip_rate=0.5) >= 1e-4  # most clean levels are 0: never a 0 threshold
    assert np.isfinite(nf.noise_level(still)).all() and np.array_equal(calibrated.denoise_clips(still)[0], still)
    clip = next(c for c in held if len(c) >= 60)[None, :60]
    noisy = (clip + 0.01 * rng.normal(size=clip.shape)).astype(np.float32)
    out, levels = calibrated.denoise_clips(noisy)
    assert levels[0] > calibrated.threshold_ and np.isfinite(out).all() and not np.array_equal(out, noisy)


@pytest.mark.real_data
def test_only_clips_noisy_throughout_change(fitted, rng, tmp_path):
    nf, held = copy.deepcopy(fitted[0]), fitted[1]  # calibrated here, not in the shared fixture
    threshold = nf.calibrate(held[30:], clip_rate=0.1)
    assert 0 < threshold < 0.01
    clean = np.stack([c[:40] for c in held[:20] if len(c) >= 40])
    quiet = nf.clip_noise_level(clean) <= threshold
    out, levels = nf.denoise_clips(clean)
    np.testing.assert_array_equal(out[quiet], clean[quiet])  # exactly as given
    assert quiet.mean() >= 0.7
    noisy = (clean + 0.02 * rng.normal(size=clean.shape)).astype(np.float32)
    given = noisy.copy()
    out, levels = nf.denoise_clips(noisy)
    np.testing.assert_array_equal(noisy, given)  # the input is not modified
    assert (levels > threshold).all() and _error(out, clean) < 0.7 * _error(noisy, clean)
    path = tmp_path / "noise_filter.safetensors"
    nf.save(path, half=True)
    again = NoiseFilter.load(path)
    assert again.threshold_ == threshold and again.level_rms_ == nf.level_rms_
    np.testing.assert_allclose(again.denoise(noisy[:3]), nf.denoise(noisy[:3]), atol=5e-4)  # float16 weights


def test_unfitted_and_bad_input_are_refused(fitted):
    with pytest.raises(NotFittedError):
        NoiseFilter().denoise(np.zeros((1, 10, 24, 3), np.float32))
    for levels in ((0.02, 0.04), (0.01,)):
        with pytest.raises(ValueError, match="two or more .* including 0.01"):
            NoiseFilter(levels=levels).fit([np.zeros((10, 24, 3))])
    with pytest.raises(ValueError, match="non-empty list"):
        NoiseFilter().fit([np.zeros((1, 24, 3))])
    nf, held = fitted
    for bad, match in ((np.zeros((10, 24, 3)), "B, T, 24, 3"), (np.full((1, 10, 24, 3), np.nan), "finite")):
        with pytest.raises(ValueError, match=match):
            nf.denoise(bad)
    with pytest.raises(ValueError, match="clip_rate"):
        nf.calibrate(held[:3], clip_rate=1.5)


@pytest.mark.real_data
def test_shipped_refiner_denoises_clips_noisy_throughout(humanact12, rng, one_torch_thread):
    """A generator's options (``denoising="filter"``) denoise a clip noisy throughout as a whole; ``refine()``'s default
    (``"runs"``) finds and reports it so too, but denoises only the runs the classifier sees in it."""
    default = Refiner.pretrained("humanact12", split="train")
    model = Refiner.pretrained("humanact12", split="train", denoising="filter")
    assert default.denoising == "runs" and model.noise_filter is not None
    assert model.manifest["learned"]["noise_threshold_m"] == pytest.approx(model.noise_filter.threshold_)
    x = humanact12[700].joints[:60].astype(np.float64)
    noisy = (x + 0.015 * rng.normal(size=x.shape)).astype(np.float32)
    out, report = model.refine(noisy, return_report=True)
    assert report.noisy_throughout and any(c["step"] == "noise" and c["repair"] == "noise_filter" for c in report.changes)
    assert _error(out, x) < 0.75 * _error(noisy, x)
    out, report = default.refine(noisy, return_report=True)
    assert report.noisy_throughout and not any("noisy throughout" in c["reason"] for c in report.changes)
    assert any(c["step"] == "noise" and "noise-group" in c["reason"] for c in report.changes)
    assert _error(out, x) < 0.9 * _error(noisy, x)
    flagged = Refiner.pretrained("humanact12", split="train", denoising="flagged")
    _, report = flagged.refine(noisy, return_report=True)
    assert not any(c["step"] == "noise" for c in report.changes)
    with pytest.raises(ValueError, match="denoising='filter' needs a `noise_filter`"):
        Refiner(*(None,) * 6, model.flaw_recognizer, model.flaw_repairer, model.flaw_classifier, denoising="filter")


def test_noise_runs_need_a_seed_of_noise_run_frames_and_grow_while_above_the_low_mark():
    high, mid, low = NOISE_PROBABILITY + 0.05, (NOISE_PROBABILITY + NOISE_LOW) / 2, NOISE_LOW - 0.1
    row = np.full(20, low)
    row[3:5] = mid
    row[5 : 5 + NOISE_RUN] = high  # a seed, grown over the mid frames around it
    row[5 + NOISE_RUN : 11] = mid
    row[14 : 14 + NOISE_RUN - 1] = high  # too short a seed
    frames = noise_run_frames(np.stack([row, np.full(20, low)]))
    assert frames.shape == (2, 20) and not frames[1].any()
    np.testing.assert_array_equal(np.flatnonzero(frames[0]), np.arange(3, 11))


@pytest.mark.real_data
def test_noise_runs_the_classifier_sees_are_denoised_and_clean_clips_left(humanact12, one_torch_thread):
    """Jitter in a real clip: the classifier's noise group finds it where its flaw threshold does not flag it."""
    clean = humanact12[0]
    jittered = corrupt(clean, "transition_jitter", 2, random_state=0).motion
    model = Refiner.pretrained("humanact12", split="train")
    before = Refiner.pretrained("humanact12", split="train", denoising="throughout")
    out, report = model.refine(jittered, return_report=True)
    runs = [c for c in report.changes if "noise-group" in c["reason"]]
    assert len(runs) == 1 and runs[0]["repair"] == "noise_filter"
    previous, report_before = before.refine(jittered, return_report=True)
    assert _error(out.joints, clean.joints) < 0.9 * _error(previous.joints, clean.joints)
    assert not any("noise-group" in c["reason"] for c in report_before.changes)
    outside = np.ones(clean.n_frames, bool)
    outside[runs[0]["start"] : runs[0]["stop"]] = False
    np.testing.assert_array_equal(out.joints[outside], previous.joints[outside])  # the step changes its runs only
    seen = 0
    for mode in ("anchor", "transition"):  # a run holding a recognised anchor is an anchor step
        _, report = model.refine(jittered, mode=mode, return_report=True)
        for change in (c for c in report.changes if "noise-group" in c["reason"]):
            held = [a for a in report.anchors if change["start"] <= a < change["stop"]]
            assert bool(held) == (mode == "anchor")
            seen += 1
    assert seen == 1  # the one run, in one of the two modes
    for motion in humanact12.motions[:40]:  # clean clips: no noise run
        _, report = model.refine(motion, return_report=True)
        assert not any("noise-group" in c["reason"] for c in report.changes)


@pytest.mark.real_data
def test_denoising_chosen_frames_leaves_every_other_frame_exactly(fitted, rng):
    nf, held = fitted
    x = np.stack([c[:40] for c in held if len(c) >= 40][:3]).astype(np.float32)
    noisy = x + (0.01 * rng.normal(size=x.shape)).astype(np.float32)
    frames = np.zeros(x.shape[:2], bool)
    frames[0, 10:20] = frames[2, 30:] = True
    out = nf.denoise(noisy, frames)
    np.testing.assert_array_equal(out[~frames], noisy[~frames])
    assert _error(out[frames], x[frames]) < 0.8 * _error(noisy[frames], x[frames])
    np.testing.assert_array_equal(nf.denoise(noisy), nf.denoise(noisy, np.ones(x.shape[:2], bool)))
