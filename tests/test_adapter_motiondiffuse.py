"""MotionDiffuse adapter: normalised HumanML3D features (a list of padded clips) to canonical motions."""
from __future__ import annotations

import numpy as np
import pytest

from refiner.adapters import humanml3d as h3d
from refiner.adapters import motiondiffuse
from refiner.core.rotations import yup_to_ydown


def normalised_batch(humanact12, rng, indices=(5, 700)):
    """MotionDiffuse-style output: per clip (T_b, 263) normalised features padded to the longest, + truth."""
    mean = rng.normal(size=263)
    std = rng.uniform(0.5, 2.0, size=263)
    feats, truths = [], []
    for i in indices:
        j22 = yup_to_ydown(humanact12.motions[i].numpy())[:40, :22]
        f = h3d.joints_to_features(j22)
        feats.append((f - mean) / std)
        truths.append(h3d.to_humanact12(h3d.canonicalize_humanml3d(j22)[:-1]))
    lengths = [len(f) for f in feats]
    padded = np.zeros((len(feats), max(lengths), 263))
    for k, f in enumerate(feats):
        padded[k, : len(f)] = f
    return list(padded), lengths, mean, std, truths


@pytest.mark.real_data
def test_normalised_features_recover_known_joints(humanact12, rng):
    clips, lengths, mean, std, truths = normalised_batch(humanact12, rng)
    before = [c.copy() for c in clips]
    motions = motiondiffuse.to_motions(clips, mean=mean, std=std, lengths=lengths, actions=[1, 2])
    for m, truth, c, b in zip(motions, truths, clips, before):
        assert m.skeleton == "humanact12" and m.joints.shape == truth.shape
        np.testing.assert_allclose(m.joints, truth, atol=1e-5)
        np.testing.assert_array_equal(c, b)
    assert [m.action for m in motions] == [1, 2]
    # y down, frame-0 pelvis at the origin
    assert all((m.joints[:, 15, 1] < m.joints[:, 0, 1]).all() for m in motions)
    np.testing.assert_allclose(motions[0].joints[0, 0], 0.0, atol=1e-6)


@pytest.mark.real_data
def test_plugin_with_stats_as_files_and_uestc(pm, humanact12, rng, tmp_path):
    clips, lengths, mean, std, truths = normalised_batch(humanact12, rng)
    np.save(tmp_path / "mean.npy", mean)
    np.save(tmp_path / "std.npy", std)
    motions = pm.convert("motiondiffuse", clips, skeleton="uestc",
                         options={"mean": tmp_path / "mean.npy", "std": str(tmp_path / "std.npy"), "lengths": lengths})
    assert [m.skeleton for m in motions] == ["uestc", "uestc"] and motions[1].n_frames == lengths[1]
    # MotionDiffuse.generate returns torch tensors; a generator carrying mean/std supplies them
    import torch

    class Trainer:
        pass

    trainer = Trainer()
    trainer.mean, trainer.std = mean, std
    again = pm.convert("motiondiffuse", [torch.from_numpy(c) for c in clips], generator=trainer,
                       options={"lengths": lengths})
    np.testing.assert_allclose(again[0].joints, truths[0], atol=1e-5)


def test_missing_statistics_and_wrong_shapes(pm, rng):
    feats = [rng.normal(size=(30, 263))]
    with pytest.raises(ValueError, match="`mean` is needed.*meta/mean.npy"):
        pm.convert("motiondiffuse", feats, options={"std": np.ones(263)})
    with pytest.raises(ValueError, match=r"`output\[0\]` must have shape \(T, 263\)"):
        pm.convert("motiondiffuse", [rng.normal(size=(30, 251))], options={"denormalized": True})
    with pytest.raises(ValueError, match="unknown option.*'smpl_path'"):
        pm.convert("motiondiffuse", feats, options={"smpl_path": "x"})
