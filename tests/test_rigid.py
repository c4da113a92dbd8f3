"""The rigid core of a mocap clip edited in places: exact frames found even when few, blended poses rebuilt from
the root outward, noise projected."""
import numpy as np
import pytest

import refiner.core.rigid as rigid
from refiner.core.rigid import rigid_core, rigid_skeleton
from refiner.core.skeletons import bone_lengths


def test_a_few_exact_frames_make_a_core_and_near_ones_do_not(rng):
    base = rng.uniform(0.05, 0.4, 23)
    u = np.linspace(0, 1, 30)[:, None]
    blended = base * (1 - 0.6 * (0.5 + u) * np.sin(np.pi * u) ** 2)  # blended toward another pose but at both ends
    core = rigid_core(blended)
    assert core is not None and np.array_equal(np.flatnonzero(core), [0, 29])
    assert rigid_core(blended, exact=None) is None  # the share rule alone: two frames of thirty are too few
    drifting = base * (1 + 0.05 * u * rng.uniform(-1, 1, 23))  # a generator's slow stretch: no two frames agree
    assert rigid_core(drifting) is None
    close = blended.copy()
    close[29] = close[0] * (1 + 5e-4)  # within the core's tolerance of each other, but not exact: no core
    assert rigid_core(close) is None


def test_a_held_pose_is_no_core(rng):
    """A clip whose bones vary (CMU's processed joints) repeats its lengths exactly where a pose is held; with the
    poses given, only exact frames that hold different poses make a core."""
    base = rng.uniform(0.05, 0.4, 23)
    lengths = base * (1 + 0.02 * rng.standard_normal((30, 23)))
    poses = np.cumsum(rng.normal(0, 0.01, (30, 24, 3)), axis=0)
    lengths[10:16], poses[10:16] = lengths[10], poses[10]  # a frozen transition: six copies of one frame
    assert rigid_core(lengths) is not None  # the lengths alone read the copies as exact mocap
    assert rigid_core(lengths, poses=poses) is None
    lengths[25] = lengths[10]  # the same bones in a pose far from the held one: a core again
    poses[25] = poses[10] + 0.05
    core = rigid_core(lengths, poses=poses)
    assert core is not None and core[[10, 25]].all()


def _blended(humanact12):
    """A held-out clip's 40 frames with every frame but the first and last blended (smoothstep, up to 70 %) toward a
    pose of another subject's clip, root path kept; and the clean clip."""
    clip = humanact12[int(np.flatnonzero(humanact12.subjects == 11)[2])].joints[:40].astype(np.float64)
    donor = humanact12[int(np.flatnonzero(humanact12.subjects == 3)[0])].joints[20].astype(np.float64)
    u = np.linspace(0, 1, 40)
    w = 0.7 * (3 * (1 - np.abs(2 * u - 1)) ** 2 - 2 * (1 - np.abs(2 * u - 1)) ** 3)
    rel = clip - clip[:, :1]
    edited = clip[:, :1] + (1 - w[:, None, None]) * rel + w[:, None, None] * (donor - donor[:1])
    return clip, edited


@pytest.mark.real_data
def test_a_blended_pose_is_rebuilt_outward_and_noise_is_projected(humanact12, rng, monkeypatch):
    clip, edited = _blended(humanact12)
    assert bone_lengths(edited[[0, -1]], "humanact12").std(0).max() < 1e-6
    rebuilt, variation = rigid_skeleton(edited, "humanact12", 0.005, keep_core=True)
    assert variation > 0.05
    np.testing.assert_array_equal(rebuilt[[0, -1]], edited[[0, -1]])  # the exact frames are the core: kept
    np.testing.assert_allclose(bone_lengths(rebuilt, "humanact12"), bone_lengths(clip, "humanact12"), rtol=3e-3)
    err = lambda a: np.linalg.norm(a - clip, axis=-1).mean()  # noqa: E731
    monkeypatch.setattr(rigid, "BLEND_AUTOCORRELATION", np.inf)
    projected = rigid_skeleton(edited, "humanact12", 0.005, keep_core=True)[0]
    assert err(rebuilt) < err(projected) - 0.002, (err(rebuilt), err(projected))  # the blend's directions kept
    noisy = clip.copy()
    noisy[10:30] += rng.normal(0, 0.01, noisy[10:30].shape)  # white noise: its bones jump from frame to frame
    alone = rigid_skeleton(noisy, "humanact12", 0.005, keep_core=True)[0]
    monkeypatch.undo()
    np.testing.assert_array_equal(rigid_skeleton(noisy, "humanact12", 0.005, keep_core=True)[0], alone)  # projected


