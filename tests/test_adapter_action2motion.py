"""Action2Motion adapter: Lie FK/IK round trips, the real shipped samples, the recogniser's verdict."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_dir

from refiner.adapters import action2motion as a2m
from refiner.adapters.lie_kinematics import LIE_KINEMATICS, reference_bone_lengths
from refiner.core.motion import Motion
from refiner.core.skeletons import get_skeleton

SAMPLES = shared_dir() / "samples" / "action2motion"
EVALUATORS = shared_dir() / "evaluators"


def _bone_lengths(joints, skeleton):
    parents = np.array(get_skeleton(skeleton).parents)
    return np.linalg.norm(joints[..., 1:, :] - joints[..., parents[1:], :], axis=-1)


def _samples(name):
    path = SAMPLES / f"{name}_samples.npy"
    if not path.is_file():
        pytest.fail(f"Action2Motion samples not found at {path}; set MOTION_REFINER_DATA.")
    return np.load(path), np.load(SAMPLES / f"{name}_labels.npy")


@pytest.mark.real_data
def test_lie_ik_then_fk_reproduces_real_humanact12_joints(humanact12):
    """IK then FK with the clip's own first frame as bone-length reference gives the clip back (1e-5 m)."""
    for i in (0, 300, 1100):
        clip = humanact12.motions[i].numpy()
        before = clip.copy()
        lie = a2m.joints_to_lie(clip)
        assert lie.shape == (len(clip), 72)
        back = a2m.lie_to_joints(lie, reference=clip[0], recenter=False)
        assert np.abs(back - clip).max() < 1e-5
        np.testing.assert_array_equal(clip, before)  # input untouched
        # the Lie parameters stay in Action2Motion's tanh*pi range
        assert np.abs(lie[:, 3:]).max() <= np.pi + 1e-6


@pytest.mark.real_data
def test_from_motions_is_the_inverse_of_to_motions(humanact12):
    """Encoding real clips (Lie, plain or continuous over time, and xyz) and decoding them gives them back."""
    motions = [humanact12.motions[i] for i in range(0, 1191, 40)]
    jumps = {}
    for continuous in (False, True):
        lies = a2m.from_motions(motions, continuous=continuous)
        for m, lie in zip(motions, lies):
            assert lie.shape == (m.n_frames, 72) and lie.dtype == np.float32
            back = a2m.to_motions(lie, representation="lie", reference=m.joints[0], recenter=False)[0]
            assert np.abs(back.joints - m.joints).max() < 1e-4
        jumps[continuous] = sum(int((np.abs(np.diff(lie[:, 3:], axis=0)) > 1.0).sum()) for lie in lies)
    assert jumps[True] < 0.3 * jumps[False]  # steps over 1 rad: mostly gone
    xyz = a2m.from_motions(motions[:1], representation="xyz")[0]
    np.testing.assert_array_equal(a2m.to_motions(xyz, representation="xyz")[0].joints, motions[0].joints)
    with pytest.raises(ValueError, match="`representation` must be 'lie' or 'xyz'"):
        a2m.from_motions(motions[:1], representation="rot6d")


def test_lie_round_trip_on_ntu_layout(rng):
    """FK of random Lie parameters, then IK -> FK again, on the 18-joint NTU-VIBE layout."""
    lie = np.concatenate([rng.normal(size=(30, 3)) * 0.1, rng.uniform(-1.0, 1.0, size=(30, 51))], axis=1)
    joints = a2m.lie_to_joints(lie, dataset="ntu13", recenter=False)
    assert joints.shape == (30, 18, 3)
    back = a2m.lie_to_joints(a2m.joints_to_lie(joints, dataset="ntu13"), reference=joints[0], dataset="uestc",
                             recenter=False)
    assert np.abs(back - joints).max() < 1e-5


