import numpy as np
import pytest

from refiner.concepts.anchors import AnchorConcepts
from refiner.core.validation import NotFittedError


def _blobs(rng, n_actions=2, per=30):
    centres = rng.normal(size=(n_actions, 3, 24, 3))
    poses, actions = [], []
    for a in range(n_actions):
        for c in range(3):
            poses.append(centres[a, c] + 0.01 * rng.normal(size=(per, 24, 3)))
            actions += [a] * per
    poses = np.concatenate(poses)
    poses -= poses[:, :1]
    return poses, np.array(actions), centres - centres[:, :, :1]


def test_recovers_known_concepts(rng):
    poses, actions, centres = _blobs(rng)
    ac = AnchorConcepts(3, random_state=0).fit(poses + 5.0, actions)  # translation must not matter
    for a in range(2):
        d = np.linalg.norm(ac.centers_[a][:, None] - centres[a][None], axis=-1).mean(-1)
        assert d.min(0).max() < 0.01
    pred = ac.predict(poses, actions)
    assert len(set(zip(actions.tolist(), pred.tolist()))) == 6
    assert ac.distance(poses, actions).max() < 0.05


def test_fit_does_not_modify_input_and_save_roundtrip(rng, tmp_path):
    poses, actions, _ = _blobs(rng)
    before = poses.copy()
    ac = AnchorConcepts(3).fit(poses, actions)
    np.testing.assert_array_equal(poses, before)
    ac.save(tmp_path / "a.safetensors")
    back = AnchorConcepts.load(tmp_path / "a.safetensors")
    assert back.get_params() == ac.get_params()
    for x, y in zip(ac.centers_, back.centers_):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(back.predict(poses, actions), ac.predict(poses, actions))


def test_unfitted_and_bad_input(rng):
    with pytest.raises(NotFittedError):
        AnchorConcepts().predict(np.zeros((1, 24, 3)), [0])
    with pytest.raises(ValueError, match="n_clusters"):
        AnchorConcepts(0).fit(np.zeros((4, 24, 3)), [0, 0, 0, 0])
    with pytest.raises(ValueError, match="action 1 has no anchors"):
        AnchorConcepts(2).fit(rng.normal(size=(4, 24, 3)), [0, 0, 2, 2])
    ac = AnchorConcepts(2).fit(rng.normal(size=(4, 24, 3)), [0, 0, 1, 1])
    with pytest.raises(ValueError, match="actions"):
        ac.predict(np.zeros((1, 24, 3)), [5])
