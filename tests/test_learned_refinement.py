"""Learned recognition and repair: tiny training on real clips, batching, windows, do-no-harm, rigid bones."""
import numpy as np
import pytest
import torch

from refiner.core.signal import linear_infill, run_peak, window_starts
from refiner.core.skeletons import BoneProportions, rigid_skeleton, robust_bone_lengths
from refiner.core.skeletons import bone_lengths, joint_bone_lengths, with_bone_lengths
from refiner.evaluation.physics import bone_length_variation
from refiner.refinement.flaw_networks import FlawRepairNet, FrameTransformerConfig
from refiner.refinement import learned_pipeline
from refiner.refinement.learned_pipeline import NOISE_RATIO, flag_runs, noise_ratio
from refiner.refinement.pipeline import Refiner

SHIPPED_TRAIN = Refiner.pretrained.__globals__["_WEIGHTS"] / "humanact12-train"


@pytest.fixture(scope="module")
def tiny_learned(humanact12, tmp_path_factory):
    """The learned parts (and the optional denoiser) trained with the tiny configuration on 72 real clips,
    installed beside the shipped parts."""
    from refiner.refinement.train_learned import train_learned_refiner

    pick = [i for a in range(12) for i in np.flatnonzero(humanact12.actions == a)[::15][:6]]  # many subjects
    out = tmp_path_factory.mktemp("tiny_learned")
    for optional in ("flaw_denoiser", "motion_infiller", "timing_estimator"):  # optional parts, installed with the others
        assert train_learned_refiner(humanact12.subset(pick), out, config="tiny", device="cpu", only=optional) is None
    for part in ("noise_filter", "noise_residual"):  # the residual behind this run's filter, found in out/parts
        assert train_learned_refiner(humanact12.subset(pick), out, config="tiny", device="cpu", only=part) is None
    refiner = train_learned_refiner(humanact12.subset(pick), out, config="tiny", device="cpu", base=SHIPPED_TRAIN)
    return refiner, out


@pytest.mark.real_data
def test_tiny_training_installs_and_resumes(tiny_learned, humanact12):
    from refiner.refinement.train_learned import train_learned

    refiner, out = tiny_learned
    assert refiner.method == "learned" and 0.05 <= refiner.flaw_recognizer.threshold_ <= 0.99
    assert 0 < refiner.flaw_repairer.correction_threshold_ < 1.0  # metres
    assert 0.05 <= refiner.flaw_classifier.threshold_ <= 0.999 and refiner.detect == "classifier"
    assert refiner.manifest["learned"]["flaw_threshold"] == pytest.approx(refiner.flaw_recognizer.threshold_)
    again = Refiner.load(out)
    assert again.flaw_denoiser is not None and again.flaw_denoiser.skeleton_ == "humanact12"
    assert again.motion_infiller is not None and again.motion_infiller.n_joints_ == 24
    assert again.timing_estimator is not None and again.retiming == "estimated"
    assert again.noise_filter is not None and again.denoising == "runs" and again.noise_filter.half_width == 1
    assert again.manifest["learned"]["noise_threshold_m"] == pytest.approx(again.noise_filter.threshold_)
    assert again.noise_residual is not None and again.noise_residual.half_width_ == 1 and again.noise_residual.hidden == 8
    assert again.manifest["learned"]["noise_residual"]["fit_clips"] > 0
    assert 0 < again.natural_bones == again.manifest["learned"]["natural_bone_variation"] < 1e-4  # mocap's exact bones
    assert again.amplitude_restorer is not None and 0 < again.amplitude_restorer.gate_ < 1
    assert again.manifest["learned"]["amplitude_gate"] == pytest.approx(again.amplitude_restorer.gate_)
    assert again.pose_prior is not None and again.pose_prior.hidden == 8 and again.posing == "prior"
    assert again.manifest["learned"]["pose_prior_threshold_m"] == pytest.approx(again.pose_prior.threshold_)
    assert again.pose_prior.texture_threshold_ >= again.pose_prior.threshold_  # the 95th percentile, the median
    assert again.manifest["learned"]["pose_prior_texture_threshold_m"] == pytest.approx(again.pose_prior.texture_threshold_)
    assert again.texture_filter is not None and again.texture_filter.channels == 8 and again.texture == "off"
    _, report = Refiner.load(out, texture="all").refine(humanact12[10].joints[:50], return_report=True)
    assert [c["step"] for c in report.changes].count("texture") == 1  # every clip, as a generator's
    assert np.isfinite(again.timing_estimator.threshold_)
    assert again.manifest["learned"]["timing_threshold_frames"] == pytest.approx(again.timing_estimator.threshold_)
    assert np.isfinite(again.manifest["learned"]["timing_agreed_threshold_frames"])  # with the classifier's agreement
    flagged = Refiner.load(out, retiming="flagged")
    flagged.timing_estimator.threshold_ = 0.0  # every frame passes: the estimated step would re-time all of them
    clip = humanact12[10].joints[:50]
    _, report = flagged.refine(clip, return_report=True)
    assert not any(c.get("repair") == "estimated_retime" for c in report.changes)
    again.timing_estimator.threshold_ = 0.0
    again.timing_agreement = 1.01  # the classifier's second opinion can veto every run
    _, report = again.refine(clip, return_report=True)
    assert not any(c.get("repair") == "estimated_retime" for c in report.changes)
    again.timing_agreement = None  # the tiny classifier's opinion is not checked here
    retimed, report = again.refine(clip, return_report=True)
    assert any(c.get("repair") == "estimated_retime" for c in report.changes)
    assert bone_length_variation(retimed) < 1e-3  # re-sampled frames go back on the clip's bone lengths
    _, report = again.refine(clip, mode="anchor", return_report=True)  # a transition step: not for anchors alone
    assert not any(c.get("repair") == "estimated_retime" for c in report.changes)
    with pytest.raises(ValueError, match="retiming='estimated' needs a `timing_estimator`"):
        Refiner.load(out, retiming="estimated").__class__(
            **{p: getattr(again, p) for p in ("recognizer", "anchor_refiner", "transition_generator",
                                              "transition_refiner", "anchor_concepts", "anchor_quality")},
            retiming="estimated")
    x = humanact12[10].joints[:50]
    np.testing.assert_allclose(again.flaw_recognizer.predict(x[None])["flaw"],
                               refiner.flaw_recognizer.predict(x[None])["flaw"], atol=1e-3)  # int8 weights
    before = (out / "parts" / "flaw_repairer.safetensors").stat().st_mtime_ns
    parts = train_learned(humanact12.subset(range(24)), out, config="tiny", device="cpu")
    assert set(parts) == {"flaw_classifier", "flaw_recognizer", "flaw_repairer", "noise_filter", "amplitude_restorer",
                          "pose_prior", "texture_filter", "flaw_denoiser", "motion_infiller", "timing_estimator",
                          "noise_residual"}
    assert (out / "parts" / "flaw_repairer.safetensors").stat().st_mtime_ns == before  # loaded, not retrained


