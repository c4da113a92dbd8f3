"""The noise residual: it corrects what the linear noise filter leaves of white noise on real held-out clips, changes
only the frames the filter denoises, survives int8 storage, must match its filter, refuses bad input, and trains."""
import numpy as np
import pytest
import torch

from refiner.core.rigid import rigid_skeleton
from refiner.core.validation import NotFittedError
from refiner.evaluation.flaws import corrupt
from refiner.nn.training import TrainSchedule
from refiner.refinement.noise_filter import NoiseFilter
from refiner.refinement.noise_residual import NoiseResidual, NoiseResidualNet, check_residual, residual_features
from refiner.refinement.pipeline import Refiner

_TINY = TrainSchedule(n_epochs=2, batch_size=64, steps_per_epoch=3, device="cpu")


def _error(y, x):
    return float(np.linalg.norm(np.asarray(y, np.float64) - x, axis=-1).mean())


def test_features_hold_the_window_the_move_and_the_level_and_an_untrained_net_corrects_nothing():
    x = torch.randn(2, 5, 3, 3) * 0.1
    move, level = torch.randn(2, 5, 3, 3) * 0.01, torch.full((2, 5), 0.01)
    f = residual_features(x, move, level, 1)
    assert f.shape == (2, 5, 3 * 9 + 9 + 1)
    np.testing.assert_allclose(f[..., 27:36].numpy(), 100 * move.reshape(2, 5, 9).numpy(), rtol=1e-5)
    np.testing.assert_allclose(f[..., -1].numpy(), 1.0)  # centimetres
    assert torch.count_nonzero(NoiseResidualNet(3, 1, 8)(f.reshape(10, -1))) == 0


@pytest.fixture(scope="module")
def tiny(humanact12):
    clips = [m.joints for m in humanact12.motions[:400:20]]
    nf = NoiseFilter(half_width=1, copies=1, rigid_tolerance=None).fit(clips)
    return NoiseResidual(hidden=8, copies=1, schedule=_TINY).fit(clips + [clips[0][:5]], nf), nf, clips


@pytest.mark.real_data
def test_tiny_training_corrects_only_the_denoised_frames_and_survives_int8(tiny, rng, tmp_path):
    residual, nf, clips = tiny
    assert residual.half_width_ == 1 and residual.skeleton_ == "humanact12" and len(residual.history_) == 2
    x = np.stack([c[:30] for c in clips[:3]]).astype(np.float32)
    noisy = x + (0.01 * rng.normal(size=x.shape)).astype(np.float32)
    frames = np.zeros(x.shape[:2], bool)
    frames[0, 5:15] = frames[2] = True
    out = nf.denoise(noisy, frames, residual=residual)
    np.testing.assert_array_equal(out[~frames], noisy[~frames])
    assert not np.array_equal(out[frames], nf.denoise(noisy, frames)[frames])
    residual.save(tmp_path / "r.safetensors", int8=True)
    again = NoiseResidual.load(tmp_path / "r.safetensors")
    np.testing.assert_allclose(nf.denoise(noisy, frames, residual=again), out, atol=2e-4)  # metres


@pytest.mark.real_data
def test_bad_input_unfitted_use_and_a_residual_of_another_filter_are_refused(tiny, humanact12):
    residual, nf, clips = tiny
    with pytest.raises(NotFittedError):
        NoiseResidual().correction(np.zeros((1, 8, 24, 3)), np.zeros((1, 8, 24, 3)), np.zeros((1, 8)))
    with pytest.raises(ValueError, match="must be"):
        residual.correction(np.zeros((1, 8, 20, 3)), np.zeros((1, 8, 20, 3)), np.zeros((1, 8)))
    with pytest.raises(ValueError, match="8 frames or more"):
        NoiseResidual(schedule=_TINY).fit([c[:5] for c in clips], nf)
    with pytest.raises(ValueError, match="min_level"):
        NoiseResidual(min_level=0.0, schedule=_TINY).fit(clips, nf)
    with pytest.raises(NotFittedError):
        NoiseResidual(schedule=_TINY).fit(clips, NoiseFilter())
    shipped = Refiner.pretrained("humanact12", split="train").noise_filter
    with pytest.raises(ValueError, match="half width"):
        check_residual(shipped, residual)  # trained behind a filter of 1 frame each side, not 3
    with pytest.raises(ValueError, match="give the filter"):
        check_residual(None, residual)
    assert check_residual(nf, residual) is residual and check_residual(shipped, None) is None


@pytest.mark.real_data
def test_shipped_residual_removes_more_jitter_than_the_filter_alone(humanact12, one_torch_thread):
    """The benchmark's jitter on held-out subjects 11-12, its true frames denoised after the rigid step, as the
    refiner's noise runs are: the filter leaves 0.60 cm, with the residual 0.56 cm (train-split weights)."""
    model = Refiner.pretrained("humanact12", split="train")
    nf, residual = model.noise_filter, model.noise_residual
    assert residual is not None and residual.half_width_ == nf.half_width
    alone, corrected = [], []
    for i, m in enumerate(humanact12.split("test").motions[::8]):
        c = corrupt(m, "transition_jitter", 2, random_state=i)
        x = rigid_skeleton(c.motion.joints, "humanact12", 0.005, keep_core=True, keep_shortened=True, spikes=True)[0][None]
        lin = nf.denoise(x, c.mask[None], capped=True)[0]
        out = nf.denoise(x, c.mask[None], capped=True, residual=residual)[0]
        np.testing.assert_array_equal(out[~c.mask], x[0][~c.mask])
        alone.append(_error(lin[c.mask], m.joints[c.mask]))
        corrected.append(_error(out[c.mask], m.joints[c.mask]))
    assert np.mean(corrected) < 0.95 * np.mean(alone), (np.mean(alone), np.mean(corrected))
    jittered = corrupt(humanact12[0], "transition_jitter", 2, random_state=0).motion  # one noise run the classifier sees
    out, report = model.refine(jittered, return_report=True)
    without = Refiner.pretrained("humanact12", split="train", noise_residual=None).refine(jittered)  # the release before
    run = next(c for c in report.changes if "noise-group" in c["reason"])
    inside = np.zeros(len(out.joints), bool)
    inside[run["start"] : run["stop"]] = True
    np.testing.assert_array_equal(out.joints[~inside], without.joints[~inside])
    assert _error(out.joints[inside], humanact12[0].joints[inside]) < _error(without.joints[inside], humanact12[0].joints[inside])
