"""The timing estimator: random re-timings, undoing known offsets, learning to find them, its place in the refiner."""
import numpy as np
import pytest

from refiner.core.signal import resample
from refiner.core.validation import NotFittedError
from refiner.nn.training import TrainSchedule
from refiner.refinement.timing_estimation import TimingEstimator, random_retiming, retime_by_offsets


def test_random_retimings_are_monotone_windows(rng):
    for _ in range(200):
        s = random_retiming(64, rng)
        assert s.shape == (64,) and (np.diff(s) >= -1e-12).all() and s[0] >= 0 and s[-1] <= 63
        moved = np.flatnonzero(np.abs(s - np.arange(64)) > 1e-9)
        if moved.size:  # one window, its ends in place
            assert moved.max() - moved.min() <= 40


@pytest.mark.real_data
def test_known_offsets_are_undone_and_nothing_else_moves(humanact12, rng):
    clip = humanact12[30].joints.astype(np.float64)[:64]
    errors = []
    for _ in range(10):
        s = random_retiming(len(clip), rng)
        flawed = resample(clip, s)
        out, runs = retime_by_offsets(flawed, s - np.arange(len(clip)), 0.5, widen=2)
        err = lambda y: np.linalg.norm(y - clip, axis=-1).mean()  # noqa: E731
        errors.append((err(flawed), err(out)))
        inside = np.zeros(len(clip), bool)
        for lo, hi in runs:
            inside[lo:hi] = True
        np.testing.assert_array_equal(out[~inside], flawed[~inside])
    before, after = np.mean(errors, 0)
    assert after < 0.3 * before, (before, after)
    same, runs = retime_by_offsets(clip, np.zeros(len(clip)), 0.5)
    assert runs == [] and np.array_equal(same, clip)


@pytest.mark.real_data
def test_estimator_learns_where_frames_belong(humanact12, one_torch_thread, tmp_path):
    train = [m.joints for m in humanact12.motions[:900:3]]
    est = TimingEstimator(hidden=32, negatives=0.0, turn=False, schedule=TrainSchedule(  # turned crops learn slower
        n_epochs=10, steps_per_epoch=40, batch_size=24, learning_rate=3e-3, patience=100), random_state=0).fit(train)
    assert est.history_[-1]["val"] < 0.85 * est.history_[0]["val"]  # 400 steps: it has begun to learn
    rng = np.random.default_rng(5)
    held = [m.joints[:64] for m in humanact12.motions[900:1190:6] if m.n_frames >= 64][:24]
    truth = np.stack([random_retiming(64, rng) - np.arange(64) for _ in held])
    flawed = np.stack([resample(c.astype(np.float64), d + np.arange(64)) for c, d in zip(held, truth)]).astype(np.float32)
    pred = est.offsets(flawed)
    assert pred.shape == truth.shape and pred.dtype == np.float32
    # better than "nothing is re-timed" (0.95 after these 400 steps; the shipped one, 8,000 steps: see the README)
    assert np.abs(pred - truth).mean() < 0.97 * np.abs(truth).mean()
    assert est.calibrate([m.joints for m in humanact12.motions[1100:1190:9]], clip_rate=0.1) > 0
    assert est.agreed_threshold_ >= est.threshold_  # AGREED_CLIP_RATE (2.5 %) of the clips, not 10 %: no lower
    path = tmp_path / "timing.safetensors"
    est.save(path)
    np.testing.assert_allclose(TimingEstimator.load(path).offsets(flawed), pred, atol=1e-5)
    for bad, match in ((flawed[0], "B, T"), (np.full_like(flawed, np.nan), "finite")):
        with pytest.raises(ValueError, match=match):
            est.offsets(bad)
    before = flawed.copy()
    est.retime(flawed)
    np.testing.assert_array_equal(flawed, before)  # the input is never modified


def test_unfitted_estimator_says_so():
    with pytest.raises(NotFittedError):
        TimingEstimator().offsets(np.zeros((1, 20, 24, 3), np.float32))
    with pytest.raises(ValueError, match="at least 8 frames"):
        TimingEstimator().fit([np.zeros((5, 24, 3))])
    with pytest.raises(ValueError, match="needs clean clips"):
        TimingEstimator().calibrate([])


