"""Reference generators: tiny fits, sample shapes and seeding, save/load, the adapter path, the shipped weights."""
from __future__ import annotations

import json

import numpy as np
import pytest

from refiner.reference import (
    GENERATOR_KINDS,
    KIND_PARAMETERS,
    WEIGHTS_DIR,
    LieVAEGenerator,
    TransformerCVAEGenerator,
    load_reference_generator,
)
from refiner.core.validation import NotFittedError
from refiner.nn.training import TrainSchedule

TINY = {
    LieVAEGenerator: dict(hidden=16, latent_dim=4),
    TransformerCVAEGenerator: dict(d_model=16, n_layers=1, n_heads=2, ffn_dim=16),
}
RAW_SHAPE = {LieVAEGenerator: (60, 72), TransformerCVAEGenerator: (60, 24, 3)}


pytestmark = pytest.mark.usefixtures("one_torch_thread")

@pytest.fixture(scope="module")
def small_set(humanact12):
    """Two clips of every action from subjects 1-10."""
    train = humanact12.split("train")
    idx = [i for a in range(12) for i in np.flatnonzero(train.actions == a)[:2]]
    return train.subset(idx)


@pytest.fixture(scope="module")
def tiny_fitted(small_set):
    return {cls: cls(**TINY[cls], schedule=TrainSchedule(n_epochs=2, steps_per_epoch=2, batch_size=8, device="cpu"),
                    random_state=0).fit(small_set)
            for cls in TINY}


@pytest.mark.real_data
@pytest.mark.parametrize("cls", list(TINY), ids=lambda c: c.__name__)
def test_tiny_fit_and_sample_shapes(cls, tiny_fitted):
    gen = tiny_fitted[cls]
    assert len(gen.history_) == 2 and all(np.isfinite(h["train"]) and np.isfinite(h["val"]) for h in gen.history_)
    raw = gen.sample("walk", 3, random_state=0)
    assert raw.shape == (3,) + RAW_SHAPE[cls] and raw.dtype == np.float32 and np.isfinite(raw).all()
    np.testing.assert_array_equal(raw, gen.sample(1, 3, random_state=0))  # name and index agree, seeded
    assert not np.allclose(raw, gen.sample(1, 3, random_state=1))
    assert not np.allclose(raw[0], raw[1])  # different samples in one batch


@pytest.mark.real_data
@pytest.mark.parametrize("cls", list(TINY), ids=lambda c: c.__name__)
def test_save_load_roundtrip(cls, tiny_fitted, tmp_path):
    gen = tiny_fitted[cls]
    gen.save(tmp_path / "g.safetensors")
    again = cls.load(tmp_path / "g.safetensors")
    np.testing.assert_allclose(again.sample(5, 2, random_state=3), gen.sample(5, 2, random_state=3), atol=1e-6)
    assert again.action_names_ == gen.action_names_ and again.get_params() == gen.get_params()
    gen.save(tmp_path / "h.safetensors", half=True)
    half = cls.load(tmp_path / "h.safetensors")
    assert (tmp_path / "h.safetensors").stat().st_size < 0.6 * (tmp_path / "g.safetensors").stat().st_size
    np.testing.assert_allclose(half.sample(5, 2, random_state=3), gen.sample(5, 2, random_state=3), atol=5e-2)
    other = next(c for c in TINY if c is not cls)
    with pytest.raises(ValueError, match=cls.__name__):
        other.load(tmp_path / "g.safetensors")


@pytest.mark.real_data
def test_lie_output_goes_through_the_action2motion_adapter(tiny_fitted):
    gen = tiny_fitted[LieVAEGenerator]
    motions = gen.to_motions(gen.sample("boxing", 2, random_state=0), "boxing")
    assert len(motions) == 2 and motions[0].action == 10 and motions[0].joints.shape == (60, 24, 3)
    np.testing.assert_allclose(motions[0].joints[0, 0], 0.0, atol=1e-6)  # the adapter re-centres frame 0
    skel = motions[0].skeleton_info
    # Forward kinematics puts every frame on the reference pose's bone lengths.
    np.testing.assert_allclose(skel.bone_lengths(motions[1].joints), np.broadcast_to(
        skel.bone_lengths(gen.reference_), (60, 23)), atol=1e-4)
    assert 0.3 < float(np.linalg.norm(gen.reference_[15] - gen.reference_[0])) < 0.8  # a real pelvis-to-head pose


