"""The flaw denoiser: identity when untrained, only suspect frames change, and it learns to remove noise."""
import numpy as np
import pytest
import torch

from refiner.nn.training import TrainSchedule
from refiner.refinement.flaw_denoiser import FlawDenoiser, FlawDenoiserNet, denoiser_features


def test_untrained_network_is_the_identity_and_features_are_translation_invariant(rng):
    x = torch.from_numpy(rng.normal(size=(2, 30, 24, 3)).astype(np.float32))
    suspect = torch.ones(2, 30, dtype=torch.bool)
    torch.testing.assert_close(FlawDenoiserNet(24)(x, suspect), x)
    f = denoiser_features(x, suspect)
    assert f.shape == (2, 30, 9 * 24 + 4)
    torch.testing.assert_close(denoiser_features(x + torch.tensor([1.0, -2.0, 0.5]), suspect), f, atol=1e-3, rtol=1e-4)


def test_unfitted_denoiser_says_so():
    with pytest.raises(Exception, match="not fitted|fit"):
        FlawDenoiser().denoise(np.zeros((1, 20, 24, 3), np.float32), np.ones((1, 20), bool))


@pytest.mark.real_data
def test_denoiser_learns_to_remove_white_noise_from_suspect_frames_only(humanact12, one_torch_thread, tmp_path):
    train = [m.joints for m in humanact12.motions[:300:3]]
    held = [m.joints[:60] for m in humanact12.motions[900:1000:10] if m.n_frames >= 60]
    den = FlawDenoiser(hidden=48, n_layers=4, kinds=("white_noise",), rigid_tolerance=None,  # raw noise, as tested
                       window=40,  # 200 steps on crops of 32-40 frames: 0.71 of the noise's error
                       schedule=TrainSchedule(n_epochs=5, steps_per_epoch=40, batch_size=32, learning_rate=3e-3,
                                              patience=100),
                       random_state=0).fit(train, validation=held[:4])
    r = np.random.default_rng(3)
    clean = np.stack(held).astype(np.float32)
    suspect = np.zeros(clean.shape[:2], bool)
    suspect[:, 15:45] = True
    noisy = clean + (0.015 * r.normal(size=clean.shape) * suspect[..., None, None]).astype(np.float32)
    out = den.denoise(noisy, suspect)
    assert out.shape == noisy.shape and out.dtype == np.float32
    np.testing.assert_array_equal(out[~suspect], noisy[~suspect])  # frames nobody flagged come back as given
    before = np.linalg.norm(noisy - clean, axis=-1)[suspect].mean()
    after = np.linalg.norm(out - clean, axis=-1)[suspect].mean()
    assert after < 0.8 * before, (before, after)
    for bad, match in ((noisy[0], "B, T"), (noisy[..., :2], "B, T"), (np.full_like(noisy, np.nan), "finite")):
        with pytest.raises(ValueError, match=match):
            den.denoise(bad, suspect)
    with pytest.raises(ValueError, match="suspect"):
        den.denoise(noisy, suspect[:, :10])
    path = tmp_path / "den.safetensors"
    den.save(path)
    np.testing.assert_allclose(FlawDenoiser.load(path).denoise(noisy, suspect), out, atol=1e-6)