@pytest.mark.real_data
def test_your_own_weights_are_looked_in_first(tiny_learned, tmp_path):
    """``Refiner.pretrained(weights=DIR)`` (and ``bench --weights DIR``) takes DIR's sets before the shipped ones,
    for the layouts served through them too; the sets DIR lacks are the shipped ones."""
    _, out = tiny_learned
    (tmp_path / "humanact12-train").symlink_to(out, target_is_directory=True)
    tiny = Refiner.load(out).flaw_recognizer.n_parameters()
    assert tiny != Refiner.pretrained(split="train").flaw_recognizer.n_parameters()
    assert Refiner.pretrained(split="train", weights=tmp_path).flaw_recognizer.n_parameters() == tiny
    assert Refiner.pretrained("uestc", split="train", weights=tmp_path).base.flaw_recognizer.n_parameters() == tiny
    assert Refiner.pretrained(weights=tmp_path).flaw_recognizer.n_parameters() != tiny  # split "all": shipped
    assert Refiner.pretrained("cmu_mocap", weights=tmp_path).manifest["dataset"] == "cmu_mocap"
    from refiner.cli.main import main

    assert main(["bench", "flaws", "--weights", str(tmp_path / "none")]) == 2  # not a folder


@pytest.mark.real_data
def test_an_optional_part_is_added_to_a_finished_refiner_leaving_its_files_alone(humanact12, tmp_path):
    from safetensors import safe_open

    from refiner.refinement.train_learned import install_part, train_learned_refiner

    added = train_learned_refiner(humanact12.subset(range(0, 1190, 40)), tmp_path, config="tiny", device="cpu",
                                  base=SHIPPED_TRAIN, only="timing_estimator")
    assert added.retiming == "estimated" and np.isfinite(added.timing_estimator.threshold_)  # calibrated there
    assert added.manifest["learned"]["timing_threshold_frames"] == pytest.approx(added.timing_estimator.threshold_)
    assert np.isfinite(added.manifest["learned"]["timing_agreed_threshold_frames"])
    assert added.manifest["learned"]["timing_estimator"]["split"] == "all"  # the part's training log
    for path in SHIPPED_TRAIN.glob("*.safetensors"):
        if path.stem != "timing_estimator":  # the shipped one, replaced
            assert (tmp_path / path.name).read_bytes() == path.read_bytes(), path.name
    with safe_open(str(tmp_path / "timing_estimator.safetensors"), "np") as f:
        assert any(k.endswith(".int8") for k in f.keys())  # stored as the shipped sets store it
    with pytest.raises(ValueError, match="install_part adds one of"):
        install_part(tmp_path, "flaw_repairer", added.flaw_repairer)