@pytest.mark.real_data
def test_joint_output_is_recentred_by_the_adapter(tiny_fitted):
    gen = tiny_fitted[TransformerCVAEGenerator]
    raw = gen.sample("walk", 2, random_state=0)
    motions = gen.to_motions(raw)
    np.testing.assert_allclose(motions[0].joints, raw[0] - raw[0, :1, :1], atol=1e-6)
    assert motions[0].action is None


def test_unfitted_and_bad_arguments(tiny_clip):
    from refiner.core.motion import Motion

    for cls in TINY:
        with pytest.raises(NotFittedError):
            cls().sample(0)
        with pytest.raises(ValueError, match="action label"):
            cls(**TINY[cls], schedule=TrainSchedule(n_epochs=1)).fit([Motion(tiny_clip)])
        with pytest.raises(ValueError, match="n_epochs"):
            cls(schedule=TrainSchedule(n_epochs=0)).fit([Motion(tiny_clip, action=1)])
    with pytest.raises(ValueError, match="unknown reference generator"):
        load_reference_generator("no_such_kind")


@pytest.mark.real_data
def test_bad_sample_arguments(tiny_fitted):
    gen = tiny_fitted[TransformerCVAEGenerator]
    with pytest.raises(ValueError, match="action"):
        gen.sample("fly", 1)
    with pytest.raises(ValueError, match="index must be in 0..11"):
        gen.sample(12, 1)
    with pytest.raises(ValueError, match="`n`"):
        gen.sample(0, 0)


def test_shipped_weights_manifest():
    manifest = json.loads((WEIGHTS_DIR / "manifest.json").read_text())
    assert "non-commercial" in manifest["licence"]
    total = 0
    for kind, cls in GENERATOR_KINDS.items():
        entry = manifest["generators"][kind]
        assert entry["class"] == cls.__name__ and entry["split"] == "train" and entry["subjects"] == list(range(1, 11))
        assert entry["dtype"] == "float16" and "train-generator" in entry["command"]
        total += (WEIGHTS_DIR / entry["file"]).stat().st_size
    assert total < 15e6  # the budget for the shipped generators
    for kind, params in KIND_PARAMETERS.items():  # the shipped -large kinds have their kind's sizes
        gen = load_reference_generator(kind)
        sizes = {k: v for k, v in params.items() if k != "schedule"}  # the schedule is the last run's
        assert {k: gen.get_params()[k] for k in sizes} == sizes, kind


def test_cli_generator_names_are_the_kinds():
    from refiner.cli.options import GENERATOR_NAMES

    assert GENERATOR_NAMES == tuple(GENERATOR_KINDS)


@pytest.mark.real_data
def test_train_generator_command(tmp_path, capsys):
    from conftest import shared_data_dir

    from refiner.cli.main import main

    data = shared_data_dir() / "humanact12" / "humanact12_joints.npz"
    assert main(["train-generator", "--kind", "actor", "--out", str(tmp_path), "--quick", "--data", str(data)]) == 0
    assert "written to" in capsys.readouterr().out
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["generators"]["actor"]["clips"] == 919 and "--quick" in manifest["generators"]["actor"]["command"]
    gen = load_reference_generator("actor", folder=tmp_path)
    assert gen.sample(0, 1, random_state=0).shape == (1, 60, 24, 3)
    (tmp_path / "actor.safetensors").write_bytes((tmp_path / "actor.safetensors").read_bytes()[:-8] + b"\0" * 8)
    with pytest.raises(ValueError, match="sha256"):
        load_reference_generator("actor", folder=tmp_path)


