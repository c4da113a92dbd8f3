"""MLD adapter: the (B, T, 150) feature-major layout is ACTOR's tensor, and converts like it."""
from __future__ import annotations

import numpy as np
import pytest
from test_adapter_actor import random_actor_output, smpl_dir  # noqa: F401  (fixture)

from refiner.adapters import actor, mld


def mld_features_by_formula(output):
    """§4: for a 150-vector v, joint j's 6D is v[j], v[25+j], ..., v[125+j] (translation at j = 24)."""
    b, _, _, t = output.shape
    feats = np.zeros((b, t, 150), dtype=np.float32)
    for j in range(25):
        for k in range(6):
            feats[:, :, 25 * k + j] = output[:, j, k, :]
    return feats


def test_layout_matches_actor_after_reshaping(rng):
    out, _ = random_actor_output(rng, batch=3, frames=7)
    feats = mld_features_by_formula(out)
    np.testing.assert_array_equal(mld.features_to_actor(feats), out)
    np.testing.assert_array_equal(mld.actor_to_features(out), feats)
    np.testing.assert_array_equal(feats[0, 2, [24, 49, 74]], out[0, 24, :3, 2])  # translation slots
    single = mld.features_to_actor(feats[1])
    np.testing.assert_array_equal(single[0], out[1])


def test_converts_like_actor(smpl_dir, rng):  # noqa: F811
    out, _ = random_actor_output(rng, batch=2, frames=9)
    feats = mld_features_by_formula(out)
    before = feats.copy()
    via_mld = mld.to_motions(feats, smpl_path=smpl_dir, lengths=[9, 5], actions=[0, 11])
    via_actor = actor.to_motions(out, smpl_path=smpl_dir, lengths=[9, 5])
    np.testing.assert_array_equal(feats, before)
    assert [m.n_frames for m in via_mld] == [9, 5] and [m.action for m in via_mld] == [0, 11]
    for a, b in zip(via_mld, via_actor):
        np.testing.assert_allclose(a.joints, b.joints, atol=1e-6)


def test_plugin_and_errors(pm, smpl_dir, rng, monkeypatch):  # noqa: F811
    out, _ = random_actor_output(rng, batch=1, frames=6)
    feats = mld.actor_to_features(out)
    motions = pm.convert("mld", feats, skeleton="uestc", options={"smpl_path": smpl_dir})
    assert motions[0].skeleton == "uestc" and motions[0].joints.shape == (6, 18, 3)
    with pytest.raises(ValueError, match=r"\(B, T, 150\)"):
        mld.features_to_actor(np.zeros((2, 60, 263)))
    with pytest.raises(ValueError, match="cannot produce skeleton 'humanml3d'"):
        pm.convert("mld", feats, skeleton="humanml3d")
    monkeypatch.delenv(actor.SMPL_ENV, raising=False)
    with pytest.raises(ValueError, match="MOTION_REFINER_SMPL"):
        pm.convert("mld", feats)
    with pytest.raises(ValueError, match="not a file"):
        mld.to_motions(feats, smpl_path=smpl_dir / "missing.pkl")
