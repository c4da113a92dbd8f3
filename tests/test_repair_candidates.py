"""Hand-written repairs of flagged runs and the planted-feet evidence they use, on real clips."""
import numpy as np
import pytest
from conftest import shared_data_dir

from refiner.core.contact import planted_feet, planted_slip
from refiner.evaluation.flaws import corrupt, foot_sliding, frozen_transition, transition_jitter
from refiner.io.datasets import load_cmu_mocap
from refiner.refinement.pipeline import splice
from refiner.refinement.repair_candidates import (CANDIDATES, grounded_run, planted_feet_run, smooth_run, spline_run,
                                                 stall_retime_run, stall_window)
from refiner.core.skeletons import get_skeleton

SKEL = get_skeleton("humanact12")


def _runs(mask):
    edges = np.flatnonzero(np.diff(np.r_[False, mask, False].astype(int)))
    return list(zip(edges[::2], edges[1::2]))


def _repaired(fn, flawed, mask):
    out = flawed.copy()
    for lo, hi in _runs(mask):
        out = splice(out, fn(out, lo, hi, SKEL), lo, hi, blend=4, keep_start=lo > 0, keep_end=hi < len(out))
    return out


def _err(a, b):
    return 100 * float(np.linalg.norm(a - b, axis=-1).mean())


@pytest.fixture(scope="module")
def walks(humanact12):
    """Twelve real clips of the first action (warm-up: the feet stay on the ground), 60+ frames."""
    idx = [i for i in np.flatnonzero(humanact12.actions == 0) if humanact12[int(i)].n_frames >= 60][:12]
    return [humanact12[int(i)] for i in idx]


@pytest.mark.real_data
def test_planted_feet_and_slip_on_real_clips(walks):
    clip = walks[0].joints
    planted = planted_feet(clip, "humanact12")
    assert planted.shape == (len(clip), 2) and planted.any(0).all()  # each foot touches down
    slip = planted_slip(clip, "humanact12")
    assert slip.shape == (len(clip) - 1, 3)
    assert np.abs(slip @ SKEL.up_vector).max() < 1e-9  # horizontal only
    moved = clip + np.array([0.0, 0.0, 0.01]) * np.arange(len(clip))[:, None, None]  # the whole body glides 1 cm/frame
    glide = planted_slip(moved, "humanact12")
    has = planted_feet(moved, "humanact12")[1:].any(1) & planted_feet(moved, "humanact12")[:-1].any(1)
    np.testing.assert_allclose(glide[has] - slip[has], np.array([0.0, 0.0, 0.01])[None].repeat(has.sum(), 0), atol=1e-9)


@pytest.mark.real_data
def test_planted_feet_run_undoes_a_glide_and_leaves_clean_clips(walks):
    before, after, clean_moved = [], [], []
    for i, m in enumerate(walks):
        c = foot_sliding(m, 2, random_state=i)
        fixed = _repaired(planted_feet_run, c.motion.joints, c.mask)
        before.append(_err(c.motion.joints, m.joints))
        after.append(_err(fixed, m.joints))
        lo, hi = _runs(c.mask)[0]
        clean_moved.append(_err(planted_feet_run(m.joints, lo, hi, SKEL), m.joints))
    assert np.mean(after) < 0.5 * np.mean(before)  # more than half of the glide's error removed
    assert np.mean(clean_moved) < 0.1 * np.mean(before)


@pytest.mark.real_data
def test_grounded_run_brings_a_floating_body_down_and_leaves_a_wrong_pose(walks):
    """A body raised 10 cm (root and feet alike) comes back down; feet lifted against a root that stays (a wrong pose),
    a clean clip and a body raised under ``min_shift`` are left alone."""
    up = SKEL.up_vector
    before, after = [], []
    for m in walks:
        x = m.joints.astype(np.float64)
        w = np.zeros(len(x))
        w[20:40] = np.sin(np.linspace(0, np.pi, 22)[1:-1])
        raised = x + 0.10 * w[:, None, None] * up
        fixed = splice(raised, grounded_run(raised, 18, 42, SKEL), 18, 42, blend=4, keep_start=True, keep_end=True)
        before.append(_err(raised, x))
        after.append(_err(fixed, x))
        np.testing.assert_array_equal(grounded_run(x, 18, 42, SKEL), x)  # the clean clip
        slight = x + 0.03 * w[:, None, None] * up
        np.testing.assert_array_equal(grounded_run(slight, 18, 42, SKEL), slight)
        feet = x.copy()
        feet[:, 1:] += 0.10 * w[:, None, None] * up  # every joint but the root: the root stays, so no body rises
        np.testing.assert_array_equal(grounded_run(feet, 18, 42, SKEL), feet)
    assert np.mean(after) < 0.2 * np.mean(before), (np.mean(after), np.mean(before))