@pytest.mark.real_data
def test_lie_targets_are_smooth_and_decode_to_the_same_joints(humanact12):
    from refiner.adapters.action2motion import joints_to_lie, lie_to_joints
    from refiner.reference import lie_targets

    clips = [m.joints for m in humanact12.split("train").motions[:40]]
    ours = [lie_targets(c) for c in clips]
    for c, lie in zip(clips, ours):
        assert lie.shape == (len(c), 72)
        np.testing.assert_allclose(lie_to_joints(lie, reference=c[0], recenter=False), c, atol=1e-4)

    def jumps(lies):
        steps = np.concatenate([np.abs(np.diff(lie[:, 3:].reshape(len(lie), 23, 3), axis=0)).max(-1).ravel()
                                for lie in lies])
        return float((steps > 1.0).mean())

    assert jumps(ours) < 0.3 * jumps([joints_to_lie(c) for c in clips])


def test_unwrap_rotvecs_follows_a_rotation_through_pi():
    from refiner.core.rotations import rotmat_to_rotvec, rotvec_to_rotmat
    from refiner.reference import unwrap_rotvecs

    angles = np.linspace(2.6, 3.7, 12)  # about z, through pi
    canonical = rotmat_to_rotvec(rotvec_to_rotmat(angles[:, None] * np.array([0.0, 0.0, 1.0])))
    assert np.abs(np.diff(canonical[:, 2])).max() > 5  # inverse kinematics flips to the other side
    lie = np.concatenate([np.zeros((12, 3)), canonical], axis=1)
    out = unwrap_rotvecs(lie)
    np.testing.assert_allclose(out[:, 5], angles, atol=1e-5)
    np.testing.assert_allclose(rotvec_to_rotmat(out[:, 3:]), rotvec_to_rotmat(canonical), atol=1e-5)


def test_training_crops_is_deprecated_and_pads_with_the_last_frame():
    from refiner.reference import training_crops

    clips = [np.arange(10, dtype=np.float32).reshape(5, 2), np.arange(40.0).reshape(20, 2)]
    with pytest.warns(DeprecationWarning, match="ClipCrops"):
        crops = training_crops(clips, 8, np.random.default_rng(0))
    assert crops.shape == (2, 8, 2) and crops.dtype == np.float32
    np.testing.assert_array_equal(crops[0], np.concatenate([clips[0], np.repeat(clips[0][-1:], 3, axis=0)]))
    start = int(crops[1, 0, 0]) // 2
    np.testing.assert_array_equal(crops[1], clips[1][start : start + 8])  # stored values, not re-centred


@pytest.mark.real_data
def test_tiny_diffusion_generator_trains_samples_deterministically_and_round_trips(small_set, tmp_path):
    from refiner.reference.diffusion import MotionDiffusionGenerator, cosine_alpha_bars

    a = cosine_alpha_bars(100)
    assert a[0] > 0.99 and a[-1] < 1e-3 and bool((a[1:] < a[:-1]).all())
    gen = MotionDiffusionGenerator(16, n_layers=1, n_heads=2, ffn_dim=16, diffusion_steps=20, sampling_steps=5,
                                   schedule=TrainSchedule(n_epochs=2, steps_per_epoch=2, batch_size=8, device="cpu"),
                                   random_state=0).fit(small_set)
    x = gen.sample("walk", 3, random_state=7)
    assert x.shape == (3, 60, 24, 3) and np.isfinite(x).all()
    np.testing.assert_array_equal(x, gen.sample("walk", 3, random_state=7))  # deterministic for a seed
    assert not np.array_equal(x, gen.sample("walk", 3, random_state=8))
    motions = gen.to_motions(x, "walk")
    assert len(motions) == 3 and motions[0].skeleton == "humanact12" and motions[0].action == 1
    gen.save(tmp_path / "mdm.safetensors")
    back = MotionDiffusionGenerator.load(tmp_path / "mdm.safetensors")
    np.testing.assert_allclose(back.sample("walk", 3, random_state=7), x, atol=1e-5)
    with pytest.raises(ValueError, match="sampling_steps"):
        MotionDiffusionGenerator(16, n_layers=1, n_heads=2, ffn_dim=16, diffusion_steps=10, sampling_steps=20,
                                 schedule=TrainSchedule(n_epochs=1, steps_per_epoch=1, batch_size=8)).fit(small_set)