@pytest.mark.real_data
def test_smooth_noise_on_each_joint_is_projected_not_rebuilt(humanact12, rng, monkeypatch):
    """Low-frequency noise deviates smoothly like a blend, but each joint on its own: no one profile in time carries
    its bone deviations (``BLEND_PROFILE``), so it is projected; rebuilt outward, each joint's noise reached its
    descendants."""
    from scipy.ndimage import gaussian_filter1d

    clip, edited = _blended(humanact12)
    dev = lambda x: bone_lengths(x, "humanact12")[1:-1] / bone_lengths(clip[:1], "humanact12") - 1  # noqa: E731
    assert rigid._one_profile(dev(edited)) > 0.9
    noisy = clip.copy()
    noisy[8:32] += 3 * gaussian_filter1d(rng.normal(0, 0.03, noisy[8:32].shape), 3, axis=0)
    assert rigid._one_profile(dev(noisy)) < rigid.BLEND_PROFILE
    err = lambda a: np.linalg.norm(a - clip, axis=-1).mean()  # noqa: E731
    out = rigid_skeleton(noisy, "humanact12", 0.005, keep_core=True)[0]
    monkeypatch.setattr(rigid, "BLEND_PROFILE", 0.0)  # the release before: rebuilt
    rebuilt = rigid_skeleton(noisy, "humanact12", 0.005, keep_core=True)[0]
    assert err(out) < err(noisy) < err(rebuilt), (err(out), err(noisy), err(rebuilt))


@pytest.mark.real_data
def test_refine_leaves_a_blended_clips_exact_frames_to_the_core_not_the_pose_prior(humanact12):
    """A clip with exact bones in some frames was edited in places: the pose prior's drift gate, which refits every
    frame, stays off (it moved the exact frames of the benchmark's wrong anchors), and the output is nearer the
    clean clip than the edit."""
    from refiner.refinement.pipeline import Refiner

    clip, edited = _blended(humanact12)
    out, report = Refiner.pretrained("humanact12", split="train").refine(edited.astype(np.float32), return_report=True)
    assert "pose" not in [c["step"] for c in report.changes]
    np.testing.assert_allclose(out[[0, -1]], edited[[0, -1]], atol=1e-5)  # the exact frames stay (a re-timing: < 1e-6)
    err = lambda a: np.linalg.norm(a - clip, axis=-1).mean()  # noqa: E731
    assert err(out) < err(edited), (err(out), err(edited))


@pytest.mark.real_data
def test_noise_leaves_the_core_roughly_and_a_blend_or_a_drift_smoothly(humanact12, rng):
    """``rough_bones``: white noise on a clip's frames 10-29 stretches and shrinks its bones frame by frame (over
    2 %, the refiner's ``NOISY_BONES``), a pose blended toward another's or a slow drift changes them smoothly;
    the core and a clip with no core read 0."""
    from refiner.core.rigid import rough_bones
    from refiner.refinement.rigid_step import NOISY_BONES

    clip, edited = _blended(humanact12)
    noisy = clip.copy()
    noisy[10:30] += rng.normal(0, 0.01, noisy[10:30].shape)
    rough = rough_bones(noisy, "humanact12")
    assert (rough[11:29] > NOISY_BONES).all() and (rough[:9] == 0).all() and (rough[31:] == 0).all()
    assert rough_bones(edited, "humanact12").max() < 0.5 * NOISY_BONES
    ramp = np.clip(np.linspace(-0.2, 1, 40), 0, 1) ** 2  # joints drifting apart after frame 6, about 1 cm each axis
    drift = clip + ramp[:, None, None] * rng.normal(0, 0.01, (1, 24, 3))
    assert rough_bones(drift, "humanact12").max() < 0.5 * NOISY_BONES
    no_core = noisy + rng.normal(0, 0.01, noisy.shape)
    np.testing.assert_array_equal(rough_bones(no_core, "humanact12"), 0.0)
    assert (rough_bones(no_core, "humanact12", natural=True)[1:-1] > NOISY_BONES).all()  # against its median lengths