def test_typed_alternatives_go_to_the_classifier_and_need_a_verified_group(rng, monkeypatch):
    from types import SimpleNamespace

    import refiner.refinement.learned_pipeline as lp

    assert "|" in lp.TYPED_REPAIRS["root"][0] and "root" in lp.VERIFY_TYPED
    y = (np.cumsum(rng.normal(0, 0.01, (40, 24, 3)), 0) + rng.normal(0, 0.01, (40, 24, 3))).astype(np.float32)
    smooth = smooth_run(y, 10, 20, SKEL)
    groups = np.zeros((40, 4))
    groups[:, list(lp.TYPED_REPAIRS).index("noise")] = 0.9
    monkeypatch.setattr(lp, "NOISE_RATIO", 0.0)
    monkeypatch.setattr(lp, "TYPED_REPAIRS", {**lp.TYPED_REPAIRS, "noise": ("root_infill|smooth", 0)})
    refiner = SimpleNamespace(repair="typed", blend=4, change_penalty=0.0, flaw_classifier=_Judge(smooth, 1.0),
                              skeleton="humanact12")
    with pytest.raises(ValueError, match="alternatives need the group 'noise' verified"):
        lp._repair_run(refiner, y, 10, 20, {}, groups, y, SKEL)
    monkeypatch.setattr(lp, "VERIFY_TYPED", ("noise",))
    name, _, out, note = lp._repair_run(refiner, y, 10, 20, {}, groups, y, SKEL)
    assert name == "smooth" and "chosen among 3 candidates" in note  # the judge likes the smoothed clip best
    refiner.flaw_classifier = _Judge(CANDIDATES["root_infill"](y, 10, 20, SKEL), 1.0)
    assert lp._repair_run(refiner, y, 10, 20, {}, groups, y, SKEL)[0] == "root_infill"


@pytest.mark.real_data
def test_stall_retime_fixes_stalls_and_leaves_moving_runs(walks):
    before, after = [], []
    for i, m in enumerate(walks):
        c = frozen_transition(m, 2, random_state=i)
        before.append(_err(c.motion.joints, m.joints))
        after.append(_err(_repaired(stall_retime_run, c.motion.joints, c.mask), m.joints))
        lo, hi = _runs(c.mask)[0]
        assert np.array_equal(stall_retime_run(m.joints, lo, hi, SKEL), m.joints) or _err(
            stall_retime_run(m.joints, lo, hi, SKEL), m.joints) < 0.5  # a real run rarely stalls
    assert np.mean(after) < 0.75 * np.mean(before)


@pytest.mark.real_data
def test_a_rest_nothing_catches_up_with_is_not_retimed(walks):
    """A clip that comes to rest at its end stops without a rush after it: no stall flaw, left alone;
    the same stop followed by a rush (a frozen transition) is re-timed."""
    m = walks[0].joints
    rest = np.concatenate([m[:40], np.repeat(m[39:40], 12, 0)])  # moves, then holds still to the end
    np.testing.assert_array_equal(stall_retime_run(rest, 30, len(rest), SKEL), rest)
    assert not np.array_equal(stall_retime_run(rest, 30, len(rest), SKEL, rush=None), rest)  # the old rule re-timed it
    frozen = frozen_transition(walks[0], 2, random_state=0)
    lo, hi = _runs(frozen.mask)[0]
    assert not np.array_equal(stall_retime_run(frozen.motion.joints, lo, hi, SKEL), frozen.motion.joints)


@pytest.mark.real_data
def test_a_standing_start_caught_up_with_late_is_not_retimed():
    """A CMU walk that starts standing and reaches its rush 55 frames later (time-warped there): no stall flaw, kept;
    the rule before (a rush anywhere later in the run) re-timed the whole clip, 40 cm per frame further from the truth."""
    clips = [m for m in load_cmu_mocap(shared_data_dir() / "cmu_mocap" / "cmu_mocap_labeled_joints.npz").split("test")
             if len(m.joints) >= 120]
    walk = clips[56].with_joints(clips[56].joints[:120])
    warped = corrupt(walk, "time_warp", 2, random_state=28).motion.joints
    skel = get_skeleton("cmu_mocap")
    np.testing.assert_array_equal(stall_retime_run(warped, 1, 120, skel), warped)
    assert _err(stall_retime_run(warped, 1, 120, skel, rush_within=None), walk.joints) > 2 * _err(warped, walk.joints)