@pytest.mark.real_data
def test_batch_equals_single_and_long_clips_use_windows(tiny_learned, humanact12, one_torch_thread):
    refiner, _ = tiny_learned
    rec = refiner.flaw_recognizer
    clips = np.stack([humanact12[i].joints[:40] for i in (3, 50, 400)])
    batch = rec.predict(clips, [0, None, 5])
    for i, a in enumerate([0, None, 5]):
        single = rec.predict(clips[i : i + 1], [a])
        np.testing.assert_allclose(batch["flaw"][i], single["flaw"][0], atol=1e-5)
    assert batch["flaw"].shape == (3, 40) and batch["action"].shape == (3, 12)
    assert ((batch["flaw"] >= 0) & (batch["flaw"] <= 1)).all()
    np.testing.assert_allclose(batch["action"].sum(1), 1.0, atol=1e-5)
    long = humanact12[int(np.argmax([m.n_frames for m in humanact12]))].joints
    assert len(long) > 3 * rec.window
    p = rec.predict(long[None])["flaw"]
    assert p.shape == (1, len(long)) and np.isfinite(p).all()
    suspect = np.zeros((1, len(long)), bool)
    suspect[0, 100:120] = True
    fixed = refiner.flaw_repairer.repair(long[None], suspect)
    assert fixed.shape == (1,) + long.shape and np.isfinite(fixed).all()
    calm = Refiner.load(tiny_learned[1])
    calm.flaw_recognizer.threshold_ = 1.0  # nothing can be flagged: a long clip comes back bit for bit
    calm.flaw_repairer.correction_threshold_ = np.inf
    calm.flaw_classifier.threshold_ = 1.0
    np.testing.assert_array_equal(calm.refine(long), long)


def test_untrained_repair_is_identity_or_linear_infill(rng):
    """Zero-initialised output: an untrained repair network keeps given frames and linearly in-fills hidden ones."""
    net = FlawRepairNet(FrameTransformerConfig(n_joints=24, n_actions=3, d_model=16, n_layers=1, n_heads=2,
                                               ffn_dim=16, dropout=0.0)).eval()
    x = rng.normal(size=(2, 30, 24, 3)).astype(np.float32)
    suspect = np.zeros((2, 30), bool)
    suspect[:, 10:18] = True
    infill = np.stack([linear_infill(c, s) for c, s in zip(x, suspect)])
    args = [torch.from_numpy(v) for v in (x, infill, suspect, np.zeros_like(suspect))]
    with torch.no_grad():
        out = net(*args, torch.tensor([0, 3]))
        hidden = net(args[1], args[1], args[2], args[2], torch.tensor([0, 3]))
    gate = torch.sigmoid(torch.tensor(4.0)).item()
    np.testing.assert_allclose(out.numpy()[:, ~suspect[0]], x[:, ~suspect[0]], atol=1e-5)
    mixed = gate * x + (1 - gate) * infill  # the root gate and the pose gates mix alike at initialisation
    np.testing.assert_allclose(out.numpy()[:, 10:18], mixed[:, 10:18], atol=1e-4)
    np.testing.assert_allclose(hidden.numpy(), infill, atol=1e-5)
    line = linear_infill(np.arange(10, dtype=np.float32)[:, None, None].repeat(2, 1).repeat(3, 2),
                         np.array([0, 0, 1, 1, 1, 0, 0, 0, 1, 1], bool))
    np.testing.assert_allclose(line[:, 0, 0], [0, 1, 2, 3, 4, 5, 6, 7, 7, 7])
    x = np.array([5.0, 9, 1, 3, 9, 4, 7])[:, None, None]  # a hidden first frame is held at the first kept one
    np.testing.assert_allclose(linear_infill(x, np.array([1, 0, 1, 0, 1, 1, 0], bool))[:, 0, 0],
                               [9, 9, 6, 3, 3 + 4 / 3, 3 + 8 / 3, 7])


def test_flag_runs_and_windows():
    p = np.array([0, 0.9, 0, 0, 0.8, 0.9, 0.95, 0, 0, 0, 0, 0.7, 0.8, 0, 0, 0, 0, 0, 0, 0.9])
    assert flag_runs(p, 0.5, min_run=2, margin=1) == [(3, 8), (10, 14)]  # single frames are not flagged
    assert flag_runs(p, 0.5, min_run=1, margin=0) == [(1, 2), (4, 7), (11, 13), (19, 20)]
    assert flag_runs(p, 0.5, min_run=2, margin=3) == [(1, 16)]  # widened runs merge
    assert flag_runs(np.zeros(10), 0.5) == []
    assert window_starts(50, 64, 32) == [0]
    assert window_starts(130, 64, 32) == [0, 32, 64, 66]


@pytest.mark.real_data
def test_noise_gate_repairs_local_jitter_only(humanact12, rng):
    clip = humanact12[20].joints.astype(np.float64)
    local = clip.copy()
    local[20:35] += rng.normal(0, 0.01, local[20:35].shape)  # 1 cm jitter in one window
    assert noise_ratio(local, 20, 35) > NOISE_RATIO + 0.3
    everywhere = clip + rng.normal(0, 0.01, clip.shape)  # as rough everywhere: the clip's texture
    assert noise_ratio(everywhere, 20, 35) < NOISE_RATIO
    assert noise_ratio(clip, 0, len(clip)) < NOISE_RATIO  # a whole clean clip against itself