def test_fk_uses_identity_per_chain_and_reference_lengths():
    """A rotation of spine3 must not move the arms (arm chains restart at the identity, §2.2)."""
    lie = np.zeros((2, 72))
    lie[1, 3 * 9 : 3 * 9 + 3] = [0.0, 0.0, 1.2]  # spine3 (joint 9) rotated in frame 1
    ref = np.asarray(a2m.lie_to_joints(np.zeros((1, 72)), recenter=False)[0]) * 1.3  # 1.3x longer bones
    j = a2m.lie_to_joints(lie, reference=ref, recenter=False)
    arms = [13, 14, 16, 17, 18, 19, 20, 21, 22, 23]
    np.testing.assert_allclose(j[1, arms] - j[1, 9], j[0, arms] - j[0, 9], atol=1e-6)
    assert np.abs(j[1, 12] - j[0, 12]).max() > 0.05  # but the neck follows spine3
    np.testing.assert_allclose(_bone_lengths(j, "humanact12"), 1.3 * np.tile(LIE_KINEMATICS["humanact12"].default_bone_lengths[1:], (2, 1)),
                               atol=1e-6)


@pytest.mark.real_data
def test_decoded_lie_samples_are_plausible_bodies():
    lie, _ = _samples("humanact12_lie_vae")
    joints = a2m.lie_to_joints(lie)
    assert joints.shape == (20, 60, 24, 3)
    np.testing.assert_allclose(joints[:, 0, 0], 0.0, atol=1e-6)  # frame-0 root at the origin
    lengths = _bone_lengths(joints, "humanact12")
    assert lengths.std(axis=(0, 1)).max() < 1e-5  # constant bones ...
    np.testing.assert_allclose(lengths[0, 0], LIE_KINEMATICS["humanact12"].default_bone_lengths[1:], atol=1e-5)
    # ... and upright in the y-down camera frame: head above (smaller y than) the pelvis in every frame
    head_up = joints[..., 0, 1] - joints[..., 15, 1]
    assert (head_up > 0.2).all()
    assert (joints[..., 7, 1] > joints[..., 0, 1]).mean() > 0.99  # ankles below the pelvis
    # per-sample reference poses from real frames set each sample's bone lengths
    refs = np.stack([a2m.lie_to_joints(np.zeros((1, 72)), recenter=False)[0] * s for s in np.linspace(0.9, 1.1, 20)])
    scaled = a2m.lie_to_joints(lie, reference=refs)
    np.testing.assert_allclose(_bone_lengths(scaled, "humanact12")[:, 0], reference_bone_lengths(refs, LIE_KINEMATICS["humanact12"])[:, 1:],
                               atol=1e-5)


@pytest.mark.real_data
def test_xyz_samples_convert_unchanged():
    xyz, labels = _samples("humanact12_xyz_vae")
    motions = a2m.to_motions(xyz, representation="xyz", actions=labels)
    assert len(motions) == 20
    for m, raw, label in zip(motions, xyz, labels):
        assert m.skeleton == "humanact12" and m.action == label and m.fps == 20.0
        np.testing.assert_array_equal(m.joints, raw.reshape(60, 24, 3))
    ntu, _ = _samples("ntu13_xyz_vae")
    ntu_motions = a2m.to_motions(ntu, representation="xyz")
    assert ntu_motions[0].skeleton == "uestc"
    np.testing.assert_array_equal(ntu_motions[3].joints, ntu[3].reshape(60, 18, 3))
    # a saved keypoint file (60, J, 3) is xyz without saying so; recentring is opt-in
    single = a2m.to_motions(xyz[0].reshape(60, 24, 3), recenter=True)[0]
    np.testing.assert_allclose(single.joints, xyz[0].reshape(60, 24, 3) - xyz[0, 0, :3], atol=1e-6)


def _recognizer_accuracy(joints, labels, seeds=(0, 1, 2, 3, 4)):
    """Mean accuracy of the HumanAct12 GRU recogniser over several random initial hidden states."""
    try:
        from refiner.evaluation.evaluators import load_recognizer
    except ImportError:
        return _local_recognizer_accuracy(joints, labels, seeds)
    rec = load_recognizer("humanact12", directory=EVALUATORS)
    motions = [Motion(j, skeleton="humanact12") for j in joints]
    return float(np.mean([(rec.predict(motions, crop="start", random_state=s) == labels).mean() for s in seeds]))


