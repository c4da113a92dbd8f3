"""The learned-component contract (sklearn style) for every network component, plus their maths."""
import json
from pathlib import Path

import numpy as np
import pytest
from sklearn.mixture import GaussianMixture

from refiner.concepts.anchors import AnchorConcepts
from refiner.concepts.segmentation import segment
from refiner.concepts.transitions import TransitionGenerator, collect_transitions
from refiner.core.validation import NotFittedError
from refiner.nn.training import TrainSchedule
from refiner.refinement.anchor_quality import gmm_log_likelihood
from refiner.refinement.anchor_recognition import AnchorRecognizer, anchor_targets, match_anchors
from refiner.refinement.anchor_refinement import AnchorRefiner
from refiner.refinement.transition_refinement import TransitionRefiner, transition_layout

SCHEDULE = TrainSchedule(n_epochs=2, steps_per_epoch=1, batch_size=8, device="cpu")
TINY = dict(d_model=16, n_layers=1, n_heads=2, ffn_dim=16, schedule=SCHEDULE)


@pytest.fixture(scope="module")
def synthetic():
    r = np.random.default_rng(3)
    clips = [np.cumsum(r.normal(scale=0.02, size=(int(r.integers(30, 50)), 24, 3)), axis=0).astype(np.float32)
             for _ in range(10)]
    segs = [segment(c, penalty=20.0) for c in clips]
    actions = np.array([i % 2 for i in range(10)])
    poses = np.concatenate([c[s.anchors] for c, s in zip(clips, segs)])
    acts = np.concatenate([np.full(len(s.anchors), a) for s, a in zip(segs, actions)])
    concepts = AnchorConcepts(2).fit(poses, acts)
    return clips, segs, actions, concepts


def _fitted(name, data):
    clips, segs, actions, concepts = data
    anchors = [s.anchors for s in segs]
    if name == "recognizer":
        return AnchorRecognizer(crop_frames=20, **TINY).fit(clips, anchors, actions)
    if name == "anchor_refiner":
        return AnchorRefiner(crop_frames=20, **TINY).fit(clips, anchors, actions, concepts)
    if name == "transition_refiner":
        return TransitionRefiner(crop_frames=20, **TINY).fit(clips, anchors, [s.coeffs for s in segs])
    return TransitionGenerator(4, hidden=16, schedule=SCHEDULE).fit(
        collect_transitions(clips, segs, actions))


CLASSES = {"recognizer": AnchorRecognizer, "anchor_refiner": AnchorRefiner,
           "transition_refiner": TransitionRefiner, "transition_generator": TransitionGenerator}


@pytest.mark.parametrize("name", list(CLASSES))
def test_contract(name, synthetic, tmp_path):
    cls = CLASSES[name]
    fresh = cls()
    assert not [k for k in vars(fresh) if k.endswith("_")]
    assert cls(**fresh.get_params()).get_params() == fresh.get_params()
    with pytest.raises(NotFittedError):
        fresh.save(tmp_path / "x.safetensors")
    clips = synthetic[0]
    copies = [c.copy() for c in clips]
    model = _fitted(name, synthetic)
    for a, b in zip(clips, copies):
        np.testing.assert_array_equal(a, b)
    path = tmp_path / f"{name}.safetensors"
    model.save(path)
    back = cls.load(path)
    assert back.get_params() == model.get_params()
    for (k, v), (k2, v2) in zip(model.network_.state_dict().items(), back.network_.state_dict().items()):
        assert k == k2
        np.testing.assert_array_equal(v.numpy(), v2.numpy())
    other = [c for c in CLASSES.values() if c is not cls][0]
    with pytest.raises(ValueError, match="expected a"):
        other.load(path)


def test_outputs_survive_save_load(synthetic, tmp_path):
    clips, segs, actions, _ = synthetic
    rec = _fitted("recognizer", synthetic)
    rec.save(tmp_path / "r.safetensors")
    back = AnchorRecognizer.load(tmp_path / "r.safetensors")
    a, b = rec.recognize(clips[0]), back.recognize(clips[0])
    np.testing.assert_array_equal(a.anchors, b.anchors)
    np.testing.assert_allclose(a.scores, b.scores, rtol=1e-6)
    gen = _fitted("transition_generator", synthetic)
    t = collect_transitions(clips, segs, actions)
    frames = gen.generate(t.start[:4], t.end[:4], t.durations[:4])
    for f, s, e, d in zip(frames, t.start, t.end, t.durations):
        assert len(f) == d + 1
        np.testing.assert_allclose(f[0], s, atol=1e-6)  # starts exactly at the start anchor
        np.testing.assert_allclose(f[-1], e, atol=1e-6)  # and ends at the end anchor
    with pytest.raises(ValueError, match="durations"):
        gen.generate(t.start[:1], t.end[:1], [0])