@pytest.mark.real_data
def test_a_frozen_stall_after_a_slow_start_is_still_retimed(walks):
    """Every stop of the run is asked for its rush, not the first alone: a clip that rests first and only speeds up
    slowly, then freezes a transition and rushes, is re-timed."""
    from refiner.refinement.repair_candidates import RUSH_WITHIN, frame_speed

    frozen = frozen_transition(walks[5], 2, random_state=0).motion.joints
    y = np.concatenate([np.repeat(frozen[:1], 8, 0), frozen])  # a rest at the start
    speed, median = frame_speed(y)
    assert not (speed[8 : 8 + RUSH_WITHIN] > 1.5 * median).any()  # the first stop is caught up with late
    assert not np.array_equal(stall_retime_run(y, 0, len(y), SKEL), y)


@pytest.mark.real_data
def test_stall_window_reaches_over_the_stall_and_the_rush(walks):
    flawed_growth, clean_growth, covered = [], [], []
    for i, m in enumerate(walks):
        c = frozen_transition(m, 3, random_state=i)
        lo, hi = _runs(c.mask)[0]
        start = lo + (hi - lo) // 3  # a detector that saw only part of the stall
        a, b = stall_window(c.motion.joints, start, start + 2)
        assert start - 12 <= a <= start and start + 2 <= b <= start + 14  # at most `reach` frames more each side
        flawed_growth.append(b - a - 2)
        covered.append(np.isin(np.arange(lo, hi), np.arange(a, b)).mean())
        a, b = stall_window(m.joints, start, start + 2)
        clean_growth.append(b - a - 2)
    assert np.mean(covered) > 0.4 and np.mean(flawed_growth) > 2 * np.mean(clean_growth) + 2


@pytest.mark.real_data
def test_smoothing_repairs_remove_jitter(walks):
    for fn, n in ((smooth_run, 6), (spline_run, 3)):  # the spline's cross-validation takes about 1 s per run
        before, after = [], []
        for i, m in enumerate(walks[:n]):
            c = transition_jitter(m, 2, random_state=i)
            before.append(_err(c.motion.joints, m.joints))
            after.append(_err(_repaired(fn, c.motion.joints, c.mask), m.joints))
        assert np.mean(after) < 0.9 * np.mean(before), fn.__name__


def test_candidates_touch_only_their_run(rng):
    y = np.cumsum(rng.normal(0, 0.01, (40, 24, 3)), 0).astype(np.float32)
    for name, fn in CANDIDATES.items():
        out = fn(y, 10, 20, SKEL)
        assert out.shape == y.shape and out.dtype == y.dtype, name
        assert np.array_equal(out[:9], y[:9]) and np.array_equal(out[21:], y[21:]), name
        assert np.array_equal(fn(y, 10, 11, SKEL)[:9], y[:9]), name


class _Judge:
    """A flaw classifier stand-in whose flaw probability rises (or falls) with the distance from ``ref``."""

    def __init__(self, ref, sign):
        self.ref, self.sign = ref, sign

    def predict(self, clips):
        return 0.5 + self.sign * np.linalg.norm(clips - self.ref, axis=-1).mean(-1)


@pytest.mark.parametrize("sign, expected", [(1.0, "keep"), (-1.0, "smooth")])
def test_verified_typed_repair_is_kept_only_when_it_looks_more_real(rng, sign, expected, monkeypatch):
    from types import SimpleNamespace

    import refiner.refinement.learned_pipeline as lp

    monkeypatch.setattr(lp, "VERIFY_TYPED", ("noise",))  # the mechanism, on the repair that is simplest to judge
    monkeypatch.setattr(lp, "NOISE_RATIO", 0.0)

    y = (np.cumsum(rng.normal(0, 0.01, (40, 24, 3)), 0) + rng.normal(0, 0.01, (40, 24, 3))).astype(np.float32)
    groups = np.zeros((40, 4))
    groups[:, list(lp.TYPED_REPAIRS).index("noise")] = 0.9
    refiner = SimpleNamespace(repair="typed", blend=4, change_penalty=0.0, flaw_classifier=_Judge(y, sign),
                              skeleton="humanact12")
    assert lp.TYPED_REPAIRS["noise"][0] == "noise_filter"  # without one (no proposals here) smoothing stands in
    name, (lo, hi), out, note = lp._repair_run(refiner, y, 10, 20, {}, groups, y, SKEL)
    assert name == expected and (lo, hi) == (10, 20)
    assert np.array_equal(out, y) == (expected == "keep")
    assert np.array_equal(out[:9], y[:9]) and np.array_equal(out[21:], y[21:])


