"""refine() inputs: float64, bfloat16, grad, sparse and meta tensors, unavailable devices, batch errors."""
from __future__ import annotations

import numpy as np
import pytest
import torch

import refiner
from refiner.nn.training import resolve_device
from refiner.refinement.motion_refiner import MotionRefiner
from refiner.refinement.pipeline import Refiner


@pytest.fixture(scope="module")
def forced():
    """The default refiner with every gate off: it flags every frame but the first and last (which anchor the in-fill)
    and keeps every change, whatever the weights, so a clip comes back with changed and unchanged frames."""
    return MotionRefiner.pretrained("humanact12", threshold=0.0, still_m=0.0, min_gain=-1.0, jerk_share=1e9,
                                    ground_tolerance_m=1e9, slide_pairs=1e9)


@pytest.fixture(scope="module")
def flawed(humanact12):
    """A real 60-frame clip in float64 that stalls on frames 25-36 with sub-float32 detail, and its action's name
    (so no test depends on inference)."""
    clip = humanact12[100]
    x = clip.crop(0, 60).joints.astype(np.float64)
    x = x + 1e-9 * np.arange(x.size).reshape(x.shape) / x.size  # lost when rounded through float32
    x[25:37] = x[25]
    return x, humanact12.action_names[clip.action]


def test_float64_comes_back_float64_with_unchanged_frames_bit_identical(flawed, forced):
    flawed_clip, action = flawed
    before = flawed_clip.copy()
    out, report = refiner.refine(flawed_clip, action=action, return_report=True)  # the shipped default
    assert out.dtype == np.float64 and out.shape == flawed_clip.shape
    np.testing.assert_array_equal(out[~report.changed_frames], flawed_clip[~report.changed_frames])
    out, report = refiner.refine(flawed_clip, action=action, return_report=True, refiner=forced)
    changed = report.changed_frames
    assert out.dtype == np.float64 and out.shape == flawed_clip.shape
    assert changed.any() and not changed.all()
    np.testing.assert_array_equal(out[~changed], flawed_clip[~changed])
    assert np.abs(out[changed] - flawed_clip[changed]).max() > 1e-4
    np.testing.assert_array_equal(flawed_clip, before)
    batch = refiner.refine(np.stack([flawed_clip, flawed_clip]), action=action, refiner=forced)
    assert batch.dtype == np.float64
    np.testing.assert_array_equal(batch[0][~changed], flawed_clip[~changed])
    np.testing.assert_allclose(batch[0], out, atol=1e-5)


def test_bfloat16_and_float64_tensors_keep_their_dtype(flawed, forced):
    flawed_clip, action = flawed
    for dtype in (torch.bfloat16, torch.float64):
        seq = torch.from_numpy(flawed_clip).to(dtype)
        out, report = refiner.refine(seq, action=action, return_report=True, refiner=forced)
        assert out.dtype == dtype and out.shape == seq.shape
        keep = torch.from_numpy(~report.changed_frames)
        assert torch.equal(out[keep], seq[keep]) and not torch.equal(out, seq)
        out = refiner.refine(seq, action=action)  # the shipped default
        assert out.dtype == dtype and out.shape == seq.shape


def test_requires_grad_tensor_comes_back_detached_with_a_warning(flawed):
    flawed_clip, action = flawed
    seq = torch.from_numpy(flawed_clip).float().requires_grad_(True)
    with pytest.warns(UserWarning, match="not differentiable.*detached"):
        out = refiner.refine(seq, action=action)
    assert not out.requires_grad and out.dtype == torch.float32
    assert seq.requires_grad  # the input is untouched


def test_sparse_and_meta_tensors_are_value_errors():
    with pytest.raises(ValueError, match="must be a dense tensor"):
        refiner.refine(torch.zeros(30, 24, 3).to_sparse())
    with pytest.raises(ValueError, match="'meta' device"):
        refiner.refine(torch.empty(30, 24, 3, device="meta"))


def test_unavailable_device_is_a_value_error(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(ValueError, match="CUDA is not available"):
        Refiner.pretrained("humanact12", device="cuda")
    with pytest.raises(ValueError, match="CUDA is not available"):
        resolve_device("cuda:0")
    with pytest.raises(ValueError, match="unknown `device` 'gpu0'"):
        resolve_device("gpu0")
    assert resolve_device("auto").type == "cpu"


def test_batch_errors_name_the_clip_for_every_kind(flawed):
    clip = flawed[0][:40]
    batch = np.stack([clip, clip, clip])
    for change, match in [
        (lambda b: b.__setitem__((1, 5, 3, 0), np.nan), "first at clip 1, frame 5, joint 3"),
        (lambda b: b.__setitem__(1, b[1] * 100), "clip 1 of 3: .*centimetres"),
        (lambda b: b.__setitem__((2, 5, 3, 0), 1e6), "clip 2 of 3: .*metres"),
    ]:
        bad = batch.copy()
        change(bad)
        with pytest.raises(ValueError, match=match):
            refiner.refine(bad)
    with pytest.raises(ValueError, match=r"J=24 .*got \(3, 40, 22, 3\)"):  # one joint count for the whole batch
        refiner.refine(batch[:, :, :22])


def test_report_names_the_quantity_its_threshold_applies_to():
    from refiner.refinement.pipeline import RefinementReport

    concepts = RefinementReport(mode="full", n_frames=3, threshold=-32.158, anchor_scores=[-10.0],
                                anchor_probability=[0.1, 0.9, 0.2]).to_dict()
    assert concepts["threshold_quantity"] == "anchor_scores" and list(concepts).index("threshold_quantity") == \
        list(concepts).index("threshold") + 1
    motion = RefinementReport(mode="full", n_frames=3, threshold=0.93, flaw_probability=[0.1, 0.2, 0.3])
    assert motion.to_dict()["threshold_quantity"] == "flaw_probability"
    assert RefinementReport(mode="full", n_frames=3).to_dict()["threshold_quantity"] is None


def test_thread_limits_hold_torch_and_blas_inside_and_restore_them():
    from threadpoolctl import threadpool_info

    from refiner.refinement.inputs import thread_limits

    torch_before = torch.get_num_threads()
    blas_before = {p["filepath"]: p["num_threads"] for p in threadpool_info()}
    with thread_limits(1):
        assert torch.get_num_threads() == 1
        inside = threadpool_info()
        assert inside and all(p["num_threads"] == 1 for p in inside)  # numpy / scipy / torch pools, one thread
    assert torch.get_num_threads() == torch_before
    assert {p["filepath"]: p["num_threads"] for p in threadpool_info()} == blas_before
    with thread_limits(None):  # untouched
        assert torch.get_num_threads() == torch_before