@pytest.mark.real_data
def test_noise_the_classifier_misses_is_denoised_where_the_bones_show_it(humanact12, monkeypatch):
    """Held-out clip 6 jittered (the benchmark's recipe, seed 6): the flaw classifier finds no noise run, but its
    noisy frames leave the clip's rigid core roughly, so the noise step denoises them (0.29 -> 0.21 cm)."""
    from refiner.concepts.segmentation import segment
    from refiner.evaluation.flaws import corrupt
    from refiner.refinement import rigid_step
    from refiner.refinement.pipeline import Refiner

    clean = humanact12.split("test").motions[6]
    flawed = corrupt(clean, "transition_jitter", 2, random_state=6, segmentation=segment(clean.joints)).motion
    model = Refiner.pretrained("humanact12", split="train")
    out, report = model.refine(flawed, action=clean.action, return_report=True)
    noise = [c for c in report.changes if c.get("repair") == "noise_filter"]
    assert noise and all("bones changed length roughly" in c["reason"] for c in noise)
    err = lambda m: np.linalg.norm(m.joints - clean.joints, axis=-1).mean()  # noqa: E731
    monkeypatch.setattr(rigid_step, "NOISY_BONES", None)
    assert err(out) < 0.8 * err(model.refine(flawed, action=clean.action))


@pytest.mark.real_data
def test_a_spike_is_put_back_between_its_neighbours_not_carried_to_the_children(humanact12, rng, monkeypatch):
    """A 5 cm spike on the left elbow (frame 12) and on the root (frames 25-26) of an exact clip: each joint, off the
    core alone, is put back between the frames around it (``SPIKE_FRAMES``); rebuilt outward, the elbow's spike
    moved the wrist and hand too. ``refine`` removes most of the spikes' error (it tripled it before)."""
    from refiner.refinement.pipeline import Refiner

    clip = next(m for m in humanact12.split("test").motions if m.n_frames >= 40).joints[:40].astype(np.float64)
    spiked = clip.copy()
    spiked[12, 18] += [0.05, -0.03, 0.02]
    spiked[25:27, 0] += [-0.04, 0.03, 0.03]
    err = lambda a: np.linalg.norm(a - clip, axis=-1).mean()  # noqa: E731
    fixed = rigid_skeleton(spiked, "humanact12", 0.005, keep_core=True, spikes=True)[0]
    assert err(fixed) < 0.5 * err(spiked)
    rebuilt = rigid_skeleton(spiked, "humanact12", 0.005, keep_core=True)[0]  # the release before: rebuilt outward
    assert err(rebuilt) > err(spiked)
    monkeypatch.setattr(rigid, "SPIKE_FRAMES", 0)
    np.testing.assert_array_equal(rigid_skeleton(spiked, "humanact12", 0.005, keep_core=True, spikes=True)[0], rebuilt)
    monkeypatch.undo()
    out = Refiner.pretrained("humanact12", split="train").refine(spiked.astype(np.float32))
    assert err(out) < 0.5 * err(spiked)


@pytest.mark.parametrize("skeleton, joint", [("uestc", 3), ("cmu_mocap", 2)])
def test_a_spike_in_a_masked_layout_moves_no_other_joint(skeleton, joint):
    """With a layout's flexible bones left free (``bones=``), a joint left with a single bone, to a child, is not
    read as spiked when that child spikes: only the spiked joint moves (the neighbour moved 3-4 mm before)."""
    from scipy.spatial.transform import Rotation

    from refiner.core.skeletons import get_skeleton
    from refiner.refinement.converted_refinement import FLEXIBLE_BONES

    skel = get_skeleton(skeleton)
    rng = np.random.default_rng(0)
    rest = np.zeros((skel.n_joints, 3))
    for j, p in enumerate(skel.parents):
        if p >= 0:
            rest[j] = rest[p] + 0.15 * rng.normal(size=3) / np.sqrt(3)
    clip = np.zeros((40, skel.n_joints, 3))  # rigid bones, every joint turning a little over time
    for t in range(40):
        for j, p in enumerate(skel.parents):
            turn = Rotation.from_rotvec(0.3 * np.sin(0.1 * t + j) * np.array([1, 0.5, 0.2]))
            clip[t, j] = [0.01 * t, 0, 0] if p < 0 else clip[t, p] + turn.apply(rest[j] - rest[p])
    spiked = clip.copy()
    spiked[12, joint] += [0.05, -0.03, 0.02]
    free = {frozenset(pair) for pair in FLEXIBLE_BONES.get(skeleton, ())}
    mask = np.array([frozenset((skel.joint_names[a], skel.joint_names[b])) not in free for a, b in skel.bones])
    assert not mask.all()
    out = rigid_skeleton(spiked, skeleton, 0.005, bones=mask, keep_core=True, spikes=True)[0]
    moved = np.linalg.norm(out[12] - clip[12], axis=-1)
    assert moved[joint] < 0.01 * np.linalg.norm([0.05, -0.03, 0.02]) and np.delete(moved, joint).max() < 1e-3