@pytest.mark.real_data
def test_training_goes_on_from_a_saved_generator_and_resumes_from_a_checkpoint(small_set, tmp_path):
    from dataclasses import replace

    from refiner.reference.diffusion import MotionDiffusionGenerator

    schedule = TrainSchedule(n_epochs=2, steps_per_epoch=2, batch_size=8, device="cpu")
    tiny = dict(n_layers=1, n_heads=2, ffn_dim=16, diffusion_steps=20, sampling_steps=5)
    gen = MotionDiffusionGenerator(16, **tiny, schedule=schedule, random_state=0).fit(small_set)
    gen.save(tmp_path / "mdm.safetensors")
    first = {k: v.clone() for k, v in gen.network_.state_dict().items()}
    more = MotionDiffusionGenerator.load(tmp_path / "mdm.safetensors")
    more.set_params(warm_start=True, schedule=replace(schedule, n_epochs=3)).fit(small_set)
    assert [h["epoch"] for h in more.history_] == [0, 1, 2, 3, 4] and more.train_seconds_ >= gen.train_seconds_
    moved = max(float((more.network_.state_dict()[k] - v.half().float()).abs().max()) for k, v in first.items()
                if v.is_floating_point())
    assert moved > 0  # it trained on from the saved weights, which a fresh fit would not reproduce
    fresh = MotionDiffusionGenerator(16, **tiny, schedule=replace(schedule, n_epochs=3), random_state=0).fit(small_set)
    assert len(fresh.history_) == 3
    # a checkpointed run stopped by its time limit after one epoch resumes there and finishes its 3 epochs
    ckpt = tmp_path / "run.ckpt"
    MotionDiffusionGenerator(16, **tiny, schedule=replace(schedule, n_epochs=3, max_seconds=0.0),
                             random_state=0).fit(small_set, checkpoint=ckpt)  # stops after its first epoch
    resumed = MotionDiffusionGenerator(16, **tiny, schedule=replace(schedule, n_epochs=3), random_state=0).fit(
        small_set, checkpoint=ckpt)
    assert [h["epoch"] for h in resumed.history_] == [0, 1, 2]
    with pytest.raises(ValueError, match="action names"):
        MotionDiffusionGenerator.load(tmp_path / "mdm.safetensors").set_params(
            warm_start=True, action_names=["a", "b"]).fit(small_set)


@pytest.mark.real_data
def test_fitted_prior_is_each_actions_posterior_gaussian(small_set, tmp_path):
    """``prior="fitted"``: per-action latent Gaussians from the training posteriors, sampled seeded, saved
    and loaded; a generator without one says so; an old file without the arrays loads as before."""
    import torch

    gen = TransformerCVAEGenerator(**TINY[TransformerCVAEGenerator], prior="fitted", random_state=0,
                                   schedule=TrainSchedule(n_epochs=2, steps_per_epoch=2, batch_size=8, device="cpu"))
    gen.fit(small_set)
    assert gen.prior_mean_.shape == (12, 16) and gen.prior_scale_.shape == (12, 16, 16)
    # the mean of action 3 is the mean of its clips' posterior means (crops differ, so only roughly)
    clips = [m for m in small_set.motions if m.action == 3]
    crops = gen._normalised({"joints": np.stack([c.joints[:60] - c.joints[:1, :1] for c in clips]).astype(np.float32)},
                            "cpu")
    with torch.no_grad():
        mu = gen.network_.encode(crops, torch.full((len(clips),), 3))[0].numpy()
    spread = np.linalg.norm(gen.prior_mean_ - mu.mean(0), axis=1)
    assert spread[3] == spread.min()  # nearer its own action's mean than any other action's
    np.testing.assert_allclose(np.tril(gen.prior_scale_[3]), gen.prior_scale_[3])  # a Cholesky factor
    x = gen.sample("walk", 3, random_state=5)
    np.testing.assert_array_equal(x, gen.sample("walk", 3, random_state=5))
    gen.save(tmp_path / "f.safetensors")
    np.testing.assert_array_equal(TransformerCVAEGenerator.load(tmp_path / "f.safetensors").sample("walk", 3, random_state=5), x)
    gen.save(tmp_path / "h.safetensors", half=True)  # the prior is stored like the weights
    half = TransformerCVAEGenerator.load(tmp_path / "h.safetensors")
    assert half.prior_scale_.dtype == np.float16
    np.testing.assert_allclose(half.sample("walk", 3, random_state=5), x, atol=5e-2)
    standard = gen.set_params(prior="standard").sample("walk", 3, random_state=5)
    assert not np.allclose(standard, x)
    del gen.prior_mean_, gen.prior_scale_
    gen.save(tmp_path / "s.safetensors")
    with pytest.raises(NotFittedError, match="no fitted prior"):
        TransformerCVAEGenerator.load(tmp_path / "s.safetensors").set_params(prior="fitted").sample(0)
    with pytest.raises(ValueError, match="`prior`"):
        TransformerCVAEGenerator(**TINY[TransformerCVAEGenerator], prior="uniform").fit(small_set)