@pytest.mark.real_data
def test_rigid_skeleton_batch_matches_clip_by_clip(humanact12, rng):
    clips = np.stack([humanact12[i].joints[:40] for i in (3, 20, 41)]).astype(np.float64)
    lengths = joint_bone_lengths(clips, "humanact12")
    clips[1] = with_bone_lengths(clips[1], lengths[1] * rng.uniform(0.9, 1.1, size=lengths[1].shape), "humanact12")
    batch, variation = rigid_skeleton(clips, "humanact12", 0.005)
    assert variation.shape == (3,) and variation[1] > 0.03 and variation[[0, 2]].max() < 1e-4
    for k in range(3):
        single, v = rigid_skeleton(clips[k], "humanact12", 0.005)
        np.testing.assert_allclose(batch[k], single, atol=1e-12)
        assert v == pytest.approx(variation[k])
    np.testing.assert_array_equal(batch[[0, 2]], clips[[0, 2]])  # rigid clips of a batch are left exactly alone


@pytest.mark.real_data
def test_rigid_skeleton_restores_stretched_bones(humanact12, rng):
    clip = humanact12[20].joints.astype(np.float64)
    lengths = joint_bone_lengths(clip, "humanact12")
    stretched = with_bone_lengths(clip, lengths * rng.uniform(0.9, 1.1, size=lengths.shape), "humanact12")
    assert bone_length_variation(stretched) > 0.03
    fixed, variation = rigid_skeleton(stretched, "humanact12", 0.005)
    assert variation > 0.03 and bone_length_variation(fixed) < 1e-3  # from 6 % to under 0.1 %
    # the lengths are restored without carrying corrections down the chains: closer to the real clip
    err = lambda a: np.linalg.norm(a - clip, axis=-1).mean()  # noqa: E731
    assert err(fixed) < err(stretched)
    same, v = rigid_skeleton(clip, "humanact12", 0.005)
    assert same is clip and v < 1e-4  # real mocap is rigid: nothing to do


@pytest.mark.real_data
def test_rigid_skeleton_keeps_a_clips_rigid_core(humanact12, rng):
    """A mocap clip edited in places keeps its exact frames (and, asked, its blended ones, whose bones shorten); a
    stretched bone goes back on the core's lengths; a clip whose bones stretch everywhere has no core."""
    from refiner.core.rigid import rigid_core

    clip = humanact12[20].joints[:60].astype(np.float64)
    edited = clip.copy()
    edited[10:20] = 0.5 * clip[10:20] + 0.5 * clip[40:50]  # halfway toward another phase: bones shorten
    lengths = joint_bone_lengths(clip, "humanact12")
    grow = np.ones_like(lengths)
    grow[30:36, 18:] = 1.1  # six frames with forearms and hands 10 % too long
    edited = with_bone_lengths(edited, joint_bone_lengths(edited, "humanact12") * grow, "humanact12")
    core = rigid_core(bone_lengths(edited, "humanact12"))
    assert core is not None and core[:10].all() and core[36:].all() and not core[30:36].any()
    kept, variation = rigid_skeleton(edited, "humanact12", 0.005, keep_core=True, keep_shortened=True)
    assert variation > 0.005
    moved = (kept != edited).any((1, 2))
    assert not moved[:30].any() and moved[30:36].all() and not moved[36:].any()  # the core and the blend as given
    np.testing.assert_allclose(bone_lengths(kept[30:36], "humanact12"), bone_lengths(clip[30:36], "humanact12"), rtol=2e-3)
    np.testing.assert_allclose(kept[30:36, :18], edited[30:36, :18], atol=1e-3)  # rebuilt outward: the parents stay
    rigid = rigid_skeleton(kept, "humanact12", 0.005, keep_core=True)[0]  # the refiner's last step: the blend too
    moved = (rigid != kept).any((1, 2))
    assert moved[10:20].all() and not moved[:10].any() and not moved[20:].any()
    np.testing.assert_allclose(bone_lengths(rigid, "humanact12"), bone_lengths(clip, "humanact12"), rtol=2e-3)
    assert (rigid_skeleton(edited, "humanact12", 0.005)[0] != edited).any((1, 2)).sum() > 50  # without: nearly all
    stretched = with_bone_lengths(clip, lengths * rng.uniform(0.9, 1.1, size=lengths.shape), "humanact12")
    assert rigid_core(bone_lengths(stretched, "humanact12")) is None
    np.testing.assert_array_equal(rigid_skeleton(stretched, "humanact12", 0.005, keep_core=True, keep_shortened=True)[0],
                                  rigid_skeleton(stretched, "humanact12", 0.005)[0])
    with pytest.raises(ValueError, match="T, n_bones"):
        rigid_core(bone_lengths(clip[None], "humanact12"))
    long = rng.uniform(0.9, 1.1, (3000, 23))
    long[1000:1800] = 0.3  # a long clip: its core is found among evenly spaced candidates
    assert np.array_equal(np.flatnonzero(rigid_core(long)), np.arange(1000, 1800))
    assert rigid_core(long[:1000]) is None


