"""MoGenTS adapter: shares the HumanML3D path with MotionDiffuse; decoder pairs and *_data.npy features."""
from __future__ import annotations

import numpy as np
import pytest
from test_adapter_motiondiffuse import normalised_batch

from refiner.adapters import mogents, motiondiffuse


@pytest.mark.real_data
def test_same_conversion_as_motiondiffuse(humanact12, rng):
    clips, lengths, mean, std, truths = normalised_batch(humanact12, rng, indices=(20, 21))
    batch = np.stack(clips)  # (B, T, 263) as RVQVAE.forward_decoder returns
    ours = mogents.to_motions(batch, mean=mean, std=std, lengths=lengths)
    theirs = motiondiffuse.to_motions(clips, mean=mean, std=std, lengths=lengths)
    for a, b, truth in zip(ours, theirs, truths):
        np.testing.assert_array_equal(a.joints, b.joints)
        np.testing.assert_allclose(a.joints, truth, atol=1e-5)
    # the decoder's (x_out1d, x_out2d) pair: x_out2d is used, as in demo_mogen.py
    pair = mogents.to_motions((np.zeros_like(batch), batch), mean=mean, std=std, lengths=lengths)
    np.testing.assert_array_equal(pair[0].joints, ours[0].joints)
    # a demo *_data.npy file: de-normalised (L, 263)
    data = batch[0, : lengths[0]] * std + mean
    saved = mogents.to_motions(data, denormalized=True)[0]
    np.testing.assert_allclose(saved.joints, truths[0], atol=1e-5)


def test_plugin_registered_and_errors(pm, rng):
    info = pm.get_adapter("mogents")
    assert info.up == "+y" and info.skeletons[0] == "humanact12"
    feats = rng.normal(size=(2, 16, 263)) * 0.1
    motions = pm.convert("mogents", feats, skeleton="uestc", options={"mean": np.zeros(263), "std": np.ones(263)})
    assert [m.joints.shape for m in motions] == [(16, 18, 3)] * 2
    with pytest.raises(ValueError, match="`std` is needed"):
        pm.convert("mogents", feats, options={"mean": np.zeros(263)})
    with pytest.raises(ValueError, match=r"\(T, 263\) or \(B, T, 263\)"):
        pm.convert("mogents", rng.normal(size=(2, 16, 22, 3)), options={"denormalized": True})
