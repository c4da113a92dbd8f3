"""The pose prior: turns with the body, leaves frames under its threshold exactly as given, refuses bad input,
survives saving, and, shipped, takes drifted joints of held-out subjects back toward real poses while leaving
clean clips alone; as the refiner's last step it reports what it changed and keeps to the mode."""
import copy

import numpy as np
import pytest
import torch

from refiner.core.validation import NotFittedError
from refiner.evaluation.flaws import corrupt
from refiner.nn.training import TrainSchedule
from refiner.refinement.pipeline import Refiner
from refiner.refinement.pose_prior import PosePrior, body_frame, drifting_skeleton

TINY = TrainSchedule(n_epochs=1, steps_per_epoch=2, batch_size=4, device="cpu")


def _error(y, x):
    return float(np.linalg.norm(np.asarray(y, np.float64) - x, axis=-1).mean())


def _shipped(folder):
    from pathlib import Path

    import refiner

    return Path(refiner.__file__).parent / "weights" / folder / "pose_prior.safetensors"


def _turned(x, angle):
    """``x (..., J, 3)`` turned by ``angle`` about HumanAct12's up axis (y)."""
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], np.float32)
    return x @ rot.T


@pytest.fixture(scope="module")
def tiny(humanact12):
    clips = [m.joints for m in humanact12.motions[:40]]
    return PosePrior(hidden=16, n_layers=1, crop=16, schedule=TINY).fit(clips), clips


@pytest.mark.real_data
def test_correction_turns_with_the_body(tiny):
    prior, clips = tiny
    x = clips[0][None, :30]
    turned = prior.correction(_turned(x, 1.1))
    np.testing.assert_allclose(turned, _turned(prior.correction(x), 1.1), atol=1e-5)
    centre, axes = body_frame(torch.from_numpy(_turned(x, -0.4)), "humanact12")
    assert centre.shape == (1, 30, 1, 3) and axes.shape == (1, 30, 3, 3)
    np.testing.assert_allclose(torch.einsum("btij,btkj->btik", axes, axes).numpy(), np.broadcast_to(np.eye(3), (1, 30, 3, 3)),
                               atol=1e-6)  # orthonormal rows


@pytest.mark.real_data
def test_threshold_gates_every_frame_and_saving_keeps_it(tiny, tmp_path):
    prior, clips = tiny
    x = clips[1][None, :40].copy()
    given = x.copy()
    assert np.isinf(prior.threshold_)  # uncalibrated: changes nothing
    out, level = prior.posed(x)
    assert np.array_equal(out, x) and level.shape == (1, 40) and (level > 0).all()
    prior = copy.deepcopy(prior)
    prior.threshold_ = float(np.median(level))
    out, level = prior.posed(x)
    under = level[0] <= prior.threshold_
    assert under.any() and (~under).any()
    assert np.array_equal(out[0, under], x[0, under]) and not np.array_equal(out[0, ~under], x[0, ~under])
    full = level[0] >= prior.fade * prior.threshold_
    np.testing.assert_allclose(out[0, full], (x + prior.correction(x))[0, full], atol=1e-6)
    assert np.array_equal(x, given)  # the input is not modified
    prior.save(tmp_path / "p.safetensors")
    back = PosePrior.load(tmp_path / "p.safetensors")
    assert back.threshold_ == prior.threshold_
    np.testing.assert_allclose(back.correction(x), prior.correction(x), atol=1e-6)
    threshold, texture = prior.calibrate(clips[:20], quantile=0.25, texture_quantile=0.9)
    levels = np.concatenate([prior.level(c[None])[0] for c in clips[:20]])
    assert abs(np.mean(levels > threshold) - 0.75) < 0.01 and abs(np.mean(levels > texture) - 0.1) < 0.01
    two = np.stack([x[0], x[0]])
    out, level = prior.posed(two, np.array([threshold, np.inf]))  # one threshold per clip
    assert not np.array_equal(out[0], two[0]) and np.array_equal(out[1], two[1])


