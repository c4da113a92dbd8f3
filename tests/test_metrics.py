"""FID, A-FID, accuracy, diversity, multimodality, MPJPE and the replicated protocol."""
from __future__ import annotations

import numpy as np
import pytest

from refiner.evaluation import metrics
from refiner.evaluation.metrics import (
    accuracy,
    action_fid,
    confidence_interval,
    confusion_matrix,
    diversity,
    fid,
    frechet_distance,
    mpjpe,
    multimodality,
)
from refiner.evaluation.protocol import evaluate


def test_frechet_distance_of_known_gaussians():
    # commuting (diagonal) covariances: tr(S1 + S2 - 2 sqrt(S1 S2)) = sum (sqrt a - sqrt b)^2
    a, b = np.array([1.0, 4.0, 9.0]), np.array([4.0, 1.0, 9.0])
    mu1, mu2 = np.zeros(3), np.array([1.0, 2.0, 0.0])
    expected = 5.0 + np.sum((np.sqrt(a) - np.sqrt(b)) ** 2)
    assert frechet_distance(mu1, np.diag(a), mu2, np.diag(b)) == pytest.approx(expected, abs=1e-9)
    assert frechet_distance(mu1, np.diag(a), mu1, np.diag(a)) == pytest.approx(0.0, abs=1e-9)


def test_fid_uses_sample_mean_and_unbiased_covariance(rng):
    x = rng.normal(size=(400, 5))
    y = rng.normal(size=(300, 5)) * 2.0 + 1.0
    expected = frechet_distance(x.mean(0), np.cov(x, rowvar=False), y.mean(0), np.cov(y, rowvar=False))
    assert fid(x, y) == pytest.approx(expected)
    assert fid(x, x) == pytest.approx(0.0, abs=1e-8)
    assert fid(x, x + [3.0, 0, 0, 0, 0]) == pytest.approx(9.0, abs=1e-8)  # a shift adds its squared length
    assert fid(x, y) == pytest.approx(fid(y, x), rel=1e-6)


def test_fid_retries_with_epsilon_when_sqrtm_is_not_finite(monkeypatch):
    real_sqrtm = metrics.scipy.linalg.sqrtm
    calls = []

    def flaky(m):
        calls.append(m.copy())
        return np.full_like(m, np.nan) if len(calls) == 1 else real_sqrtm(m)

    monkeypatch.setattr(metrics.scipy.linalg, "sqrtm", flaky)
    s = np.diag([1.0, 2.0])
    value = frechet_distance(np.zeros(2), s, np.zeros(2), s)
    assert len(calls) == 2
    np.testing.assert_allclose(calls[1], (s + 1e-6 * np.eye(2)) @ (s + 1e-6 * np.eye(2)))
    assert value == pytest.approx(0.0, abs=1e-5)


@pytest.mark.parametrize("imag, ok", [(1e-4, True), (1e-2, False)])
def test_fid_imaginary_part_rule(monkeypatch, imag, ok):
    monkeypatch.setattr(metrics.scipy.linalg, "sqrtm", lambda m: np.eye(2) * (1.0 + 1j * imag))
    s = np.eye(2)
    if ok:
        assert frechet_distance(np.zeros(2), s, np.zeros(2), s) == pytest.approx(0.0)
    else:
        with pytest.raises(ValueError, match="imaginary"):
            frechet_distance(np.zeros(2), s, np.zeros(2), s)


def test_action_fid_per_action(rng):
    f = rng.normal(size=(600, 4))
    y = np.repeat([0, 1, 2], 200)
    real = f.copy()
    real[y == 1] += [2.0, 0, 0, 0]
    out = action_fid(f, y, real, y, n_per_action=None)
    assert set(out) == {0, 1, 2}
    assert out[0] == pytest.approx(0.0, abs=1e-8) and out[1] == pytest.approx(4.0, abs=1e-6)
    sub = action_fid(f, y, real, y, n_per_action=50, random_state=0)
    assert sub == action_fid(f, y, real, y, n_per_action=50, random_state=0)
    assert set(action_fid(f, y, real[:400], y[:400])) == {0, 1}  # action 2 absent on the real side


def test_accuracy_and_confusion():
    logits = np.array([[2.0, 1.0], [0.0, 3.0], [5.0, 1.0], [0.0, 1.0]])
    labels = np.array([0, 1, 1, 1])
    assert accuracy(logits, labels) == 0.75
    assert accuracy(logits.argmax(1), labels) == 0.75
    cm = confusion_matrix(logits.argmax(1), labels, 2)
    np.testing.assert_array_equal(cm, [[1, 0], [1, 2]])
    assert np.trace(cm) / cm.sum() == 0.75
    with pytest.raises(ValueError, match="shape"):
        accuracy(logits, labels[:3])