def test_run_ends_stay_and_short_clips_find_their_runs():
    """A run's last frame is kept even when estimated source times pile up on it; runs on clips shorter
    than the widening land where the offsets are; offsets of another length are refused."""
    x = np.arange(30, dtype=np.float64)[:, None, None] * np.ones((1, 2, 3))  # one joint pair moving 1 per frame
    d = np.zeros(30)
    d[10:16], d[16:19] = [1, 2, 3, 4, 4, 3], [2, 2, 1]
    out, runs = retime_by_offsets(x, d, 3.0, widen=3)
    assert runs == [(9, 20)] and out[19, 0, 0] == 19 and np.array_equal(out[20:], x[20:])
    for n, expected in ((5, (1, 5)), (6, (2, 6)), (12, (8, 12))):
        d = np.zeros(n)
        d[-1] = 5.0
        assert retime_by_offsets(x[:n], d, 1.0, widen=3)[1] == [expected]
    with pytest.raises(ValueError, match="one value per frame"):
        retime_by_offsets(x, np.zeros(29), 1.0)
    d = np.zeros(30)
    d[10:16] = [1, 2, 3, 4, 4, 3]
    jumps = np.zeros(29, bool)
    jumps[25] = True  # a jump outside the run: re-timed as before
    assert retime_by_offsets(x, d, 3.0, widen=3, jumps=jumps)[1] == [(9, 20)]
    jumps[14] = True  # inside it: re-sampling would spread the jump, so the run is left as given
    out, runs = retime_by_offsets(x, d, 3.0, widen=3, jumps=jumps)
    assert runs == [] and np.array_equal(out, x)


def test_the_smoothed_view_keeps_shape_and_slow_motion_and_drops_noise(rng):
    from refiner.refinement.timing_estimation import smoothed_in_time

    t = np.linspace(0, 1, 60, dtype=np.float32)
    slow = 0.3 * np.stack([np.sin(np.pi * t)] * 3, -1)[:, None].repeat(4, 1)  # (60, 4, 3) metres
    noisy = (slow + rng.normal(0, 0.01, slow.shape)).astype(np.float32)
    assert smoothed_in_time(noisy, 0.0) is noisy  # sigma 0: the clip as given
    out = smoothed_in_time(noisy[None], 1.5)[0]  # batches smooth along their time axis
    assert out.shape == noisy.shape and out.dtype == np.float32
    assert np.abs(out - slow).mean() < 0.6 * np.abs(noisy - slow).mean()
    assert np.abs(out - slow).max() < 0.7 * np.abs(noisy - slow).max()


@pytest.mark.real_data
def test_turned_training_crops_keep_bones_and_heights(humanact12):
    """Crops turned about the vertical (``turn``): the same poses, bones and heights, facing elsewhere."""
    from refiner.core.skeletons import bone_lengths
    from refiner.refinement.timing_estimation import _RetimedCrops

    clips = [m.joints for m in humanact12.motions[:40] if m.n_frames >= 64][:8]
    plain = _RetimedCrops(clips, 64, 0.0, 0.0, "humanact12")  # not re-timed: the same crops, one of them turned
    turned = _RetimedCrops(clips, 64, 0.0, 0.0, "humanact12", turn=True)
    (x, dx), (y, dy) = [zip(*(c._crop(clip, np.random.default_rng(i)) for i, clip in enumerate(clips)))
                        for c in (plain, turned)]  # one seed per clip: the same crop start in both
    x, y = np.stack(x), np.stack(y)
    assert not np.any(dx) and not np.any(dy)
    np.testing.assert_allclose(bone_lengths(y, "humanact12"), bone_lengths(x, "humanact12"), atol=1e-5)
    np.testing.assert_allclose(y[..., 1], x[..., 1], atol=1e-5)  # y is the vertical: heights stay
    assert np.abs(y[..., [0, 2]] - x[..., [0, 2]]).mean() > 0.01  # they face elsewhere