def test_gmm_log_likelihood_matches_sklearn(rng):
    x = np.concatenate([rng.normal(size=(200, 5)), rng.normal(3, 0.5, size=(100, 5))])
    gmm = GaussianMixture(2, random_state=0).fit(x)
    np.testing.assert_allclose(gmm_log_likelihood(x, gmm.weights_, gmm.means_, gmm.covariances_),
                               gmm.score_samples(x), rtol=1e-8)


def test_anchor_targets_and_matching():
    t = anchor_targets(10, [0, 5, 9])
    assert t[5] == 1.0 and t[0] == 1.0 and abs(t[4] - np.exp(-0.5)) < 1e-6
    assert match_anchors([0, 6, 12], [0, 5, 9]) == (2, 3, 3)
    idx, tau, dur = transition_layout(10, [0, 4, 9])
    assert idx.tolist() == [0, 0, 0, 0, 1, 1, 1, 1, 1, 1]
    assert tau[4] == 0.0 and tau[9] == 1.0 and dur[0] == 4


def test_schedule_is_one_parameter_and_old_flat_files_fold_into_it(synthetic, tmp_path):
    """Every estimator takes its training settings as one ``schedule``; the shipped files, saved with the
    settings flat (``n_epochs``, ..., ``verbose``), load with them folded into it."""
    from safetensors import safe_open

    from refiner.nn.components import NetworkComponent

    weights = Path(__file__).resolve().parents[1] / "refiner" / "weights" / "humanact12"
    for cls in CLASSES.values():
        params = cls().get_params()
        assert isinstance(params["schedule"], TrainSchedule) and not {"n_epochs", "device", "verbose"} & set(params)
    from refiner.core.serialization import load_state, save_state

    tensors, metadata = load_state(weights / "recognizer.safetensors")
    params = json.loads(metadata["refiner.params"])
    schedule = params.pop("schedule")  # as the files were written before the schedule was one parameter:
    flat = {**params, **{k: v for k, v in schedule.items() if k != "progress"}, "verbose": schedule["progress"]}
    old = tmp_path / "flat_recognizer.safetensors"
    save_state(old, tensors, {**metadata, "refiner.params": json.dumps(flat)})
    with safe_open(str(old), "np") as f:
        assert "schedule" not in json.loads(f.metadata()["refiner.params"])
    loaded = AnchorRecognizer.load(old).schedule
    assert loaded == AnchorRecognizer.load(weights / "recognizer.safetensors").schedule
    assert (loaded.n_epochs, loaded.patience, loaded.max_seconds, loaded.progress) == (600, 40, 100.0, True)
    with pytest.raises(ValueError, match="`schedule` must be"):
        AnchorRecognizer(schedule={"n_epochs": 2}).fit(*_recognizer_data(synthetic))

    class Flat(NetworkComponent):  # an estimator that still declares the fields one by one
        def __init__(self, n_epochs=3, batch_size=4, learning_rate=1e-3, patience=2, steps_per_epoch=None,
                     max_seconds=None, device="cpu", verbose=True):
            self.n_epochs, self.batch_size, self.learning_rate, self.patience = n_epochs, batch_size, learning_rate, patience
            self.steps_per_epoch, self.max_seconds, self.device, self.verbose = steps_per_epoch, max_seconds, device, verbose

    assert Flat()._schedule() == TrainSchedule(3, 4, 1e-3, patience=2, device="cpu", progress=True)
    assert Flat._init_params({"n_epochs": 5}) == {"n_epochs": 5}  # its saved params stay as they are


def test_anchor_refiner_uses_the_validation_clips(synthetic):
    """``validation=`` held-out clips select the weights (it was silently ignored)."""
    clips, segs, actions, concepts = synthetic
    anchors = [s.anchors for s in segs]
    model = AnchorRefiner(crop_frames=20, **TINY).fit(clips[:7], anchors[:7], actions[:7], concepts,
                                                      validation=(clips[7:], anchors[7:], actions[7:]))
    assert all("val" in h for h in model.history_)
    with pytest.raises(ValueError, match="validation"):
        AnchorRefiner(crop_frames=20, **TINY).fit(clips, anchors, actions, concepts, validation=([], [], []))


