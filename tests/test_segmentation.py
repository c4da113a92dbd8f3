import numpy as np
import pytest

from refiner.concepts.segmentation import _segment_naive, fit_costs, segment
from refiner.concepts.splines import eval_spline, fit_spline


@pytest.mark.parametrize("seed", range(6))
def test_dp_matches_brute_force(seed):
    """Same optimum (cost and cut points) as enumerating every cut set with np.polyfit."""
    r = np.random.default_rng(seed)
    x = np.cumsum(r.normal(size=(13, 3, 3)) * 0.05, axis=0)
    penalty = float(r.uniform(1.0, 20.0))
    seg = segment(x, penalty=penalty)
    anchors, cost = _segment_naive(x, penalty=penalty)
    np.testing.assert_array_equal(seg.anchors, anchors)
    assert seg.cost == pytest.approx(cost, rel=1e-6)


def test_fit_costs_match_polyfit(rng):
    x = np.cumsum(rng.normal(size=(30, 4, 3)) * 0.03, axis=0)
    costs = fit_costs(x)
    for k, n in [(0, 3), (0, 29), (5, 17), (10, 25)]:
        t = np.arange(n - k + 1)
        _, res, *_ = np.polyfit(t, x[k : n + 1].reshape(n - k + 1, -1) * 100, 3, full=True)
        expected = res.sum() / 4 if res.size else 0.0
        assert costs[k, n] == pytest.approx(expected, rel=1e-6, abs=1e-8)
    assert np.isinf(costs[0, 2]) and np.isinf(costs[5, 4])


def test_more_penalty_never_more_transitions(humanact12):
    for m in humanact12.motions[::97]:
        counts = [segment(m.joints, penalty=lam).n_transitions for lam in (10, 100, 200, 400, 2000)]
        assert counts == sorted(counts, reverse=True), counts


def test_infinite_penalty_gives_one_transition(tiny_clip):
    seg = segment(tiny_clip, penalty=np.inf)
    assert seg.anchors.tolist() == [0, len(tiny_clip) - 1]


def test_finds_known_junction(tiny_clip):
    seg = segment(tiny_clip, penalty=1.0)
    assert seg.anchors.tolist() == [0, 20, 40]
    assert seg.fit_cost < 1e-6
    np.testing.assert_allclose(seg.reconstruct(), tiny_clip, atol=1e-5)


@pytest.mark.real_data
def test_reconstruction_within_reported_error(humanact12):
    """The splines reproduce each clip within its fit cost: MPJPE^2 <= cost / frames (Jensen)."""
    for m in humanact12.motions[::60]:
        seg = segment(m.joints)
        err_cm = 100 * np.linalg.norm(seg.reconstruct() - m.joints, axis=-1)
        assert err_cm.mean() < 3.0
        # per-frame mean squared error of the reconstruction is bounded by the DP's fit cost
        # (anchor frames come from one of two fits, each at most the optimum at that frame sum)
        assert (err_cm**2).mean(1).sum() <= seg.fit_cost * 1.0001 + 1e-6


def test_splines_roundtrip(rng):
    coeffs = rng.normal(size=(4, 24, 3)).astype(np.float32)
    frames = eval_spline(coeffs, 17)
    np.testing.assert_allclose(fit_spline(frames), coeffs, atol=1e-4)
    import torch

    np.testing.assert_allclose(eval_spline(torch.tensor(coeffs), 17).numpy(), frames, atol=1e-5)


def test_segment_rejects_bad_input():
    x = np.zeros((10, 24, 3))
    before = x.copy()
    segment(x)
    np.testing.assert_array_equal(x, before)
    with pytest.raises(ValueError, match="at least 4 frames"):
        segment(np.zeros((3, 24, 3)))
    with pytest.raises(ValueError, match="NaN"):
        segment(np.full((10, 24, 3), np.nan))
    with pytest.raises(ValueError, match="penalty"):
        segment(x, penalty=-1)
    with pytest.raises(ValueError, match="penalty"):
        segment(x, penalty="big")
    with pytest.raises(ValueError, match="min_duration"):
        segment(x, min_duration=0)