@pytest.mark.real_data
def test_a_clip_is_retimed_the_same_alone_or_in_a_batch(humanact12):
    """Batched and single convolutions differ in the last bits; a clip near or past the threshold is estimated alone."""
    from refiner.evaluation.flaws import time_warp
    from refiner.refinement.pipeline import Refiner

    est = Refiner.pretrained("humanact12", split="train").timing_estimator
    clips = [m for m in humanact12.split("test").motions if m.n_frames >= 60][:48]
    batch = np.stack([time_warp(m, 3, random_state=i).motion.joints[:60] for i, m in enumerate(clips)]).astype(np.float32)
    out, runs = est.retime(batch)
    assert sum(map(len, runs)) >= 5  # the shipped estimator re-times warped clips
    for b in range(len(batch)):
        alone, alone_runs = est.retime(batch[b : b + 1])
        assert alone_runs[0] == runs[b]
        np.testing.assert_array_equal(alone[0], out[b])


def test_a_run_the_flaw_classifier_does_not_read_as_timing_is_not_retimed(humanact12):
    """The flaw classifier's second opinion (``timing_agreement``): a clean clip of a calibration subject whose estimated
    offsets pass the threshold over frames 51-69 (its timing-group probability there stays under 0.3; re-timed, they
    move 10.3 cm on average) keeps them; a generator's clips (``GENERATOR_OPTIONS``: every run) have them re-timed."""
    from refiner.refinement.inputs import GENERATOR_OPTIONS
    from refiner.refinement.pipeline import Refiner

    train = humanact12.split("train")
    clip = [m for m, s in zip(train.motions, train.subjects) if s in (9, 10)][::2][3]

    def retimed(**options):
        out, report = Refiner.pretrained("humanact12", split="train", **options).refine(clip, return_report=True)
        return out, [c for c in report.changes if c.get("repair") == "estimated_retime"]

    out, runs = retimed()  # (frames 75-81 pass the lower threshold the agreement allows, and the classifier agrees)
    assert not any(r["start"] <= 51 and r["stop"] >= 69 for r in runs)
    np.testing.assert_array_equal(out.joints[:70], clip.joints[:70])
    for options in ({"timing_agreement": None}, {**GENERATOR_OPTIONS, "amplitude": "keep", "texture": "off"}):
        out, runs = retimed(**options)
        assert len(runs) == 1 and runs[0]["start"] <= 51 and runs[0]["stop"] >= 69
        assert np.abs(out.joints - clip.joints)[51:69].max() > 0.005
    for bad in (1.5, -0.1, True):
        with pytest.raises(ValueError, match="timing_agreement"):
            Refiner.pretrained("humanact12", split="train", timing_agreement=bad)


def test_with_the_classifiers_agreement_runs_pass_at_the_agreed_threshold(humanact12):
    """With the classifier's agreement, runs are re-timed past the manifest's lower threshold (2.5 % of clean clips, not
    1 %): a held-out time warp whose offsets peak between the two is re-timed there and not without the agreement."""
    from refiner.evaluation.flaws import time_warp
    from refiner.refinement.pipeline import Refiner
    from refiner.refinement.timing_estimation import AGREED_KEY

    model = Refiner.pretrained("humanact12", split="train")
    agreed, alone = model.manifest["learned"][AGREED_KEY], model.timing_estimator.threshold_
    assert 0 < agreed < alone
    clip = [c for c in humanact12.split("test").motions if c.n_frames >= 60][58]
    bad = time_warp(clip, 2, random_state=58).motion
    assert agreed < np.abs(model.timing_estimator.retiming_offsets(bad.joints[None])[0]).max() < alone

    def runs(**options):
        _, report = Refiner.pretrained("humanact12", split="train", **options).refine(bad, return_report=True)
        return [c for c in report.changes if c.get("repair") == "estimated_retime"]

    assert len(runs()) == 1 and f"(threshold {agreed:.1f})" in runs()[0]["reason"]
    assert runs(timing_agreement=None) == []
