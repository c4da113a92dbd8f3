"""The Action2Motion recogniser: weights, faithful preprocessing, hidden-state modes, real-data accuracy."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from refiner.evaluation.evaluators import (
    HUMANACT12_FINE_CODES,
    RECOGNIZERS,
    ActionRecognizer,
    RecognizerConfig,
    crop_clip,
    evaluators_dir,
    load_recognizer,
    load_recognizer_state,
)
from refiner.core.motion import Motion


def _evaluators():
    from conftest import shared_dir

    return shared_dir() / "evaluators"


@pytest.fixture(scope="module")
def rec():
    return load_recognizer("humanact12", hidden="fixed", directory=_evaluators())


def _tiny(hidden="random", random_state=0, n_frames=60):
    """An untrained recogniser on 24 joints with 12 classes (weights from torch's default init, seeded)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(0)
        return ActionRecognizer(RecognizerConfig(24, 12, n_frames=n_frames), hidden=hidden, random_state=random_state)


def test_evaluators_dir_is_beside_the_data():
    from refiner.io.datasets import default_data_dir

    assert evaluators_dir() == default_data_dir().parent / "evaluators"


@pytest.mark.real_data
def test_real_humanact12_crops_are_recognised_at_99_percent(humanact12):
    """Published figure: 99.9 % top-1 on real 60-frame crops, native frame, first-frame root subtracted."""
    rec = load_recognizer("humanact12", directory=_evaluators())  # faithful random hidden state
    pred = rec.predict(humanact12.motions, crop="random", random_state=0)
    acc = float(np.mean(pred == humanact12.actions))
    assert acc >= 0.99, acc


@pytest.mark.real_data
def test_fine_recogniser_uses_sorted_fine_codes(humanact12):
    rec = load_recognizer("humanact12_fine", hidden="fixed", directory=_evaluators())
    assert len(rec.config.class_names) == 34 and list(HUMANACT12_FINE_CODES) == sorted(set(humanact12.fine_codes))
    target = np.array([HUMANACT12_FINE_CODES.index(c) for c in humanact12.fine_codes])
    assert np.mean(rec.predict(humanact12.motions) == target) >= 0.98


@pytest.mark.real_data
def test_cmu_recogniser_scale_and_length():
    """93.6 % published; needs 100-frame crops and raw CMU units / 20 (our metres x 0.886)."""
    from conftest import shared_data_dir

    from refiner.io.datasets import load_cmu_mocap

    cmu = load_cmu_mocap(shared_data_dir() / "cmu_mocap" / "cmu_mocap_labeled_joints.npz")
    rec = load_recognizer("cmu_mocap", hidden="fixed", directory=_evaluators())
    assert rec.config.n_frames == 100
    assert np.mean(rec.predict(cmu.motions) == cmu.actions) >= 0.92


@pytest.mark.real_data
@pytest.mark.parametrize("name", list(RECOGNIZERS))
def test_tar_and_safetensors_give_identical_outputs(name, humanact12):
    config, st_file, tar_file = RECOGNIZERS[name]
    a = load_recognizer(_evaluators() / st_file, hidden="fixed")
    b = load_recognizer(_evaluators() / tar_file, hidden="fixed")
    assert a.config == b.config == config  # identified by weight shapes
    for key, value in a.state_dict().items():
        assert torch.equal(value, b.state_dict()[key]), key
    x = torch.from_numpy(np.random.default_rng(0).normal(size=(5, 60, config.n_joints * 3)).astype(np.float32))
    h0 = torch.randn(2, 5, 128, generator=torch.Generator().manual_seed(3))
    with torch.no_grad():
        fa, la = a(x, h0)
        fb, lb = b(x, h0)
    assert torch.equal(fa, fb) and torch.equal(la, lb)
    if name == "humanact12":
        clips = humanact12.motions[:40]
        np.testing.assert_array_equal(a.features(clips), b.features(clips))


def test_forward_shapes_and_feature_range():
    net = _tiny()
    x = torch.randn(3, 60, 72)
    feats, logits = net(x, torch.zeros(2, 3, 128))
    assert feats.shape == (3, 30) and logits.shape == (3, 12)
    assert feats.abs().max() < 1.0  # tanh
    torch.testing.assert_close(logits, net.linear2(feats))


def test_hidden_random_is_fresh_per_call_but_seeded():
    clips = np.random.default_rng(0).normal(size=(4, 4, 24, 3)).astype(np.float32) * 0.3
    a = _tiny("random", random_state=5, n_frames=4)  # short clips: the untrained GRU still remembers h0
    first, second = a.features(clips), a.features(clips)
    assert not np.allclose(first, second)  # a new N(0,1) draw every call, as Action2Motion
    b = _tiny("random", random_state=5, n_frames=4)
    np.testing.assert_array_equal(b.features(clips), first)  # same seed, same sequence of draws
    np.testing.assert_array_equal(b.features(clips), second)
    np.testing.assert_array_equal(a.features(clips, random_state=1), a.features(clips, random_state=1))
    a.reset()
    np.testing.assert_array_equal(a.features(clips), first)


def test_hidden_fixed_and_zeros_are_deterministic():
    clips = np.random.default_rng(1).normal(size=(6, 4, 24, 3)).astype(np.float32) * 0.3
    fixed = _tiny("fixed", random_state=2, n_frames=4)
    out = fixed.features(clips)
    np.testing.assert_array_equal(fixed.features(clips), out)
    # clip i gets the same noise whatever the batch size, and chunking changes nothing
    np.testing.assert_allclose(fixed.features(clips[:2]), out[:2], atol=1e-6)
    np.testing.assert_allclose(fixed.features(clips, batch_size=4), out, atol=1e-6)
    assert not np.allclose(out, _tiny("fixed", random_state=3, n_frames=4).features(clips))
    zeros = _tiny("zeros", n_frames=4)
    x = torch.from_numpy(clips - clips[:, :1, :1]).reshape(6, 4, 72)
    with torch.no_grad():
        expected = zeros(x, torch.zeros(2, 6, 128))[0].numpy()
    np.testing.assert_allclose(zeros.features(clips), expected, atol=1e-6)
    h = fixed.initial_hidden(3)
    assert h.shape == (2, 3, 128) and abs(float(h.std()) - 1.0) < 0.1
    assert torch.count_nonzero(zeros.initial_hidden(3)) == 0


def test_preprocessing_crops_pads_and_centres():
    net = _tiny("fixed")
    t = np.arange(30, dtype=np.float32)
    short = np.zeros((30, 24, 3), np.float32) + t[:, None, None] * 0.01 + 5.0  # far from the origin
    x = net.prepare([short])
    assert x.shape == (1, 60, 24, 3)
    np.testing.assert_allclose(x[0, 0, 0], 0.0)  # first-frame root at the origin
    np.testing.assert_allclose(x[0, 29:], np.broadcast_to(x[0, 29], (31, 24, 3)))  # padded with the last frame
    long = np.zeros((100, 24, 3), np.float32)
    long[:, 1:, 0] = np.arange(100, dtype=np.float32)[:, None]  # root still, other joints carry the frame index
    assert net.prepare(long[None], crop="start")[0, 0, 1, 0] == 0
    assert net.prepare(long[None], crop="center")[0, 0, 1, 0] == 20
    starts = [int(net.prepare([long], random_state=s)[0, 0, 1, 0]) for s in range(20)]
    assert all(0 <= s <= 40 for s in starts) and len(set(starts)) > 5
    assert starts == [int(net.prepare([long], random_state=s)[0, 0, 1, 0]) for s in range(20)]
    np.testing.assert_array_equal(crop_clip(long, 60, 70), long[40:100])  # start clipped to T - 60


def test_features_are_translation_invariant_and_inputs_untouched():
    net = _tiny("fixed")
    clip = np.random.default_rng(2).normal(size=(60, 24, 3)).astype(np.float32) * 0.2
    before = clip.copy()
    f = net.features(Motion(clip))
    np.testing.assert_allclose(net.features(Motion(clip + [1.0, -2.0, 3.0])), f, atol=1e-5)
    np.testing.assert_array_equal(clip, before)


def test_input_scale_is_applied():
    cfg = RecognizerConfig(20, 8, skeleton="cmu_mocap", n_frames=100, input_scale=2.0)
    net = ActionRecognizer(cfg, hidden="zeros")
    clip = np.random.default_rng(0).normal(size=(100, 20, 3)).astype(np.float32)
    x = net.prepare([Motion(clip, skeleton="cmu_mocap")])
    np.testing.assert_allclose(x[0], (clip - clip[:1, :1]) * 2.0, atol=1e-6)


def test_errors_are_clear(tmp_path):
    net = _tiny()
    with pytest.raises(ValueError, match="unknown recogniser"):
        load_recognizer("humanact13")
    with pytest.raises(ValueError, match="not found"):
        load_recognizer("humanact12", directory=tmp_path)
    with pytest.raises(ValueError, match="hidden"):
        ActionRecognizer(RecognizerConfig(24, 12), hidden="noise")
    with pytest.raises(ValueError, match="skeleton 'humanml3d'"):
        net.features([Motion(np.zeros((60, 22, 3)), skeleton="humanml3d")])
    with pytest.raises(ValueError, match="J=24"):
        net.features(np.zeros((2, 60, 22, 3)))
    with pytest.raises(ValueError, match="crop"):
        net.features(np.zeros((2, 60, 24, 3)), crop="middle")
    bad = tmp_path / "bad.tar"
    torch.save({"weights": torch.zeros(3)}, bad)
    with pytest.raises(ValueError, match="'model'"):
        load_recognizer_state(bad)
    odd = tmp_path / "odd.tar"
    state = {k: v for k, v in _tiny().state_dict().items()}
    state["linear2.weight"] = torch.zeros(5, 30)
    torch.save({"model": state}, odd)
    with pytest.raises(ValueError, match="matching no known recogniser"):
        load_recognizer(odd)
    other = tmp_path / "x.npz"
    other.write_bytes(b"")
    with pytest.raises(ValueError, match="unsupported"):
        load_recognizer_state(other)


def test_shipped_humanact12_recogniser_is_verified_with_licence_and_provenance():
    """The packaged copy carries its MIT licence and source in a sha256-checked manifest."""
    import json

    from refiner.core.manifest import content_sha256
    from refiner.evaluation.evaluator_weights import EVALUATOR_WEIGHTS_DIR, LICENCE_FILE, packaged_recognizer

    path = packaged_recognizer("humanact12")
    assert path == EVALUATOR_WEIGHTS_DIR / "humanact12_gru.safetensors"
    manifest = json.loads((EVALUATOR_WEIGHTS_DIR / "manifest.json").read_text())
    assert manifest["content_sha256"] == content_sha256(manifest)
    assert "MIT" in manifest["licence"] and "non-commercial" in manifest["licence"]
    assert manifest["source"]["repository"].endswith("EricGuo5513/action-to-motion")
    entry = manifest["evaluators"]["humanact12"]
    # sha256 of Action2Motion's original model_file/action_recognition_model_humanact12.tar
    assert entry["source_sha256"] == "e2d231fd8a425bc642d4c342466d5eaae2ae16e8a67e8dd253820ef5512d7bca"
    assert "MIT License" in (EVALUATOR_WEIGHTS_DIR / LICENCE_FILE).read_text()
    assert packaged_recognizer("ntu13") is None


def test_shipped_recogniser_copy_is_refused_when_edited(tmp_path):
    import shutil

    from refiner.evaluation.evaluator_weights import EVALUATOR_WEIGHTS_DIR, packaged_recognizer

    folder = tmp_path / "evaluators"
    shutil.copytree(EVALUATOR_WEIGHTS_DIR, folder)
    licence = folder / "LICENSE-action-to-motion.txt"
    licence.write_text(licence.read_text().replace("MIT", "GPL"))
    with pytest.raises(ValueError, match="does not match the sha256"):
        packaged_recognizer("humanact12", folder=folder)
    shutil.copy(EVALUATOR_WEIGHTS_DIR / licence.name, licence)
    (folder / "humanact12_gru.safetensors").unlink()
    with pytest.raises(ValueError, match="missing"):
        packaged_recognizer("humanact12", folder=folder)


@pytest.mark.real_data
def test_shipped_recogniser_gives_the_logits_of_the_shared_original(humanact12):
    """Same tensors as Action2Motion's .tar in ../shared: identical logits on real clips."""
    from refiner.evaluation.evaluator_weights import packaged_recognizer

    shipped = load_recognizer("humanact12", hidden="fixed")  # no directory: the shipped copy
    assert load_recognizer_state(packaged_recognizer("humanact12")).keys() == shipped.state_dict().keys()
    original = load_recognizer(_evaluators() / "action_recognition_model_humanact12.tar", hidden="fixed")
    clips = humanact12.motions[:16]
    np.testing.assert_array_equal(shipped.predict_logits(clips, crop="start"),
                                  original.predict_logits(clips, crop="start"))
    for a, b in zip(shipped.state_dict().values(), original.state_dict().values()):
        assert torch.equal(a, b)


def test_missing_recogniser_message_names_env_files_and_source(tmp_path, monkeypatch):
    monkeypatch.setenv("MOTION_REFINER_DATA", str(tmp_path / "data"))
    with pytest.raises(ValueError) as err:
        load_recognizer("ntu13")
    msg = str(err.value)
    for part in ("$MOTION_REFINER_DATA", "ntu13_vibe_gru.safetensors", "action_recognition_model_vibe_v2.tar",
                 "github.com/EricGuo5513/action-to-motion", str(tmp_path / "evaluators")):
        assert part in msg, part
