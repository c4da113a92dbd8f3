"""Training flaws: every mechanism changes only the frames it reports, deterministically, and never a held-out one."""
import numpy as np
import pytest

from refiner.evaluation.flaws import FLAW_FAMILIES
from refiner.refinement.training_flaws import (HELD_OUT_FAMILIES, MECHANISMS, TRAINING_FAMILIES, limb_joints, mirror_pairs,
                                    synthesize)


@pytest.fixture(scope="module")
def walk(humanact12):
    clip = humanact12[int(np.flatnonzero(humanact12.actions == 1)[0])].joints[:60]
    return clip - clip[:1, :1]


def test_families_split_into_training_and_held_out():
    assert set(HELD_OUT_FAMILIES) | set(TRAINING_FAMILIES) == set(FLAW_FAMILIES)
    assert not set(HELD_OUT_FAMILIES) & set(TRAINING_FAMILIES) and len(HELD_OUT_FAMILIES) >= 2


@pytest.mark.real_data
@pytest.mark.parametrize("kind", MECHANISMS)
def test_each_mechanism_touches_only_its_mask(walk, kind):
    rng = np.random.default_rng(3)
    donor = walk[::-1].copy()
    flaw = synthesize(walk, rng, kinds=[kind], clean_probability=0.0, max_flaws=1, donors=[donor])
    assert flaw.kinds == (kind,) and flaw.joints.shape == walk.shape and flaw.joints.dtype == np.float32
    np.testing.assert_array_equal(flaw.joints[~flaw.touched], walk[~flaw.touched])
    moved = np.linalg.norm(flaw.joints - walk, axis=-1).mean(-1)
    assert flaw.touched.any() and moved[flaw.touched].max() > 1e-3, kind  # a real change, in metres
    again = synthesize(walk, np.random.default_rng(3), kinds=[kind], clean_probability=0.0, max_flaws=1,
                       donors=[donor])
    np.testing.assert_array_equal(again.joints, flaw.joints)


@pytest.mark.real_data
def test_retimings_never_play_backwards(walk):
    """The held-out `reversed_transition` mechanism must not sneak into training: time only moves forward."""
    t = np.arange(len(walk), dtype=np.float64)
    ramp = np.repeat(t[:, None, None], 24, 1).repeat(3, 2) * 0.01  # joints move forward with time
    for seed in range(40):
        for kind in ("hold", "stall", "time_warp", "stutter"):
            f = synthesize(ramp, np.random.default_rng(seed), kinds=[kind], clean_probability=0.0, max_flaws=1)
            assert (np.diff(f.joints[:, 0, 0]) >= -1e-6).all(), (kind, seed)


def test_no_training_flaw_moves_the_body_horizontally(rng):
    """The held-out `foot_sliding` mechanism: whole-body shifts in training are vertical (y) only."""
    still = np.zeros((40, 24, 3))
    still[:, :, 1] = np.linspace(-1.0, 0.0, 24)
    for kind in ("float", "sink_drift"):
        f = synthesize(still, rng, kinds=[kind], clean_probability=0.0, max_flaws=1)
        np.testing.assert_array_equal(f.joints[..., [0, 2]], still[..., [0, 2]].astype(np.float32))
        assert np.abs(f.joints[..., 1] - still[..., 1]).max() > 0.01
    # a limb offset or drift moves a limb, never the root: a whole-body offset would be a glide
    moved_root = moved_limb = 0
    for seed in range(60):
        for kind in ("limb_offset", "limb_drift"):
            f = synthesize(still, np.random.default_rng(seed), kinds=[kind], clean_probability=0.0, max_flaws=1)
            moved_root += int(np.abs(f.joints[:, 0] - still[:, 0]).max() > 0)
            moved_limb += int(np.abs(f.joints - still).max() > 0.005)
    assert moved_root == 0 and moved_limb > 100


def test_mirror_pairs_and_limbs():
    pairs = mirror_pairs("humanact12")
    assert pairs[1] == 2 and pairs[2] == 1 and pairs[0] == 0 and pairs[20] == 21  # hips, pelvis, wrists
    assert (pairs[pairs] == np.arange(24)).all()
    np.testing.assert_array_equal(limb_joints("humanact12", 18), [18, 20, 22])  # left elbow, wrist, hand


def test_bad_input_is_refused(rng):
    with pytest.raises(ValueError, match="T >= 8"):
        synthesize(np.zeros((5, 24, 3)), rng)
    with pytest.raises(ValueError, match="unknown flaw mechanisms"):
        synthesize(np.zeros((20, 24, 3)), rng, kinds=["reverse"])
    clean = synthesize(np.ones((20, 24, 3)), rng, clean_probability=1.0)
    assert clean.kinds == () and not clean.touched.any()


@pytest.mark.real_data
def test_flaw_batches_can_put_flawed_crops_on_rigid_bones(humanact12):
    from refiner.evaluation.physics import bone_length_variation
    from refiner.refinement.flaw_training import FlawBatches

    clips = [m.joints for m in humanact12.motions[:40]]
    kinds = ["bone_stretch", "white_noise"]
    raw = FlawBatches(clips, None, None, lengths=(48, 48), kinds=kinds, n_actions=1).sample(np.arange(16), np.random.default_rng(0))
    rigid = FlawBatches(clips, None, None, lengths=(48, 48), kinds=kinds, n_actions=1,
                        rigid_tolerance=0.005).sample(np.arange(16), np.random.default_rng(0))
    np.testing.assert_array_equal(raw["clean"].numpy(), rigid["clean"].numpy())  # same crops, same flaws
    full = rigid["valid"].numpy().all(1)
    var_raw = [bone_length_variation(x) for x in raw["flawed"].numpy()[full]]
    var_rigid = [bone_length_variation(x) for x in rigid["flawed"].numpy()[full]]
    assert max(var_raw) > 0.02 and max(var_rigid) < 0.01
