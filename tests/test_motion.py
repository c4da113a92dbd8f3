import numpy as np
import pytest
import torch

from refiner import Motion, stack_motions, unstack_motions


def test_motion_copies_and_freezes(rng):
    x = rng.normal(size=(10, 24, 3))
    before = x.copy()
    m = Motion(x, action=3)
    assert m.joints.dtype == np.float32 and m.joints.shape == (10, 24, 3)
    x[0, 0, 0] = 99.0
    assert m.joints[0, 0, 0] == np.float32(before[0, 0, 0])
    with pytest.raises(ValueError):
        m.joints[0, 0, 0] = 1.0
    out = m.numpy()
    out[0] = 0
    assert m.joints[0, 0, 0] == np.float32(before[0, 0, 0])


def test_motion_torch_roundtrip(rng):
    t = torch.tensor(rng.normal(size=(5, 18, 3)), dtype=torch.float32)
    m = Motion(t, skeleton="uestc")
    assert torch.equal(m.torch(), t)
    assert m.n_joints == 18 and m.skeleton == "uestc"


def test_normalized_puts_first_root_at_origin(rng):
    x = rng.normal(size=(8, 24, 3)) + 5.0
    n = Motion(x).normalized()
    np.testing.assert_allclose(n.joints[0, 0], 0.0, atol=1e-6)
    np.testing.assert_allclose(n.joints - n.joints[:, :1], (x - x[:, :1]).astype(np.float32), atol=1e-5)


@pytest.mark.parametrize(
    "joints, kwargs, match",
    [
        (np.zeros((10, 22, 3)), {}, "J=24"),
        (np.zeros((10, 24)), {}, r"\(T, J, 3\)"),
        (np.zeros((1, 24, 3)), {}, "at least 2 frames"),
        (np.full((4, 24, 3), np.nan), {}, "NaN"),
        (np.zeros((4, 24, 3)), {"skeleton": "smpl99"}, "unknown skeleton"),
        (np.zeros((4, 24, 3)), {"fps": 0}, "fps"),
        (np.zeros((4, 24, 3)), {"action": -1}, "action"),
        ("abc", {}, "numeric|numbers|shape"),
    ],
)
def test_motion_rejects_bad_input(joints, kwargs, match):
    with pytest.raises(ValueError, match=match):
        Motion(joints, **kwargs)


def test_inf_reported_with_position():
    x = np.zeros((6, 24, 3))
    x[4, 2, 1] = np.inf
    with pytest.raises(ValueError, match="frame 4, joint 2"):
        Motion(x)


def test_stack_unstack(rng):
    ms = [Motion(rng.normal(size=(6, 24, 3)), action=i) for i in range(3)]
    batch = stack_motions(ms)
    assert batch.shape == (3, 6, 24, 3)
    back = unstack_motions(batch, actions=[0, 1, 2])
    assert all(a == b for a, b in zip(ms, back))
    with pytest.raises(ValueError, match="share one shape"):
        stack_motions([ms[0], Motion(rng.normal(size=(7, 24, 3)))])