@pytest.mark.real_data
def test_refine_puts_shortened_bones_back_at_last(humanact12):
    """A mocap clip whose arm shrinks for a while comes back with rigid bones, its other frames exactly as given."""
    clip = humanact12[20].joints[:60].astype(np.float32)
    lengths = joint_bone_lengths(clip, "humanact12")
    scale = np.ones_like(lengths)
    scale[20:40, [17, 19, 21, 23]] = 1 - 0.1 * np.sin(np.linspace(0, np.pi, 20))[:, None] ** 2
    shrunk = with_bone_lengths(clip, lengths * scale, "humanact12").astype(np.float32)
    out, report = Refiner.pretrained("humanact12", split="train").refine(shrunk, action=humanact12[20].action,
                                                                         return_report=True)
    assert bone_length_variation(shrunk) > 0.005 and bone_length_variation(out) < 1e-4, bone_length_variation(out)
    untouched = ~np.zeros(60, bool)
    for change in report.changes:
        untouched[change["start"] : change["stop"]] = False
    assert untouched.sum() >= 30 and np.array_equal(out[untouched], shrunk[untouched])
    assert np.abs(out - clip).max() < 1e-3  # one limb's bones off: rebuilt outward, the true pose comes back
    assert any(c["step"] == "skeleton" and "rigid core" in c["reason"] for c in report.changes)


def test_a_repair_that_changes_nothing_is_reported_as_kept(humanact12):
    """A held-out clip time-warped without a stall: its flagged timing run has nothing to re-time, so the report
    lists no re-timing (it listed one that moved 0.0 cm, and the run's frames were projected as if repaired)."""
    from refiner.evaluation.flaws import corrupt

    clip = humanact12.split("test").motions[27]
    warped = corrupt(clip, "time_warp", 2, random_state=27).motion
    out, report = Refiner.pretrained("humanact12", split="train").refine(warped, action=clip.action,
                                                                         return_report=True)
    assert [c["step"] for c in report.changes] == ["skeleton"]
    assert any("changed nothing; kept" in n for n in report.notes)
    assert np.linalg.norm(out.joints - warped.joints, axis=-1).mean() < 5e-4  # only shortened bones put back


def test_robust_bone_lengths_trust_noise_and_doubt_drift(rng):
    """A bone whose length is noisy keeps its median; one whose length drifts slowly is drawn to its share."""
    prop = BoneProportions(np.array([0.5, 0.3, 0.2]), np.array([0.01, 0.01, 0.01]))
    true = np.array([0.5, 0.3, 0.2])  # the clip's scale is 1
    t = np.linspace(0, 1, 60)[:, None]
    noisy = true + rng.normal(0, 0.01, (60, 3))
    drifting = true + np.array([0.0, 0.0, 0.06]) * t  # the last bone grows by up to 30 %
    got = robust_bone_lengths(np.stack([noisy, drifting]), prop)
    np.testing.assert_array_equal(robust_bone_lengths(np.stack([noisy, drifting])), np.median(np.stack([noisy, drifting]), 1))
    assert np.abs(got[0] - np.median(noisy, 0)).max() < 0.003  # noise: the median stands
    assert abs(np.median(drifting[:, 2]) - 0.2) > 0.025 and abs(got[1, 2] - 0.2) < 0.01  # drift: the share wins
    exact = np.repeat(true[None] * 1.1, 60, 0)  # a rigid clip of another person: its lengths, not the shares
    exact[::3] *= 0.9
    np.testing.assert_allclose(robust_bone_lengths(exact[None], prop)[0], true * 1.1)
    assert prop.select(np.array([True, False, True])).mean.sum() == pytest.approx(1.0)
    with pytest.raises(ValueError, match="has 3 bones; the lengths have 2"):
        robust_bone_lengths(np.stack([noisy[:, :2]]), prop)
    with pytest.raises(ValueError, match="B, T, n_bones"):
        robust_bone_lengths(noisy, prop)


@pytest.mark.real_data
def test_rigid_skeleton_with_proportions_undoes_drifting_bones(humanact12):
    """Joints that drift apart stretch their bones slowly; the learned proportions put them back nearer the truth."""
    from refiner.evaluation.flaws import corrupt

    prop = BoneProportions.from_clips([m.joints for m in humanact12.split("train").motions[::5]], "humanact12")
    assert prop.mean.shape == (23,) and prop.mean.sum() == pytest.approx(1.0) and (prop.spread > 0).all()
    errors = {"flawed": [], "median": [], "proportions": []}
    for i in (5, 205, 405, 605, 805, 1005):
        clip = humanact12[i]
        flawed = corrupt(clip, "anchor_drift", 2, random_state=i).motion.joints.astype(np.float64)
        err = lambda a: np.linalg.norm(a - clip.joints, axis=-1).mean()  # noqa: E731
        errors["flawed"].append(err(flawed))
        errors["median"].append(err(rigid_skeleton(flawed, "humanact12", 0.005)[0]))
        errors["proportions"].append(err(rigid_skeleton(flawed, "humanact12", 0.005, proportions=prop)[0]))
    mean = {k: np.mean(v) for k, v in errors.items()}
    assert mean["proportions"] < 0.95 * mean["flawed"] and mean["proportions"] < 0.95 * mean["median"], mean


