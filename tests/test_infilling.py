"""The motion in-filler: linear interpolation when untrained, only gap frames change, and it learns to beat it."""
import numpy as np
import pytest

from refiner.core.signal import linear_infill
from refiner.nn.training import TrainSchedule
from refiner.refinement.infilling import GapBatches, MotionInfiller


def test_gap_batches_in_fill_linearly_and_keep_the_context(rng):
    clips = [np.cumsum(rng.normal(0, 0.01, (n, 24, 3)), 0) for n in (20, 50, 80)]
    b = GapBatches(clips, length=40, gap=(4, 10)).sample(np.arange(3), np.random.default_rng(0))
    gap, valid = b["gap"].numpy(), b["valid"].numpy()
    assert gap.any(1).all() and not (gap & ~valid).any() and valid.sum(1).tolist() == [20, 40, 40]
    given, clean = b["given"].numpy(), b["clean"].numpy()
    np.testing.assert_array_equal(given[~gap], clean[~gap])
    for k in range(3):
        m = int(valid[k].sum())
        np.testing.assert_allclose(given[k, :m], linear_infill(clean[k, :m], gap[k, :m]), atol=1e-6)


def test_unfitted_infiller_says_so():
    with pytest.raises(Exception, match="not fitted|fit"):
        MotionInfiller().infill(np.zeros((1, 20, 24, 3), np.float32), np.ones((1, 20), bool))


@pytest.mark.real_data
def test_infiller_learns_to_beat_linear_interpolation(humanact12, one_torch_thread, tmp_path):
    train = [m.joints for m in humanact12.motions[:600:2]]
    held = [m.joints[:60] for m in humanact12.motions[900:1100:10] if m.n_frames >= 60]
    est = MotionInfiller(hidden=48, n_layers=4, gap=(6, 16), window=40,  # 240 steps on 40-frame crops: 0.89 of linear
                         schedule=TrainSchedule(n_epochs=6, steps_per_epoch=40, batch_size=32, learning_rate=3e-3,
                                                patience=100),
                         random_state=0).fit(train, validation=held[:4])
    clean = np.stack(held).astype(np.float32)
    gap = np.zeros(clean.shape[:2], bool)
    gap[:, 20:32] = True
    out = est.infill(clean, gap)
    assert out.shape == clean.shape and out.dtype == np.float32
    np.testing.assert_array_equal(out[~gap], clean[~gap])  # the context comes back as given
    linear = np.stack([linear_infill(c, g) for c, g in zip(clean, gap)])
    before = np.linalg.norm(linear - clean, axis=-1)[gap].mean()
    after = np.linalg.norm(out - clean, axis=-1)[gap].mean()
    assert after < 0.9 * before, (before, after)
    for bad, match in ((clean[0], "B, T"), (np.full_like(clean, np.nan), "finite"), (clean, "gap")):
        with pytest.raises(ValueError, match=match):
            est.infill(bad, gap if bad is not clean else gap[:, :10])
    np.testing.assert_array_equal(est.infill(clean, np.ones_like(gap)), clean)  # nothing to in-fill from
    path = tmp_path / "infill.safetensors"
    est.save(path)
    np.testing.assert_allclose(MotionInfiller.load(path).infill(clean, gap), out, atol=1e-6)
