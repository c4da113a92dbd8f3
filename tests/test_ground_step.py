"""The support steps on real HumanAct12 clips: a body raised off its floor goes back onto it, a tilted floor is
found, a jump, a sunk body or one limb off the floor is left alone; a gliding body is slid back, one foot sliding
alone is not; clean clips are left as given."""
from __future__ import annotations

import json

import numpy as np
import pytest

from refiner.core.skeletons import get_skeleton
from refiner.refinement.motion_refiner import MotionRefiner
from refiner.core.floor import floor_gap, floor_plane
from refiner.refinement.steps.ground import GlideConfig, GlideStep, GroundConfig, GroundStep, calibrated_glide, calibrated_ground
from refiner.refinement.steps.infill import InfillConfig

pytestmark = pytest.mark.real_data
SKEL = get_skeleton("humanact12")
UP = SKEL.up_vector
CONFIG = GroundConfig(float_m=0.045)


@pytest.fixture(scope="module")
def walks(humanact12):
    """Real clips of the held-out subjects standing on the floor (no jump, no chair), 60 frames or more, float64."""
    test = humanact12.split("test")
    return [np.asarray(m.joints, np.float64) for m in test if m.action not in (3, 6) and m.n_frames >= 60]


def _bump(n, start, stop, metres):
    """``(n,)`` a smooth bump of ``metres`` over ``[start, stop)``."""
    t = np.arange(n)
    return metres * np.clip(np.minimum(t - start + 1, stop - t) / 4, 0, 1) ** 2


def _refined(clip):
    out, changes, _ = GroundStep("humanact12", CONFIG).refine(clip[None])
    return out[0], changes[0]


def test_clean_walks_are_left_as_given(walks):
    touched = [np.abs(_refined(c)[0] - c).max() > 0 for c in walks]
    assert len(walks) >= 100 and np.mean(touched) <= 0.05


@pytest.mark.parametrize("metres", [0.08, 0.12])
def test_a_raised_body_goes_back_on_its_floor(walks, metres):
    fixed = 0
    for clip in walks[:30]:
        moved = clip + _bump(len(clip), 20, 40, metres)[:, None, None] * UP
        given = moved.copy()
        out, changes = _refined(moved)
        np.testing.assert_array_equal(moved, given)  # the input is not modified
        kept = np.zeros(len(clip), bool)
        for e in changes:
            kept[e["start"]:e["stop"]] |= e["kept"]
        np.testing.assert_array_equal(out[~kept], moved[~kept])  # frames of no kept run as given
        horizontal = lambda x: x - (x @ UP)[..., None] * UP  # noqa: E731
        np.testing.assert_allclose(horizontal(out), horizontal(moved), atol=1e-9)  # only the vertical changes
        np.testing.assert_allclose(out - out[:, :1], moved - moved[:, :1], atol=1e-9)  # every pose kept
        before = np.linalg.norm(moved - clip, axis=-1).mean()
        after = np.linalg.norm(out - clip, axis=-1).mean()
        fixed += after < 0.5 * before
        assert after <= before + 1e-9
        assert all(e["step"] == "ground" for e in changes)
    assert fixed >= 15


def test_a_tilted_floor_is_found(walks):
    clip = max(walks, key=lambda c: np.ptp(c[:, SKEL.root, 0]))  # the clip that covers most floor along x
    basis = np.stack([[1.0, 0, 0], [0, 0, 1.0]])
    tilted = clip + 0.15 * (clip @ basis[0])[..., None] * UP  # the floor rises 15 cm a metre along x
    slope = floor_plane(tilted, SKEL)[1:] - floor_plane(clip, SKEL)[1:]
    assert abs(np.hypot(*slope) - 0.15) < 0.03
    assert np.quantile(np.abs(floor_gap(tilted, SKEL)), 0.9) < 0.05


def test_a_ballistic_jump_is_left_alone(walks):
    clip = walks[1]
    t = np.arange(len(clip)) / SKEL.fps
    flight = np.clip(1.6 * (t - t[20]) - 0.5 * 9.81 * (t - t[20]) ** 2, 0, None) * (t >= t[20])  # 0.33 s, 13 cm
    jumped = clip + flight[:, None, None] * UP
    out, _ = _refined(jumped)
    assert flight.max() > 0.1
    np.testing.assert_array_equal(out[15:35], jumped[15:35])


@pytest.mark.parametrize("joints, metres", [(("left_knee", "left_ankle", "left_foot"), 0.1), (None, -0.08)])
def test_one_leg_off_the_floor_or_a_sunk_body_is_left_alone(walks, joints, metres):
    clip = walks[2]
    moved = clip.copy()
    which = slice(None) if joints is None else [SKEL.index(n) for n in joints]
    moved[:, which] += _bump(len(clip), 20, 40, metres)[:, None, None] * UP
    out, _ = _refined(moved)
    np.testing.assert_array_equal(out[15:45], moved[15:45])