def test_shipped_weights_know_bone_proportions():
    """The learned weight sets carry their proportions and use them; ``rigid_lengths="median"`` keeps the old step."""
    model = Refiner.pretrained("humanact12", split="train")
    assert model.rigid_lengths == "proportions" and model.bone_proportions.mean.shape == (23,)
    assert Refiner.pretrained("humanact12", split="train", rigid_lengths="median").rigid_lengths == "median"
    with pytest.raises(ValueError, match="rigid_lengths"):
        Refiner.pretrained("humanact12", split="train", rigid_lengths="mean")
    assert model.rigid_core and not Refiner.pretrained("humanact12", split="train", rigid_core=False).rigid_core
    with pytest.raises(ValueError, match="rigid_core"):
        Refiner.pretrained("humanact12", split="train", rigid_core="yes")
    record = model.bone_proportions.to_dict()
    for bad in ({"mean": record["mean"]}, {"mean": record["mean"][:5], "spread": record["spread"]},
                {"mean": [float("nan")] + record["mean"][1:], "spread": record["spread"]}):
        with pytest.raises(ValueError, match="bone proportions"):
            BoneProportions.from_dict(bad)
    short = {"mean": record["mean"][:19], "spread": record["spread"][:19]}
    with pytest.raises(ValueError, match="has 23"):
        Refiner(**{p: getattr(model, p) for p in ("recognizer", "anchor_refiner", "transition_generator",
                                                  "transition_refiner", "anchor_concepts", "anchor_quality")},
                manifest={"learned": {"bone_proportions": short}})


@pytest.mark.real_data
def test_learned_refiner_does_no_harm_and_reports(tiny_learned, humanact12, monkeypatch):
    refiner, out = tiny_learned
    # every frame flagged makes one run no noisier than its own clip, which the noise gate keeps
    # (tested on its own in test_noise_gate_repairs_local_jitter_only); here the repair must run
    monkeypatch.setattr(learned_pipeline, "NOISE_RATIO", 0.0)
    forced = Refiner.load(out, detect="classifier+recognizer+correction")
    forced.flaw_recognizer.threshold_ = forced.flaw_classifier.threshold_ = 1e-6  # flag every frame
    clip = humanact12[700]
    before = clip.numpy()
    result, report = forced.refine(clip, return_report=True)
    np.testing.assert_array_equal(clip.joints, before)
    changed = report.changed_frames
    assert changed.any() and report.changes[0]["reason"].startswith("flagged: kinematic flaw probability")
    assert len(report.correction_cm) == clip.n_frames
    np.testing.assert_array_equal(result.joints[~changed], clip.joints[~changed])
    assert len(report.flaw_probability) == clip.n_frames and report.action == clip.action
    # a batch of torch clips comes back as torch, clip by clip like single calls; actions inferred
    batch = torch.from_numpy(np.stack([humanact12[i].joints[:30] for i in (5, 6)]))
    out_b, reports = forced.refine(batch, return_report=True)
    assert isinstance(out_b, torch.Tensor) and out_b.shape == batch.shape and all(r.action_inferred for r in reports)
    single = forced.refine(batch[1].numpy())
    np.testing.assert_allclose(out_b[1].numpy(), single, atol=1e-5)
    # stretching bones in generator output come back rigid, and the report says so
    lengths = joint_bone_lengths(before, "humanact12")
    wobbly = with_bone_lengths(before, lengths * np.random.default_rng(0).uniform(0.9, 1.1, lengths.shape),
                               "humanact12").astype(np.float32)
    fixed, rep = refiner.refine(wobbly, action=clip.action, return_report=True)
    assert bone_length_variation(fixed) < 1e-3 and rep.changes[0]["step"] == "skeleton"
    with pytest.raises(ValueError, match="repair"):
        Refiner.load(out, repair="nope")
    with pytest.raises(ValueError, match="unknown detect"):
        Refiner.load(out, detect="classifier+magic")
    for repair in ("select", "given", "infill"):  # the other repair strategies run and keep unflagged frames
        other = Refiner.load(out, repair=repair)
        other.flaw_classifier.threshold_ = 1e-6
        res, rep = other.refine(clip, return_report=True)
        assert res.joints.shape == clip.joints.shape and np.isfinite(res.joints).all()
        np.testing.assert_array_equal(res.joints[~rep.changed_frames], clip.joints[~rep.changed_frames])