@pytest.mark.real_data
@pytest.mark.parametrize("kind", ["a2m-large", "actor-large"])
def test_large_kinds_train_tiny_with_their_own_settings(kind, tmp_path, small_set):
    """``--quick`` shrinks the network but keeps the kind's other settings (the large actor's fitted prior)."""
    from refiner.reference import train_reference_generator

    gen = train_reference_generator(kind, small_set, tmp_path, quick=True)
    back = load_reference_generator(kind, folder=tmp_path)
    assert back.get_params() == gen.get_params() and (tmp_path / f"{kind}.safetensors").is_file()
    np.testing.assert_allclose(back.sample(2, 2, random_state=0), gen.sample(2, 2, random_state=0), atol=5e-2)
    if kind == "actor-large":
        assert back.prior == "fitted" and back.guidance == 1.0 and back.prior_scale_.shape == (12, 16, 16)
    else:
        assert back.hidden == 16 and not back.schedule.keep_best


@pytest.mark.real_data
def test_training_from_a_file_of_other_sizes_is_refused(tiny_fitted, tmp_path, humanact12):
    from refiner.reference import train_reference_generator

    tiny_fitted[TransformerCVAEGenerator].save(tmp_path / "tiny.safetensors")
    with pytest.raises(ValueError, match="not a generator of kind 'actor-large'"):
        train_reference_generator("actor-large", humanact12, tmp_path, init=tmp_path / "tiny.safetensors", quick=True)


def test_lie_vae_guidance_extrapolates_the_action_code():
    """Guidance g feeds ``onehot + g (onehot - 1/C)``: the code keeps its sum, g = 0 is the trained one-hot."""
    import torch

    from refiner.reference.lie_vae import LieVAE, LieVAEConfig

    torch.manual_seed(0)
    net = LieVAE(LieVAEConfig(n_actions=4, pose_dim=6, hidden=8, latent_dim=2))
    prev, actions = torch.zeros(2, 3, 6), torch.tensor([1, 3])
    code = net.condition(prev, actions, guidance=0.5)[..., 6:10]
    np.testing.assert_allclose(code[0, 0].numpy(), [-0.125, 1.375, -0.125, -0.125])
    np.testing.assert_allclose(code.sum(-1).numpy(), 1.0, rtol=1e-6)
    assert torch.equal(net.condition(prev, actions, guidance=0.0), net.condition(prev, actions))
    noise = torch.randn(2, 5, 2)
    with torch.no_grad():
        plain = net.generate(actions, noise)
        assert torch.equal(plain, net.generate(actions, noise, guidance=0.0))
        assert not torch.allclose(plain, net.generate(actions, noise, guidance=1.0))


def test_shipped_generators_sample_with_their_kinds_guidance():
    for kind in ("a2m-large", "actor-large"):
        assert load_reference_generator(kind).guidance == KIND_PARAMETERS[kind]["guidance"]
    with pytest.raises(ValueError, match="`guidance` must be a finite number"):
        load_reference_generator("a2m-large").set_params(guidance=float("nan")).sample(0, 1)