def test_drifting_skeleton_tells_slow_deformation_from_noise_and_one_bone(tiny_clip, rng):
    """The step's gate: every bone deforming slowly passes; white noise, rigid bones and one stretching bone do not."""
    x = np.repeat(tiny_clip[:1], 60, axis=0) + np.linspace(0, 0.3, 60)[:, None, None]  # a rigid body gliding
    t = np.linspace(0, 1, 60)[:, None, None]
    drift = x + t * rng.normal(size=(1, 24, 3)) * 0.06  # every joint on its own straight line
    noisy = x + rng.normal(size=x.shape) * 0.02
    one = x.copy()
    one[:, 22] += t[..., 0] * np.array([0.08, 0.0, 0.0])  # a hand drifting alone: one bone stretches
    gate = drifting_skeleton(np.stack([x, drift, noisy, one]), "humanact12")
    assert gate.tolist() == [False, True, False, False]
    with pytest.raises(ValueError, match="B, T, J, 3"):
        drifting_skeleton(drift, "humanact12")


def test_refuses_bad_input_and_unfitted_use(tiny):
    with pytest.raises(NotFittedError):
        PosePrior().correction(np.zeros((1, 10, 24, 3)))
    prior, _ = tiny
    with pytest.raises(ValueError, match="must be \\(B, T, 24, 3\\)"):
        prior.correction(np.zeros((10, 24, 3)))
    bad = np.zeros((1, 10, 24, 3))
    bad[0, 3, 2, 1] = np.nan
    with pytest.raises(ValueError, match="finite"):
        prior.posed(bad)
    with pytest.raises(ValueError, match="clips"):
        PosePrior(schedule=TINY).fit([np.zeros((1, 24, 3))])
    with pytest.raises(ValueError, match="clean_probability"):
        PosePrior(clean_probability=1.0, schedule=TINY).fit([np.zeros((20, 24, 3))])
    with pytest.raises(ValueError, match="quantile"):
        prior.calibrate([np.zeros((20, 24, 3))], quantile=1.0)
    with pytest.raises(ValueError, match="quantile"):
        prior.calibrate([np.zeros((20, 24, 3))], texture_quantile=0.0)


@pytest.mark.real_data
def test_shipped_prior_pulls_drifted_joints_back_and_leaves_clean_clips(humanact12):
    """Subjects 11-12 (never seen by the train-split weights): the step's gate passes drifting clips and no clean
    one, the prior takes drifting joints nearer the clean clip, and the refiner gains by the step."""
    model = Refiner.pretrained("humanact12", split="train")
    kept = Refiner.pretrained("humanact12", split="train", posing="keep")
    prior = model.pose_prior
    assert prior is not None and 0 < prior.threshold_ < 0.02
    clips = [m for m in humanact12.split("test").motions if len(m.joints) >= 60][::8][:12]
    bad = [corrupt(m, "anchor_drift", 2, random_state=i).motion.joints for i, m in enumerate(clips)]
    assert not drifting_skeleton(np.stack([m.joints[:60] for m in clips]), "humanact12").any()
    assert drifting_skeleton(np.stack([b[:60] for b in bad]), "humanact12").mean() > 0.8
    errors = {"flawed": [], "prior": [], "refined": [], "kept": []}
    for m, b in zip(clips, bad):
        x = m.joints.astype(np.float64)
        errors["flawed"].append(_error(b, x)), errors["prior"].append(_error(prior.posed(b[None])[0][0], x))
        errors["refined"].append(_error(model.refine(b, action=m.action), x))
        errors["kept"].append(_error(kept.refine(b, action=m.action), x))
        assert np.array_equal(model.refine(m.joints, action=m.action), kept.refine(m.joints, action=m.action))
    mean = {k: float(np.mean(v)) for k, v in errors.items()}
    assert mean["prior"] < 0.85 * mean["flawed"] and mean["refined"] < 0.85 * mean["kept"], mean


@pytest.mark.real_data
def test_refiner_step_reports_every_change_in_every_mode(humanact12, tmp_path):
    """A whole-clip step, like the rigid skeleton: every mode runs it; each changed frame is in a "pose" or
    "skeleton" entry; files saved before the texture threshold load without it."""
    model = Refiner.pretrained("humanact12", split="train")
    m = next(c for c in humanact12.split("test").motions if len(c.joints) >= 60)
    bad = corrupt(m, "anchor_drift", 3, random_state=3).motion
    kept = Refiner.pretrained("humanact12", split="train", posing="keep").refine(bad, action=m.action)
    for mode in ("full", "anchor", "transition"):
        out, report = model.refine(bad, action=m.action, mode=mode, return_report=True)
        steps = [c for c in report.changes if c.get("repair") == "pose_prior"]
        assert steps and all(c["step"] == "pose" and "pose prior" in c["reason"] for c in steps)
        covered = np.zeros(len(out.joints), bool)
        for c in report.changes:
            covered[c["start"] : c["stop"]] = True
        assert np.array_equal(out.joints[~covered], bad.joints[~covered])
    assert not np.array_equal(model.refine(bad, action=m.action).joints, kept.joints)
    with pytest.raises(ValueError, match="posing"):
        Refiner.pretrained("humanact12", split="train", posing="snap")
    import json

    from refiner.core.serialization import load_state, save_state

    tensors, meta = load_state(_shipped("humanact12-train"))
    fitted = json.loads(meta["refiner.fitted"])
    del fitted["texture_threshold_"]  # as files before the texture step
    save_state(tmp_path / "old.safetensors", tensors, {**meta, "refiner.fitted": json.dumps(fitted)})
    assert np.isinf(PosePrior.load(tmp_path / "old.safetensors").texture_threshold_)