def test_diversity_follows_the_action2motion_sampler(rng):
    f = rng.normal(size=(50, 30))
    r = np.random.default_rng(7)
    first, second = r.integers(0, 50, 200), r.integers(0, 50, 200)
    expected = np.linalg.norm(f[first] - f[second], axis=1).mean()
    assert diversity(f, random_state=7) == pytest.approx(expected)
    assert diversity(np.ones((10, 3))) == 0.0
    # two points at distance 2, pairs with replacement: half the pairs differ -> about 1
    two = np.array([[0.0, 0.0], [2.0, 0.0]])
    assert diversity(two, n_pairs=20000, random_state=0) == pytest.approx(1.0, abs=0.03)


def test_multimodality_within_labels():
    # label 0: all one point (contributes 0); label 1: two points 2 apart, j drawn within the label
    # (j may equal i) -> expected distance 1; overall mean over both labels -> 0.5
    f = np.array([[0.0, 0.0]] * 6 + [[0.0, 0.0], [2.0, 0.0]])
    y = np.array([0] * 6 + [1, 1])
    assert multimodality(f, y, n_per_label=4000, random_state=0) == pytest.approx(0.5, abs=0.03)
    assert multimodality(f, y, random_state=3) == multimodality(f, y, random_state=3)
    # a label seen once pairs with itself
    assert multimodality(np.array([[0.0], [1.0], [5.0]]), np.array([0, 0, 1]), n_per_label=3000,
                         random_state=0) == pytest.approx(0.25, abs=0.03)


def test_mpjpe_and_confidence_interval():
    a = np.zeros((10, 24, 3))
    b = a + [0.0, 0.03, 0.04]
    assert mpjpe(a, b) == pytest.approx(0.05)
    mask = np.zeros(10, bool)
    mask[:3] = True
    b[3:] = 0.0
    assert mpjpe(a, b, mask=mask) == pytest.approx(0.05)
    assert mpjpe(a, b) == pytest.approx(0.015)
    mean, half = confidence_interval([1.0, 2.0, 3.0, 4.0])
    assert mean == 2.5 and half == pytest.approx(1.96 * np.sqrt(1.25) / 2.0)  # population std
    with pytest.raises(ValueError, match="shape"):
        mpjpe(a, b[:5])


def test_inputs_are_validated_and_not_modified(rng):
    f = rng.normal(size=(20, 3))
    before = f.copy()
    fid(f, f)
    diversity(f)
    multimodality(f, np.arange(20) % 2)
    np.testing.assert_array_equal(f, before)
    with pytest.raises(ValueError, match="at least 2"):
        fid(f[:1], f)
    with pytest.raises(ValueError, match="share D"):
        fid(f, f[:, :2])
    with pytest.raises(ValueError, match="NaN"):
        fid(np.full((3, 3), np.nan), f)
    with pytest.raises(ValueError, match="integer"):
        multimodality(f, np.linspace(0, 1, 20))


@pytest.mark.real_data
def test_evaluate_replicates_the_protocol(humanact12):
    from conftest import shared_dir

    from refiner.evaluation.evaluators import load_recognizer

    rec = load_recognizer("humanact12", directory=shared_dir() / "evaluators")
    test = humanact12.split("test").motions
    train = humanact12.split("train").motions
    ev = evaluate(rec, test, train, n_replications=3, n_generated=300, n_real=300, match_labels=True,
                  a_fid=True, random_state=0)
    assert ev.n_replications == 3 and all(len(v) == 3 for k, v in ev.values.items() if ":" not in k)
    assert ev.mean("accuracy") >= 0.98 and ev.mean("real_accuracy") >= 0.98
    assert 0.0 < ev.mean("fid") < 2.0
    assert 5.0 < ev.mean("diversity") < 9.0 and 1.0 < ev.mean("multimodality") < 4.0
    assert ev.interval("fid") == pytest.approx(1.96 * ev.values["fid"].std() / np.sqrt(3))
    again = evaluate(rec, test, train, n_replications=3, n_generated=300, n_real=300, match_labels=True,
                     a_fid=True, random_state=0)
    np.testing.assert_array_equal(again.values["fid"], ev.values["fid"])
    # motionless clips (each frozen at its first frame) are far from real motion
    frozen = [m.with_joints(np.repeat(m.joints[:1], len(m), axis=0)) for m in test]
    worse = evaluate(rec, frozen, train, n_replications=3, n_generated=300, n_real=300, match_labels=True)
    assert worse.mean("fid") > ev.mean("fid") + 3.0 and worse.mean("accuracy") < 0.7
    calls = []
    evaluate(rec, lambda r: calls.append(1) or test[:40], train, n_replications=2)
    assert calls == [1, 1]