@pytest.mark.parametrize("local, expected", [(True, "smooth"), (False, "keep")])
def test_noise_runs_are_smoothed_where_noisier_than_their_clip(rng, local, expected):
    from types import SimpleNamespace

    import refiner.refinement.learned_pipeline as lp

    y = np.cumsum(rng.normal(0, 0.01, (40, 24, 3)), 0)
    noisy = slice(10, 20) if local else slice(None)
    y[noisy] += rng.normal(0, 0.01, y[noisy].shape)
    y = y.astype(np.float32)
    groups = np.zeros((40, 4))
    groups[:, list(lp.TYPED_REPAIRS).index("noise")] = 0.9
    # a judge that finds any change less real: noise is not verified by the flaw classifier (it cannot
    # tell a smoothed run from a noisy one), only gated by how much noisier the run is than its clip
    refiner = SimpleNamespace(repair="typed", blend=4, change_penalty=0.0, flaw_classifier=_Judge(y, 1.0),
                              skeleton="humanact12")
    name, _, out, note = lp._repair_run(refiner, y, 10, 20, {}, groups, y, SKEL)
    assert name == expected and np.array_equal(out, y) == (expected == "keep")
    assert expected == "smooth" or "no noisier than the rest of the clip" in note


def test_windows_do_not_grow_over_a_jump_in_the_recording(monkeypatch):
    """A whole-body jump (:func:`teleports`: 18 HumanAct12 clips have one) is no rush: a window stops before it,
    and a path that holds it is not re-timed (the jump was spread over the re-timed frames: +1.2 m on one
    held-out clip)."""
    from refiner.refinement import repair_candidates
    from refiner.refinement.repair_candidates import retime_path, teleports

    step = np.full(39, 0.01)
    step[19:26] = 0.03  # a rush
    step[26] = 0.5  # the jump: 50 times the median step
    y = np.zeros((40, 3, 3))
    y[1:, :, 0] = np.cumsum(step)[:, None]
    assert np.flatnonzero(teleports(y)).tolist() == [26]
    assert stall_window(y, 15, 20) == (15, 26)  # re-times y[14..26]: the rush, not the jump after it
    np.testing.assert_array_equal(retime_path(y, 10, 30, y[10:31]), y)
    assert not np.array_equal(retime_path(y, 10, 25, y[10:26]), y)
    still = np.zeros((40, 3, 3))  # frames 1-9 still after a jump from frame 0, then steady motion
    still[0, :, 0] = -0.5
    still[10:, :, 0] = 0.01 * np.arange(1, 31)[:, None]
    assert stall_window(still, 4, 8)[0] == 2  # grown over the stall, not over the jump (a = 1 re-times from frame 0)
    monkeypatch.setattr(repair_candidates, "GLITCH", np.inf)  # the release before: grown over the jump
    assert stall_window(y, 15, 20) == (15, 28) and stall_window(still, 4, 8)[0] == 1

@pytest.mark.real_data
def test_stall_retiming_spans_the_stop_and_its_rush_not_the_whole_run(walks, monkeypatch):
    """A run widened 15 frames past a frozen transition holds motion that never stalled: re-timed with the stop and
    its rush only, those frames stay as given, and the clip ends nearer the truth than with the whole run re-timed."""
    import refiner.refinement.repair_candidates as rc

    results = []
    for i, m in enumerate(walks):
        c = frozen_transition(m, 2, random_state=i)
        lo, hi = _runs(c.mask)[0]
        if hi + 15 > len(m.joints) - 1:
            continue
        stall = stall_retime_run(c.motion.joints, lo, hi + 15, SKEL)
        changed = np.flatnonzero((stall != c.motion.joints).any((1, 2)))
        if not changed.size:
            continue
        assert changed[-1] < hi + 14  # the frames after the rush are kept
        monkeypatch.setattr(rc, "STALL_SPAN", "run")
        whole = stall_retime_run(c.motion.joints, lo, hi + 15, SKEL)
        monkeypatch.setattr(rc, "STALL_SPAN", "stall")
        results.append((_err(stall, m.joints), _err(whole, m.joints)))
    assert len(results) >= 3
    assert np.mean([a for a, _ in results]) < np.mean([b for _, b in results])