def _local_recognizer_accuracy(joints, labels, seeds):
    """Fallback when refiner.evaluation.evaluators is not there: the §8.2 network written out here."""
    import torch
    from safetensors.torch import load_file

    class GRURecognizer(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.recurrent = torch.nn.GRU(72, 128, 2)
            self.linear1 = torch.nn.Linear(128, 30)
            self.linear2 = torch.nn.Linear(30, 12)

        def forward(self, x, h0):
            out, _ = self.recurrent(x.transpose(0, 1), h0)
            return self.linear2(torch.tanh(self.linear1(out[-1])))

    net = GRURecognizer()
    net.load_state_dict(load_file(str(EVALUATORS / "humanact12_gru.safetensors")))
    x = np.asarray(joints, dtype=np.float32)
    x = torch.from_numpy((x - x[:, :1, :1]).reshape(len(x), x.shape[1], -1))
    accs = []
    with torch.no_grad():
        for s in seeds:
            h0 = torch.randn(2, len(x), 128, generator=torch.Generator().manual_seed(s))
            accs.append((net(x, h0).argmax(1).numpy() == labels).mean())
    return float(np.mean(accs))


@pytest.mark.real_data
def test_recognizer_scores_xyz_samples_as_documented():
    """75 % on the shipped xyz samples in the native frame (data README), near chance after a y-flip."""
    xyz, labels = _samples("humanact12_xyz_vae")
    joints = np.stack([m.joints for m in a2m.to_motions(xyz, representation="xyz")])
    acc = _recognizer_accuracy(joints, labels)
    assert 0.70 <= acc <= 0.82, acc
    flipped = joints * np.array([1.0, -1.0, -1.0], dtype=np.float32)
    assert _recognizer_accuracy(flipped, labels) < 0.35


def test_wrong_input_raises_clear_errors():
    with pytest.raises(ValueError, match="representation"):
        a2m.to_motions(np.zeros((2, 60, 72)))
    with pytest.raises(ValueError, match=r"\(T, 72\) or \(N, T, 72\).*54 values per frame is ntu13"):
        a2m.lie_to_joints(np.zeros((2, 60, 54)))
    with pytest.raises(ValueError, match="`lie` must have shape"):
        a2m.lie_to_joints(np.zeros((2, 60, 70)))
    with pytest.raises(ValueError, match="unknown `dataset` 'smpl'"):
        a2m.lie_to_joints(np.zeros((60, 72)), dataset="smpl")
    with pytest.raises(ValueError, match="zero-length bone"):
        a2m.lie_to_joints(np.zeros((60, 72)), reference=np.zeros((24, 3)))
    with pytest.raises(ValueError, match="one pose per sample"):
        a2m.lie_to_joints(np.zeros((3, 60, 72)), reference=np.ones((2, 24, 3)))
    with pytest.raises(ValueError, match="`xyz` must have shape"):
        a2m.xyz_to_joints(np.zeros((60, 22, 3)))
    with pytest.raises(ValueError, match="NaN"):
        a2m.to_motions(np.full((60, 72), np.nan), representation="lie")
    with pytest.raises(ValueError, match="`actions` must have one entry per clip"):
        a2m.to_motions(np.zeros((2, 60, 72)), representation="xyz", actions=[1])


def test_plugin_registered_and_converts(pm):
    info = pm.get_adapter("action2motion")
    assert info.skeletons == ("humanact12", "uestc") and info.up == "-y" and info.source == "built-in"
    raw = np.random.default_rng(0).normal(size=(3, 60, 54)).astype(np.float32) * 0.3
    before = raw.copy()
    motions = pm.convert("action2motion", raw, options={"representation": "lie"})
    assert [m.skeleton for m in motions] == ["uestc"] * 3
    np.testing.assert_array_equal(raw, before)
    with pytest.raises(ValueError, match="unknown option.*'mean'.*accepted: representation"):
        pm.convert("action2motion", raw, options={"mean": 0})