@pytest.mark.real_data
def test_converted_skeletons_get_the_step_on_their_own_bones(humanact12):
    """A uestc clip is judged on its own (rigid) bones, refined through HumanAct12's prior, and comes back nearer."""
    from refiner.core.skeletons import convert

    model = Refiner.pretrained("uestc", split="train")
    kept = Refiner.pretrained("uestc", split="train", posing="keep")
    clips = [m for m in humanact12.split("test").motions if len(m.joints) >= 60][::10][:6]
    clean = np.stack([convert(m.joints[:60], "humanact12", "uestc") for m in clips])
    bad = np.stack([convert(corrupt(m, "anchor_drift", 2, random_state=i).motion.joints[:60], "humanact12", "uestc")
                    for i, m in enumerate(clips)])
    out, reports = model.refine(bad, return_report=True)
    assert sum(any(c.get("repair") == "pose_prior" for c in r.changes) for r in reports) >= 4
    assert _error(out, clean) < _error(kept.refine(bad), clean)
    assert np.array_equal(model.refine(clean), kept.refine(clean))
    mask = np.ones(len(model.rigid_bones), bool)
    mask[:] = False
    assert not drifting_skeleton(bad, "uestc", bones=mask).any()  # no bone judged: nothing drifts


@pytest.mark.real_data
def test_clips_noisy_throughout_get_the_texture_threshold():
    """A generator's texture (the a2m reference generator jitters on every frame, its bones rigid) is corrected past
    the higher threshold only, and the noise step says which clips are noisy throughout."""
    from refiner.reference import load_reference_generator
    from refiner.refinement.noise_filter import filtered_noise

    model = Refiner.pretrained("humanact12", split="train", denoising="filter")  # a generator's, GENERATOR_OPTIONS
    prior = model.pose_prior
    assert prior.texture_threshold_ > prior.threshold_
    clips = np.stack([m.joints for m in load_reference_generator("a2m").sample_motions(1, 6, random_state=3)])
    assert not drifting_skeleton(clips, "humanact12").any()
    _, noisy = filtered_noise(model, clips, [type("R", (), {"changes": []})() for _ in clips])
    assert noisy.sum() >= 3
    out, reports = model.refine(clips, action=[1] * len(clips), return_report=True)
    steps = [c for r in reports for c in r.changes if c.get("repair") == "pose_prior"]
    assert steps and all("noisy throughout" in c["reason"] and f"{100 * prior.texture_threshold_:.2f} cm" in c["reason"]
                         for c in steps)
    kept = Refiner.pretrained("humanact12", split="train", denoising="filter", posing="keep").refine(clips, action=[1] * len(clips))
    assert not np.array_equal(out, kept)
    assert [r.noisy_throughout for r in reports] == noisy.tolist()
    # drifting too: the drift threshold, natively and through the uestc conversion alike
    from refiner.core.skeletons import convert

    t = np.linspace(0, 1, clips.shape[1])[None, :, None, None]
    drift = (clips + t * np.random.default_rng(0).normal(size=(len(clips), 1, 24, 3)) * 0.05).astype(np.float32)
    uestc = np.stack([convert(c, "humanact12", "uestc") for c in drift]).astype(np.float32)
    for name, x in (("humanact12", drift), ("uestc", uestc)):
        _, reports = Refiner.pretrained(name, split="train").refine(x, return_report=True)
        reasons = [c["reason"] for r in reports for c in r.changes if c.get("repair") == "pose_prior"]
        assert reasons and all(f"threshold {100 * prior.threshold_:.2f} cm" in why for why in reasons), name