@pytest.mark.real_data
def test_denoiser_repairs_and_detects_when_asked_and_smoothing_stands_in_without_it(tiny_learned, humanact12, monkeypatch):
    import refiner.refinement.learned_pipeline as lp

    refiner, out = tiny_learned
    monkeypatch.setattr(lp, "TYPED_REPAIRS", {g: ("denoise", 0) for g in lp.TYPED_REPAIRS})
    monkeypatch.setattr(lp, "VERIFY_TYPED", ())
    monkeypatch.setattr(lp, "NOISE_RATIO", 0.0)  # one whole-clip run is no noisier than its clip
    clip = humanact12[700]
    model = Refiner.load(out, detect="classifier+denoiser")
    model.flaw_classifier.threshold_ = 1e-6  # flag every frame
    res, rep = model.refine(clip, return_report=True)
    assert {c["repair"] for c in rep.changes} == {"denoise"} and "denoiser correction" in rep.changes[0]["reason"]
    assert len(rep.denoiser_correction_cm) == clip.n_frames
    np.testing.assert_array_equal(res.joints[~rep.changed_frames], clip.joints[~rep.changed_frames])
    model.flaw_denoiser = None  # weights without a denoiser: smoothing stands in
    model.detect = "classifier"
    _, rep = model.refine(clip, return_report=True)
    assert {c["repair"] for c in rep.changes} == {"smooth"}
    with pytest.raises(ValueError, match="flaw_denoiser"):
        Refiner(*[getattr(model, n) for n in ("recognizer", "anchor_refiner", "transition_generator",
                                               "transition_refiner", "anchor_concepts", "anchor_quality",
                                               "flaw_recognizer", "flaw_repairer", "flaw_classifier")],
                detect="classifier+denoiser")


@pytest.mark.real_data
def test_train_cli_learned_tiny(tmp_path, capsys):
    from conftest import shared_data_dir

    from refiner.cli.main import main
    from refiner.io.datasets import load_humanact12

    # every 5th clip, as a folder of Action2Motion .npy clips: the names keep the subjects, so the split and
    # the calibration subjects (9-10) are the real ones, at a fifth of the segmentation and calibration time
    full = load_humanact12(shared_data_dir() / "humanact12" / "humanact12_joints.npz")
    data = tmp_path / "clips"
    data.mkdir()
    for name, motion in list(zip(full.names, full.motions))[::5]:
        np.save(data / f"{name}.npy", motion.joints)
    args = ["train", "--learned", "--config", "tiny", "--device", "cpu", "--data", str(data), "--split", "train",
            "--out", str(tmp_path / "out"), "--base", str(SHIPPED_TRAIN)]
    assert main(args + ["--only", "flaw_repairer"]) == 0
    assert (tmp_path / "out" / "parts" / "flaw_repairer.safetensors").is_file()
    assert not (tmp_path / "out" / "manifest.json").exists()
    assert main(args) == 0
    assert "learned steps added" in capsys.readouterr().out
    model = Refiner.load(tmp_path / "out")
    assert model.method == "learned" and model.manifest["learned"]["split"] == "train"


@pytest.mark.real_data
def test_flaw_features_see_what_flaws_break(humanact12):
    """Kinematic evidence: batch and single clip agree; jitter raises the residual, stretching the bone deviation."""
    from refiner.refinement.flaw_features import N_FEATURES, flaw_features

    clip = next(m for m in humanact12 if m.n_frames >= 50).joints[:50].astype(np.float64)
    batch = flaw_features(np.stack([clip, clip[::-1]]))
    assert batch.shape == (2, 50, N_FEATURES) and np.isfinite(batch).all()
    np.testing.assert_allclose(flaw_features(clip), batch[0], rtol=1e-5, atol=1e-5)
    noisy = clip + np.random.default_rng(0).normal(scale=0.02, size=clip.shape)
    assert flaw_features(noisy)[:, 6].mean() > 3 * flaw_features(clip)[:, 6].mean()  # jitter residual
    lengths = joint_bone_lengths(clip, "humanact12")
    long_arm = lengths.copy()
    long_arm[20:, 18] *= 1.3  # left elbow -> wrist bone 30 % longer from frame 20 on
    stretched = with_bone_lengths(clip, long_arm, "humanact12")
    assert flaw_features(stretched)[:, 9].max() > 10 * flaw_features(clip)[:, 9].max()  # bone deviation
    with pytest.raises(ValueError, match="T >= 4"):
        flaw_features(clip[:3])


@pytest.mark.real_data
def test_flaw_classifier_tiny_fit_and_calibration(tiny_learned, humanact12):
    refiner, _ = tiny_learned
    clf = refiner.flaw_classifier
    x = np.stack([humanact12[i].joints[:40] for i in (1, 2, 3)])
    every = clf.predict_all(x)
    assert every.shape == (3, 40, 5) and ((every >= 0) & (every <= 1)).all()  # flaw + 4 flaw groups
    np.testing.assert_allclose(clf.predict(x), every[..., 0])
    clips = [humanact12[i].joints for i in range(40, 60)]
    th = clf.calibrate(clips, clip_rate=0.1)
    flagged = np.mean([run_peak(clf.predict(c[None])[0], 2) > th for c in clips])
    assert th == clf.threshold_ and flagged <= 0.1 + 1e-9  # at most the asked share of clean clips