def test_calibration_keeps_clean_clips_and_refuses_two_floors(walks):
    float_m = calibrated_ground(walks, SKEL)
    assert CONFIG.least_float_m <= float_m < 0.25
    on_a_step = [c + (0.4 * (np.arange(len(c)) >= len(c) // 2))[:, None, None] * UP for c in walks]
    assert calibrated_ground(on_a_step, SKEL) is None  # a body 40 cm off its floor for half of every clip


def test_the_shipped_refiner_runs_the_support_step_first():
    from refiner.refinement.motion_refiner import _WEIGHTS

    manifest = json.loads((_WEIGHTS / "humanact12-motion" / "manifest.json").read_text())
    refiner = MotionRefiner.pretrained("humanact12")
    assert [s.name for s in refiner.steps] == ["ground", "glide", "retime"]
    assert refiner.steps[0].config == GroundConfig(**manifest["ground"])
    assert refiner.steps[1].config == GlideConfig(**manifest["glide"])
    assert [s.name for s in MotionRefiner.pretrained("cmu_mocap").steps] == ["retime"]  # CMU stands on stairs, ladders
    assert MotionRefiner(refiner.model, InfillConfig(threshold=0.5)).steps[0].name == "retime"


def test_the_report_names_a_floating_stretch(walks):
    clip = walks[3]
    raised = (clip + _bump(len(clip), 20, 40, 0.1)[:, None, None] * UP).astype(np.float32)
    out, report = MotionRefiner.pretrained("humanact12").refine(raised, return_report=True)
    ground = [c for c in report.changes if c["step"] == "ground"]
    assert ground and ground[0]["parts"] == ["root"] and "floor" in ground[0]["reason"]
    assert np.linalg.norm(out - clip, axis=-1).mean() < np.linalg.norm(raised - clip, axis=-1).mean()


GLIDE = GlideConfig(glide_m=0.07)


def _slid(clip, metres, joints=None):
    """``clip`` with the body (or only ``joints``) slid ``metres`` along x and back over frames 20-40."""
    out = clip.copy()
    which = slice(None) if joints is None else [SKEL.index(n) for n in joints]
    out[:, which] += _bump(len(clip), 20, 40, metres)[:, None, None] * np.array([1.0, 0.0, 0.0])
    return out


def test_a_gliding_body_is_slid_back_and_clean_clips_are_not(walks):
    step = GlideStep("humanact12", GLIDE)
    touched = [np.abs(step.refine(c[None])[0][0] - c).max() > 0 for c in walks]
    assert np.mean(touched) <= 0.05
    fixed = 0
    for clip in walks[:30]:
        slid = _slid(clip, 0.15)
        given = slid.copy()
        out, changes, _ = step.refine(slid[None])
        out = out[0]
        np.testing.assert_array_equal(slid, given)
        np.testing.assert_allclose(out @ UP, slid @ UP, atol=1e-9)  # heights kept
        np.testing.assert_allclose(out - out[:, :1], slid - slid[:, :1], atol=1e-9)  # every pose kept
        after, before = np.linalg.norm(out - clip, axis=-1).mean(), np.linalg.norm(slid - clip, axis=-1).mean()
        assert after <= before + 1e-9
        fixed += after < 0.6 * before
    assert fixed >= 10


def test_one_foot_sliding_alone_is_not_a_glide(walks):
    step = GlideStep("humanact12", GLIDE)
    moved = []
    for clip in walks[:20]:
        slid = _slid(clip, 0.15, joints=("left_ankle", "left_foot"))
        moved.append(np.abs(step.refine(slid[None])[0][0][20:40] - slid[20:40]).max() > 0)
    assert sum(moved) <= 2


def test_glide_calibration_flags_few_clean_pieces(walks):
    glide_m = calibrated_glide(walks, SKEL)
    assert 0.01 < glide_m < 0.25
    assert calibrated_glide(walks, SKEL, share=0.5) < glide_m


def test_grown_runs_need_min_run_frames_and_grow_to_their_edges():
    from refiner.refinement.steps.ground import grown_runs

    size = np.array([0, 0.02, 0.06, 0.1, 0.1, 0.06, 0.02, 0, 0.2, 0, 0.03, 0.1, 0.1, 0.1, 0.1])
    assert grown_runs(size, 0.05, 3, 0.25) == [(1, 7), (10, 14)]  # the lone frame 8 is too short; never the last
    assert grown_runs(size, 0.05, 5, 0.25) == []