def _recognizer_data(data):
    clips, segs, actions, _ = data
    return clips, [s.anchors for s in segs], actions


def test_transition_refiner_calibrate_sets_its_one_threshold(synthetic):
    model = _fitted("transition_refiner", synthetic)
    clips, anchors, _ = _recognizer_data(synthetic)
    loose, strict = model.calibrate(clips, anchors, percentile=50.0), model.calibrate(clips, anchors, percentile=1.0)
    assert strict == model.threshold_ and loose <= strict
    flagged = [r > strict for c, a in zip(clips, anchors) for r in model.refine_transitions(c, a)[1]]
    assert np.mean(flagged) < 0.1  # about 1 % of these real transitions are above it


def test_training_ends_on_the_best_or_the_last_weights(rng):
    """``keep_best``: the weights of the lowest validation loss, or the last epoch's."""
    import torch

    from refiner.nn.training import fit_network

    x = torch.from_numpy(rng.normal(size=(64, 3)).astype(np.float32))
    y = x @ torch.tensor([[1.0], [-2.0], [0.5]])

    def loss(net, batch, r):
        return torch.nn.functional.mse_loss(net(batch["x"]), batch["y"])

    def run(keep_best):
        torch.manual_seed(0)
        net = torch.nn.Linear(3, 1)
        # validation on the negated targets: the loss there grows as training fits the real ones
        history = fit_network(net, loss, lambda idx, r: {"x": x[idx], "y": y[idx]}, 64, {"x": x, "y": -y},
                              TrainSchedule(n_epochs=6, batch_size=16, learning_rate=0.05, patience=10,
                                            keep_best=keep_best, device="cpu"), np.random.default_rng(0))
        return net, history

    best, history = run(True)
    last, _ = run(False)
    vals = [h["val"] for h in history]
    assert int(np.argmin(vals)) < len(vals) - 1  # the last epoch is not the best one
    with torch.no_grad():
        assert float(loss(best, {"x": x, "y": -y}, None)) == pytest.approx(min(vals), rel=1e-5)
        assert float(loss(last, {"x": x, "y": -y}, None)) == pytest.approx(vals[-1], rel=1e-5)


def test_lower_triangles_pack_and_unpack(rng):
    from refiner.core.serialization import pack_lower, unpack_lower

    chol = np.tril(rng.normal(size=(3, 2, 5, 5)))
    packed = pack_lower(chol)
    assert packed.shape == (3, 2, 15)
    np.testing.assert_array_equal(unpack_lower(packed), chol)
    a = rng.normal(size=(4, 4))
    cov = a @ a.T
    np.testing.assert_array_equal(unpack_lower(pack_lower(cov), symmetric=True), cov)
    with pytest.raises(ValueError, match="not the lower triangle"):
        unpack_lower(np.zeros(7))
    with pytest.raises(ValueError, match="square"):
        pack_lower(np.zeros((5, 3)))


@pytest.mark.real_data
def test_shipped_anchor_quality_keeps_its_scores_in_half_the_bytes(humanact12, tmp_path):
    """The shipped file stores the covariances' lower triangles; a full-matrix file (the old layout) still loads."""
    from refiner.core.serialization import load_state, save_state
    from refiner.refinement.anchor_quality import AnchorQuality
    from refiner.refinement.pipeline import _WEIGHTS

    path = _WEIGHTS / "humanact12-train" / "anchor_quality.safetensors"
    tensors, metadata = load_state(path)
    assert "covariances.lower" in tensors and "covariances" not in tensors
    model = AnchorQuality.load(path)
    np.testing.assert_array_equal(model.covariances_, np.swapaxes(model.covariances_, -1, -2))
    full = {k: v for k, v in tensors.items() if k != "covariances.lower"}
    full["covariances"] = model.covariances_.astype(np.float32)
    save_state(tmp_path / "full.safetensors", full, metadata)
    old = AnchorQuality.load(tmp_path / "full.safetensors")
    poses = np.stack([humanact12[i].joints[10] for i in range(0, 1000, 100)])
    actions = np.array([humanact12[i].action for i in range(0, 1000, 100)])
    np.testing.assert_array_equal(old.score(poses, actions), model.score(poses, actions))
    assert (tmp_path / "full.safetensors").stat().st_size > 1.8 * path.stat().st_size