@pytest.mark.real_data
def test_flaw_classifier_trains_on_crops_made_rigid_like_the_refiner_sees_them(humanact12):
    """With ``rigid_tolerance`` the flawed training crops are put on rigid bones first (so their
    bone-deviation features are small), and the labels are what is left of each flaw."""
    from refiner.refinement.flaw_classifier import FlawClassifier

    clips = [m.joints for m in humanact12.subset(range(0, 240, 20))]
    feats = {}
    for tol in (None, 0.005):
        clf = FlawClassifier(copies=6, rigid_tolerance=tol, random_state=0)
        clf.skeleton_ = "humanact12"
        feats[tol] = clf._examples(clips, np.random.default_rng(3), 6)
    assert feats[None]["feats"].shape == feats[0.005]["feats"].shape
    dev_raw, dev_rigid = feats[None]["feats"][..., 9].max(1), feats[0.005]["feats"][..., 9].max(1)  # bone dev. max
    stretched = dev_raw > 0.5  # crops whose flaws changed some bone by more than 5 %
    assert stretched.sum() >= 5
    assert np.median(dev_rigid[stretched]) < 0.2 * np.median(dev_raw[stretched])
    assert feats[0.005]["label"][..., 0].sum() <= feats[None]["label"][..., 0].sum()  # some flaw removed by rigidity


@pytest.mark.real_data
def test_learned_steps_alone_make_a_refiner_and_the_paper_method_says_what_is_missing(tiny_learned, humanact12, tmp_path):
    refiner, _ = tiny_learned
    alone = Refiner(None, None, None, None, None, None, refiner.flaw_recognizer, refiner.flaw_repairer,
                    refiner.flaw_classifier, skeleton="humanact12", action_names=refiner.action_names,
                    manifest={"dataset": "humanact12", "licence": "test"})
    x = humanact12[10].joints
    np.testing.assert_array_equal(alone.refine(x), refiner.refine(x))  # the learned method uses no paper part
    alone.save(tmp_path / "alone")
    assert sorted(p.stem for p in (tmp_path / "alone").glob("*.safetensors")) == [
        "flaw_classifier", "flaw_recognizer", "flaw_repairer"]
    np.testing.assert_array_equal(Refiner.load(tmp_path / "alone").refine(x), alone.refine(x))
    with pytest.raises(ValueError, match="method='concepts'.*needs the parts recognizer.*learned steps only"):
        Refiner.load(tmp_path / "alone", method="concepts")


@pytest.mark.real_data
@pytest.mark.parametrize("with_infiller", [True, False])
def test_typed_motion_infill_repair_and_its_stand_in(tiny_learned, humanact12, monkeypatch, with_infiller):
    _, out = tiny_learned
    forced = Refiner.load(out)
    if not with_infiller:
        forced.motion_infiller = None  # weights without it: the repair network's in-fill stands in
    given = forced.flaw_classifier.predict_all

    def flag_middle(x):  # frames 10-29 flagged: an in-fill needs kept frames to in-fill from
        p = given(x).copy()
        p[..., 0] = 0.0
        p[:, 10:30, 0] = 1.0
        return p

    forced.flaw_classifier.predict_all = flag_middle
    forced.denoising = "flagged"  # the typed repairs alone (not the last step for clips noisy throughout)
    for group in learned_pipeline.TYPED_REPAIRS:
        monkeypatch.setitem(learned_pipeline.TYPED_REPAIRS, group, ("motion_infill", 0))
    monkeypatch.setattr(learned_pipeline, "VERIFY_TYPED", ())
    monkeypatch.setattr(learned_pipeline, "NOISE_RATIO", 0.0)
    clips = np.stack([humanact12[i].joints[:40] for i in (5, 60)])
    result, reports = forced.refine(clips, return_report=True)
    assert result.shape == clips.shape and np.isfinite(result).all()
    names = {c.get("repair") for r in reports for c in r.changes} - {None}
    assert names == {"motion_infill" if with_infiller else "network_infill"}, names


def test_norms_are_numpys_norms_bit_for_bit():
    from refiner.core.signal import norms

    rng = np.random.default_rng(3)
    for dtype in (np.float32, np.float64):
        for shape in ((5, 7, 24, 3), (40, 2), (3,), (4, 9)):  # 9 components: numpy's own (pairwise) sum
            v = rng.normal(size=shape).astype(dtype)
            out = norms(v)
            assert out.dtype == dtype and out.shape == shape[:-1]
            np.testing.assert_array_equal(out, np.linalg.norm(v, axis=-1))
    np.testing.assert_array_equal(norms(np.array([[3, 4], [6, 8]])), [5.0, 10.0])  # integers as float64
