"""Amplitude restoration: real clips read as about 1, damped ones as damped; restoring brings them back toward
the true clip, leaves clips above the gate exactly as given, survives saving, refuses bad input."""
import numpy as np
import pytest

from refiner.core.contact import contact_joints, heights, on_ground_as
from refiner.core.validation import NotFittedError
from refiner.refinement.amplitude import LENGTHS, AmplitudeRestorer, joint_spread
from refiner.refinement.pipeline import Refiner


def _damped(x, k):
    rel = x - x[:, :1]
    mean = rel.mean(0, keepdims=True)
    return x[:, :1] + mean + k * (rel - mean)


@pytest.fixture(scope="module")
def fitted(humanact12):
    fit = np.flatnonzero(humanact12.subjects <= 8)[::2]
    held = np.flatnonzero(humanact12.subjects >= 9)[::3]
    est = AmplitudeRestorer().fit([humanact12[i].joints for i in fit], humanact12.actions[fit], n_actions=12)
    return est, [humanact12[i] for i in held]


def test_joint_spread_is_scale_free_and_zero_at_the_root(rng):
    x = np.cumsum(rng.normal(0, 0.01, (40, 24, 3)), 0)
    s = joint_spread(x, "humanact12")
    assert s.shape == (24,) and s[0] == 0 and (s[1:] > 0).all()
    np.testing.assert_allclose(joint_spread(3.0 * x + 1.0, "humanact12"), s, rtol=1e-9)


@pytest.mark.real_data
def test_damped_clips_are_found_and_restored(fitted):
    est, held = fitted
    assert est.spread_.shape == (12, len(LENGTHS), 24) and np.isfinite(est.spread_).all()
    gate, target = est.calibrate([m.joints for m in held], [m.action for m in held], clip_rate=0.05)
    assert 0.3 < gate < 0.9 < target < 1.2
    clean = [est.amplitude(m.joints[:60], m.action) for m in held]
    damped = [est.amplitude(_damped(m.joints[:60].astype(np.float64), 0.3), m.action) for m in held]
    assert 0.8 < np.median(clean) < 1.25 and np.median(damped) < 0.4
    assert np.mean(np.array(damped) < gate) > 0.8 and np.mean(np.array(clean) < gate) < 0.1
    before, after, kept = [], [], 0
    long = [m for m in held if m.n_frames >= LENGTHS[0]]  # shorter ones are never scaled (below)
    for m in long:
        x = m.joints[:60].astype(np.float64)
        y = _damped(x, 0.3)
        out, k, s = est.restore(y, m.action)
        if s == 1.0:
            np.testing.assert_array_equal(out, y)
            kept += 1
            continue
        assert s > 1.0 and k < gate
        before.append(np.linalg.norm(y - x, axis=-1).mean()), after.append(np.linalg.norm(out - x, axis=-1).mean())
    assert kept < 0.2 * len(long) and np.mean(after) < 0.6 * np.mean(before), (np.mean(before), np.mean(after))
    for m in [m for m in held if m.n_frames >= 16]:  # under 32 frames a clip spreads less than any fitted length: never scaled
        y = _damped(m.joints[:16].astype(np.float64), 0.2)
        out, k, s = est.restore(y, m.action)
        assert s == 1.0 and np.array_equal(out, y)
    assert est.scale(1e-6) == est.max_scale == 10.0 and est.scale(est.gate_) == 1.0


@pytest.mark.real_data
def test_saved_restorer_is_the_same_and_bad_input_is_refused(fitted, tmp_path):
    est, held = fitted
    est.calibrate([m.joints for m in held], [m.action for m in held], clip_rate=0.05)
    est.save(tmp_path / "a.safetensors")
    again = AmplitudeRestorer.load(tmp_path / "a.safetensors")
    x = held[3].joints
    assert again.amplitude(x, 2) == pytest.approx(est.amplitude(x, 2), rel=1e-5) and again.gate_ == est.gate_
    a, b = [m.joints[:40] for m in held if m.n_frames >= 40][:2]  # a batch in one pass is each clip alone
    np.testing.assert_allclose(est.amplitudes(np.stack([a, b]), [2, 3]), [est.amplitude(a, 2), est.amplitude(b, 3)],
                               rtol=1e-12)
    with pytest.raises(NotFittedError):
        AmplitudeRestorer().amplitude(x, 0)
    for bad, match in (((x[:1], 0), "T >= 2"), ((x[:, :20], 0), "24, 3"), ((x, 12), "12 actions"), ((x, None), "12 actions"),
                       ((x, "1"), "12 actions"), ((x, 1.7), "12 actions"), ((x, True), "12 actions")):
        with pytest.raises(ValueError, match=match):
            est.amplitude(*bad)
    with pytest.raises(ValueError, match="one int action each"):
        AmplitudeRestorer().fit([x], [0, 1])
    with pytest.raises(ValueError, match="32 frames"):
        AmplitudeRestorer().fit([x[:20]], [0])
    with pytest.raises(ValueError, match="actions must be in 0..1"):
        AmplitudeRestorer().fit([x, x], [0, 2], n_actions=2)


@pytest.mark.real_data
def test_shipped_refiner_restores_a_damped_clip_and_keeps_a_real_one(humanact12, one_torch_thread):
    """On for a generator's clips (GENERATOR_OPTIONS), off in refine(), which may be given a calm real person."""
    from refiner.refinement.inputs import GENERATOR_OPTIONS

    assert Refiner.pretrained("humanact12", split="train").amplitude == "keep"
    model = Refiner.pretrained("humanact12", split="train", **GENERATOR_OPTIONS)
    assert model.amplitude_restorer is not None and model.amplitude == "restore"
    est = model.amplitude_restorer
    m = next(humanact12[i] for i in np.flatnonzero(humanact12.subjects == 11)  # a clip that moves as real ones do
             if humanact12[i].n_frames >= 60 and 0.9 < est.amplitude(humanact12[i].joints[:60], humanact12[i].action) < 1.2)
    x = m.joints[:60].astype(np.float64)
    damped = on_ground_as(_damped(x, 0.15), x, "humanact12")  # as a generator damps: the feet still meet the ground
    out, report = model.refine(damped.astype(np.float32), action=m.action, return_report=True)
    assert any(c["step"] == "amplitude" for c in report.changes)
    err = lambda a: np.linalg.norm(a - x, axis=-1).mean()  # noqa: E731
    assert err(out) < 0.5 * err(damped), (err(out), err(damped))
    lift = lambda a: heights(a[:, list(contact_joints("humanact12"))], "humanact12").min(-1)  # noqa: E731
    off = lambda a: np.abs(lift(a) - lift(x)).mean()  # noqa: E731
    assert off(out) < 0.5 * off(_damped(x, 0.15)), (off(out), off(_damped(x, 0.15)))  # feet where they met the ground
    _, report = model.refine(x.astype(np.float32), action=m.action, return_report=True)
    assert not any(c["step"] == "amplitude" for c in report.changes)
    _, report = model.refine(_damped(x, 0.15).astype(np.float32), return_report=True)  # no action given: not judged
    assert not any(c["step"] == "amplitude" for c in report.changes)
    kept = Refiner.pretrained("humanact12", split="train")
    _, report = kept.refine(_damped(x, 0.15).astype(np.float32), action=m.action, return_report=True)
    assert not any(c["step"] == "amplitude" for c in report.changes)