def test_int8_rows_quantize_within_half_a_step(rng):
    from refiner.core.serialization import dequantize_rows, quantize_rows

    a = rng.normal(size=(6, 4, 5)).astype(np.float32) * np.arange(1, 7)[:, None, None]
    a[2] = 0.0  # a dead unit keeps its zeros
    codes, scales = quantize_rows(a)
    assert codes.dtype == np.int8 and codes.shape == a.shape and scales.shape == (6,)
    back = dequantize_rows(codes, scales)
    step = np.abs(a).reshape(6, -1).max(1) / 127
    assert (np.abs(back - a).reshape(6, -1).max(1) <= step / 2 + 1e-7).all()
    np.testing.assert_array_equal(back[2], 0.0)
    with pytest.raises(ValueError, match="at least 2"):
        quantize_rows(np.ones(3))
    with pytest.raises(ValueError, match="finite"):
        quantize_rows(np.array([[1.0, np.nan]]))
    with pytest.raises(ValueError, match="one scale per row"):
        dequantize_rows(codes, scales[:3])


def test_int8_save_stores_large_matrices_as_codes_and_loads_close(synthetic, tmp_path):
    from refiner.core.serialization import load_state
    from refiner.nn.components import INT8_MIN_SIZE

    gen = _fitted("transition_generator", synthetic)
    gen.save(tmp_path / "f16.safetensors", half=True)
    gen.save(tmp_path / "i8.safetensors", int8=True)
    tensors, _ = load_state(tmp_path / "i8.safetensors")
    state = gen.network_.state_dict()
    big = [k for k, v in state.items() if v.ndim >= 2 and v.numel() >= INT8_MIN_SIZE]
    assert big and all(tensors[f"network.{k}.int8"].dtype == np.int8 for k in big)
    assert all(tensors[f"network.{k}"].dtype == np.float16 for k in state if k not in big)  # the rest as half
    back = TransitionGenerator.load(tmp_path / "i8.safetensors")
    for k, v in back.network_.state_dict().items():
        assert v.dtype == state[k].dtype
        ref, got = state[k].float().numpy(), v.float().numpy()
        if k in big:  # within half a step of the row's own scale: a scale shared by the tensor would fail here
            rows, refs = got.reshape(len(got), -1), ref.reshape(len(ref), -1)
            assert (np.abs(rows - refs).max(1) <= np.abs(refs).max(1) / 254 + 1e-7).all(), k
        else:
            np.testing.assert_allclose(got, ref, rtol=1e-3, atol=1e-4)
    assert (tmp_path / "i8.safetensors").stat().st_size < 0.75 * (tmp_path / "f16.safetensors").stat().st_size
    broken = {k: v for k, v in tensors.items() if not k.endswith(".int8_scale")}
    from refiner.core.serialization import save_state
    save_state(tmp_path / "broken.safetensors", broken, load_state(tmp_path / "i8.safetensors")[1])
    with pytest.raises(ValueError, match="without their scales"):
        TransitionGenerator.load(tmp_path / "broken.safetensors")


def test_int8_leaves_buffers_exact_and_refiner_save_checks_its_part_names(rng, tmp_path):
    import torch
    from torch import nn

    from refiner.nn.components import NetworkComponent

    class Tiny(NetworkComponent):
        def __init__(self, width: int = 64):
            self.width = width

        def fit(self):
            self.network_ = self._make_network({})
            return self

        def _make_network(self, fitted):
            net = nn.Linear(self.width, self.width)
            net.register_buffer("table", torch.zeros(self.width, self.width))
            return net

    model = Tiny().fit()
    model.network_.table.copy_(torch.from_numpy(rng.normal(size=(64, 64)).astype(np.float32)))
    model.save(tmp_path / "t.safetensors", int8=True)
    back = Tiny.load(tmp_path / "t.safetensors")
    np.testing.assert_array_equal(back.network_.table.numpy(), model.network_.table.half().float().numpy())
    assert not np.array_equal(back.network_.weight.detach().numpy(), model.network_.weight.detach().half().float().numpy())
    from refiner.refinement.pipeline import Refiner

    refiner = Refiner.pretrained("humanact12", split="train")
    for bad in ("transition", ["recognizer", "anchor_concepts"], True):
        with pytest.raises(ValueError, match="`int8` must name"):
            refiner.save(tmp_path / "r", int8=bad)
