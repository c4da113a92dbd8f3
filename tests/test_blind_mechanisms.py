"""Blind flaw mechanisms: shapes, purity, determinism, bone lengths and a local, visible change, on synthetic
and real HumanAct12 clips."""
from __future__ import annotations

import numpy as np
import pytest

from refiner.core.skeletons import bone_lengths, get_skeleton, joint_bone_lengths
from refiner.evaluation import blind_gait_mechanisms, blind_timing_mechanisms
from refiner.evaluation.blind_geometry import bones
from refiner.evaluation.blind_mechanisms import MECHANISMS

SKEL = get_skeleton("humanact12")
# mechanisms that keep every frame's bone lengths exactly (sink_into_floor may stretch the legs, joint_jitter
# adds position noise)
KEEPS_BONES = {"wrong_limb_pose", "freeze_catch_up", "hover_above_ground", "foot_skate", "stutter", "tempo_drift",
               "dropped_frames_crawl", "same_foot_twice", "lagging_limb"}
GROUND = ["hover_above_ground", "foot_skate", "sink_into_floor", "joint_jitter"]
TIMING = ["stutter", "tempo_drift", "dropped_frames_crawl"]
GAIT = ["same_foot_twice", "bone_stretch", "lagging_limb"]
VISIBLE_M = {"joint_jitter": 0.01, "bone_stretch": 0.02}  # 1-2 cm RMS noise; 3-8 % of a limb; the others a few cm
LEG_BONES = [4, 5, 7, 8]  # bones ending at the knees and ankles (thighs and shins)


def _rigid_clip(n_frames: int, seed: int = 0) -> np.ndarray:
    """A synthetic rigid-skeleton walk-like clip: smoothly swinging bones of fixed length, a moving root."""
    rng = np.random.default_rng(seed)
    rest = np.array([[0, 0, 0], [.06, .09, 0], [-.06, .09, 0], [0, -.11, 0], [0, .38, 0], [0, .38, 0],
                     [0, -.13, 0], [0, .40, 0], [0, .40, 0], [0, -.06, 0], [0, .05, -.12], [0, .05, -.12],
                     [0, -.23, 0], [.08, -.12, 0], [-.08, -.12, 0], [0, -.1, 0], [.1, .02, 0], [-.1, .02, 0],
                     [0, .26, 0], [0, .26, 0], [0, .25, 0], [0, .25, 0], [0, .09, 0], [0, .09, 0]], float)
    t = np.arange(n_frames)[:, None, None] / 20.0
    phase, freq = rng.uniform(0, 2 * np.pi, (1, 24, 3)), rng.uniform(0.3, 1.5, (1, 24, 3))
    dirs = rest / np.maximum(np.linalg.norm(rest, axis=-1, keepdims=True), 1e-9)
    dirs = dirs + 0.5 * np.sin(2 * np.pi * freq * t + phase)
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    x = np.zeros((n_frames, 24, 3))
    x[:, 0] = np.stack([0.1 * np.sin(t[:, 0, 0]), 0.02 * np.sin(6 * t[:, 0, 0]), -1.2 * t[:, 0, 0]], -1)
    for j, p in enumerate(SKEL.parents):
        if p >= 0:
            x[:, j] = x[:, p] + np.linalg.norm(rest[j]) * dirs[:, j]
    return (x - x[:1, :1]).astype(np.float32)


@pytest.mark.parametrize("name", sorted(MECHANISMS))
@pytest.mark.parametrize("n_frames", [40, 97, 200])
def test_shape_purity_and_bones(name, n_frames):
    clip = _rigid_clip(n_frames, seed=n_frames)
    before = clip.copy()
    clip.flags.writeable = False
    for seed in range(5):
        for severity in (0.5, 1.0, 2.0):
            out = MECHANISMS[name](clip, np.random.default_rng(seed), severity)
            assert out.shape == clip.shape and out.dtype == np.float32 and np.isfinite(out).all()
            assert out is not clip and np.array_equal(clip, before)
            err = np.abs(bone_lengths(out, SKEL) - bone_lengths(clip, SKEL)).max()
            assert err < 1e-5 or name not in KEEPS_BONES


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_deterministic_for_a_seed(name):
    clip = _rigid_clip(80)
    a = MECHANISMS[name](clip, np.random.default_rng(7))
    b = MECHANISMS[name](clip, np.random.default_rng(7))
    assert np.array_equal(a, b)
    others = [MECHANISMS[name](clip, np.random.default_rng(s)) for s in range(8, 12)]
    assert any(not np.array_equal(a, o) for o in others)


@pytest.mark.parametrize("name", sorted(MECHANISMS))
def test_change_is_local_and_visible(name):
    clip = _rigid_clip(120, seed=3)
    for seed in range(10):
        out = MECHANISMS[name](clip, np.random.default_rng(seed))
        disp = np.linalg.norm(out - clip, axis=-1)
        changed = np.flatnonzero(disp.max(1) > 1e-5)
        assert changed.size and changed[0] >= 1
        assert changed[-1] - changed[0] + 1 <= 30
        assert disp.max() > VISIBLE_M.get(name, 0.03)


def test_float64_input_and_zero_severity():
    clip = _rigid_clip(60).astype(np.float64)
    for fn in MECHANISMS.values():
        out = fn(clip, np.random.default_rng(0), 0.0)
        assert out.dtype == np.float32
        assert np.abs(out - clip).max() < 1e-5


def test_each_frame_keeps_its_own_bone_lengths():
    clip = _rigid_clip(70, seed=5) + np.random.default_rng(1).normal(0, 0.005, (70, 24, 3)).astype(np.float32)
    for fn in (MECHANISMS[k] for k in sorted(KEEPS_BONES)):
        for seed in range(4):
            out = fn(clip, np.random.default_rng(seed))
            assert np.abs(bone_lengths(out, SKEL) - bone_lengths(clip, SKEL)).max() < 1e-5


@pytest.fixture(scope="module")
def real_clips(humanact12):
    """Four real HumanAct12 clips of different actions and lengths, float32 ``(T, 24, 3)``."""
    return [np.asarray(humanact12.motions[i].numpy(), np.float32) for i in (0, 300, 700, 1100)]


def _changed_frames(out: np.ndarray, clip: np.ndarray) -> np.ndarray:
    return np.flatnonzero(np.abs(out.astype(np.float64) - clip).max((1, 2)) > 1e-6)


@pytest.mark.real_data
@pytest.mark.parametrize("name", GROUND + TIMING + GAIT)
def test_ground_mechanisms_on_real_clips_are_pure_local_and_seeded(name, real_clips):
    """On real clips: float32 of the same shape, input untouched, one window of 8-30 whole frames, seeded."""
    for clip in real_clips:
        before = clip.copy()
        view = clip.view()
        view.flags.writeable = False
        outs = []
        for seed in range(6):
            out = MECHANISMS[name](view, np.random.default_rng(seed))
            assert out.shape == clip.shape and out.dtype == np.float32 and np.isfinite(out).all()
            assert np.array_equal(clip, before)
            changed = _changed_frames(out, clip)
            assert 8 <= changed.size <= 30 and changed[0] >= 1 and changed[-1] <= len(clip) - 2
            assert np.array_equal(changed, np.arange(changed[0], changed[-1] + 1))  # one window, no gaps
            assert np.array_equal(out, MECHANISMS[name](clip, np.random.default_rng(seed)))
            outs.append(out)
        assert all(not np.array_equal(outs[0], o) for o in outs[1:])


@pytest.mark.real_data
def test_hover_lifts_the_whole_body_rigidly(real_clips):
    for clip in real_clips:
        for seed in range(8):
            d = MECHANISMS["hover_above_ground"](clip, np.random.default_rng(seed)).astype(np.float64) - clip
            assert np.abs(d[..., [0, 2]]).max() < 1e-6 and d[..., 1].max() < 1e-6  # only up (-y)
            assert np.abs(d - d[:, :1]).max() < 1e-5  # every joint by the same height
            assert 0.02 < -d[..., 1].min() < 0.13
            assert np.abs(bone_lengths(clip + d, SKEL) - bone_lengths(clip, SKEL)).max() < 1e-5


@pytest.mark.real_data
def test_foot_skate_slides_along_the_floor(real_clips):
    """Feet slide horizontally at their own heights, by the whole body or by one re-solved leg."""
    forms = set()
    for clip in real_clips:
        for seed in range(12):
            out = MECHANISMS["foot_skate"](clip, np.random.default_rng(seed))
            d = out.astype(np.float64) - clip
            feet = [7, 8, 10, 11]
            assert np.abs(d[:, feet, 1]).max() < 1e-5
            assert np.linalg.norm(d[:, feet][..., [0, 2]], axis=-1).max() > 0.02
            assert np.abs(bone_lengths(out, SKEL) - bone_lengths(clip, SKEL)).max() < 1e-5
            moved = np.flatnonzero(np.abs(d).max((0, 2)) > 1e-6)
            if moved.size == 24:
                assert np.abs(d - d[:, :1]).max() < 1e-5 and np.abs(d[..., 1]).max() < 1e-6
                forms.add("body")
            else:
                assert set(moved) <= {4, 7, 10} or set(moved) <= {5, 8, 11}
                forms.add("leg")
    assert forms == {"body", "leg"}


@pytest.mark.real_data
def test_sink_only_moves_joints_down_and_stretches_at_most_the_legs(real_clips):
    for clip in real_clips:
        for seed in range(10):
            out = MECHANISMS["sink_into_floor"](clip, np.random.default_rng(seed))
            d = out.astype(np.float64) - clip
            assert np.abs(d[..., [0, 2]]).max() < 1e-6 and d[..., 1].min() > -1e-6  # only down (+y)
            assert 0.02 < d[:, [10, 11], 1].max() < 0.1
            stretch = np.abs(joint_bone_lengths(out, SKEL) - joint_bone_lengths(clip, SKEL))
            assert np.delete(stretch, LEG_BONES, axis=1).max() < 1e-5
            assert stretch.max() <= d[..., 1].max() + 1e-5


@pytest.mark.real_data
def test_jitter_is_a_high_frequency_burst_on_one_group(real_clips):
    groups = [{18, 20, 22}, {19, 21, 23}, {4, 7, 10}, {5, 8, 11}, {12, 15}, set(range(24))]
    for clip in real_clips:
        for seed in range(10):
            out = MECHANISMS["joint_jitter"](clip, np.random.default_rng(seed))
            d = out.astype(np.float64) - clip
            moved = set(np.flatnonzero(np.abs(d).max((0, 2)) > 1e-6))
            assert moved in groups
            w = d[_changed_frames(out, clip)][:, sorted(moved)]
            rms = np.sqrt((w ** 2).sum(-1).mean())
            assert 0.004 < rms < 0.025
            # shaking, not a slow offset: frame-to-frame changes as large as the offsets themselves
            assert np.sqrt((np.diff(w, axis=0) ** 2).sum(-1).mean()) > 0.5 * rms


@pytest.mark.real_data
@pytest.mark.parametrize("name", ["hover_above_ground", "sink_into_floor", "joint_jitter"])
def test_severity_scales_the_flaw(name, real_clips):
    clip = real_clips[1]
    one = MECHANISMS[name](clip, np.random.default_rng(3), 1.0).astype(np.float64) - clip
    two = MECHANISMS[name](clip, np.random.default_rng(3), 2.0).astype(np.float64) - clip
    assert np.abs(two - 2.0 * one).max() < 1e-5


# ---- timing mechanisms: the synthetic clip's root moves -z at exactly 6 cm a frame and is interpolated linearly,
# so the played time of every output frame can be read back from the root


def _played_time(out: np.ndarray) -> np.ndarray:
    """Time (in frames) each frame of a re-timed ``_rigid_clip`` shows, from its root's z."""
    return -out[:, 0, 2].astype(np.float64) / 0.06


def _window_speeds(out: np.ndarray, clip: np.ndarray):
    """Changed frames and the playback speed (played frames per frame) of each step into, through and out of them."""
    changed = _changed_frames(out, clip)
    speed = np.diff(_played_time(out))[changed[0] - 1:changed[-1] + 1]
    return changed, speed


def test_timing_mechanisms_are_all_in_the_registry():
    assert set(TIMING) == set(blind_timing_mechanisms.MECHANISMS) and set(TIMING) <= set(MECHANISMS)
    assert all(MECHANISMS[k] is blind_timing_mechanisms.MECHANISMS[k] for k in TIMING)
    assert len(MECHANISMS) == 2 + len(GROUND) + len(TIMING) + len(GAIT)


@pytest.mark.parametrize("name", TIMING)
def test_timing_mechanisms_only_retime_and_rejoin_the_timeline(name):
    """One 8-30 frame window; its poses are the clip's own at other times; the timeline is rejoined at its end."""
    clip = _rigid_clip(120, seed=3)
    for seed in range(10):
        out = MECHANISMS[name](clip, np.random.default_rng(seed))
        changed, speed = _window_speeds(out, clip)
        assert 8 <= changed.size <= 30 and np.array_equal(changed, np.arange(changed[0], changed[-1] + 1))
        assert np.array_equal(out[:changed[0]], clip[:changed[0]]) and np.array_equal(out[changed[-1] + 1:],
                                                                                      clip[changed[-1] + 1:])
        assert abs(speed.sum() - len(speed)) < 1e-3  # the time lost or gained inside is exactly made up
        assert np.abs(bone_lengths(out, SKEL) - bone_lengths(clip, SKEL)).max() < 1e-5


def test_stutter_runs_backwards_briefly_then_catches_up():
    clip = _rigid_clip(120, seed=3)
    for seed in range(10):
        _, speed = _window_speeds(MECHANISMS["stutter"](clip, np.random.default_rng(seed)), clip)
        back = np.flatnonzero(speed < -0.5)
        assert 1 <= back.size <= 6 and back[0] == 0  # a few frames played in reverse, starting the window
        assert (speed[back[-1] + 1:] > 0.9).all()  # afterwards only forwards: the replay, then the catch-up
        assert speed.max() > 1.05


def test_tempo_drift_slows_smoothly_without_freezing_then_speeds_up():
    clip = _rigid_clip(120, seed=3)
    for seed in range(10):
        out = MECHANISMS["tempo_drift"](clip, np.random.default_rng(seed))
        changed, speed = _window_speeds(out, clip)
        assert 0.02 < speed.min() < 0.35 and speed.max() > 1.2  # near-still, never frozen, then faster
        assert np.argmin(speed) < np.argmax(speed)  # the slow stretch comes first
        assert np.abs(np.diff(speed)).max() < 0.75 * (speed.max() - speed.min())  # eases, no hard stop or start
        moving = np.linalg.norm(np.diff(out[changed[0] - 1:changed[-1] + 2], axis=0), axis=-1).max(1)
        assert moving.min() > 1e-4  # some residual motion in every frame


def test_tempo_drift_keeps_a_small_residual_wobble():
    """Beyond the re-timing, bones wobble a little: rotations of about a degree, none at zero severity."""
    clip = _rigid_clip(120, seed=3)
    for seed in range(5):
        out = MECHANISMS["tempo_drift"](clip, np.random.default_rng(seed)).astype(np.float64)
        tau = _played_time(out)
        i0 = np.clip(np.floor(tau).astype(int), 0, len(clip) - 2)
        f = (tau - i0)[:, None, None]
        lerp = clip[i0] * (1 - f) + clip[i0 + 1] * f  # what a pure re-timing would show, near enough
        rel = lambda y: y - y[:, :1]  # noqa: E731
        gap = np.linalg.norm(rel(out) - rel(lerp), axis=-1).max()
        assert 1e-3 < gap < 0.06


def test_dropped_frames_jump_ahead_then_crawl():
    clip = _rigid_clip(120, seed=3)
    for seed in range(10):
        _, speed = _window_speeds(MECHANISMS["dropped_frames_crawl"](clip, np.random.default_rng(seed)), clip)
        jump = np.flatnonzero(speed > 1.5)
        assert jump.size in (1, 2) and np.array_equal(jump, np.arange(jump.size))  # skipped at the start
        crawl = speed[jump.size:]
        assert (crawl > 0.04).all() and (crawl < 1.0 + 1e-6).all() and crawl.min() < 0.6  # slow, never a wait
        assert (np.diff(crawl) > -1e-6).all()  # speeding back up to normal, never slowing again


@pytest.mark.parametrize("name", TIMING)
def test_timing_severity_scales_the_warp(name):
    """Same seed, same window; a larger severity shifts the played time further."""
    clip = _rigid_clip(120, seed=3)
    frames = np.arange(len(clip))
    for seed in range(5):
        lags = [np.abs(_played_time(MECHANISMS[name](clip, np.random.default_rng(seed), s)) - frames).max()
                for s in (0.5, 1.0, 2.0)]
        assert lags[0] < lags[1] <= lags[2] + 1e-6 and lags[0] > 0.2


# ---- gait and limb mechanisms (same foot twice, bone stretch, lagging limb) on real clips

LEGS = {"left": [4, 7, 10], "right": [5, 8, 11]}
LIMBS = [[18, 20, 22], [19, 21, 23], LEGS["left"], LEGS["right"]]


def test_gait_mechanisms_are_all_in_the_registry():
    assert set(GAIT) == set(blind_gait_mechanisms.MECHANISMS)
    assert all(MECHANISMS[k] is blind_gait_mechanisms.MECHANISMS[k] for k in GAIT)


@pytest.mark.real_data
@pytest.mark.parametrize("name", GAIT)
def test_gait_mechanisms_on_real_clips_keep_the_ends_and_bones_and_show(name, real_clips):
    """First and last frame exact, some joint moved by over 2 cm, bones kept where promised."""
    for clip in real_clips:
        for seed in range(4):
            out = MECHANISMS[name](clip, np.random.default_rng(seed))
            assert np.array_equal(out[[0, -1]], clip[[0, -1]])
            assert np.linalg.norm(out.astype(np.float64) - clip, axis=-1).max() > 0.02
            err = np.abs(joint_bone_lengths(out, SKEL) - joint_bone_lengths(clip, SKEL)).max()
            assert err < 1e-5 or name not in KEEPS_BONES


def _moved_joints(out: np.ndarray, clip: np.ndarray) -> list:
    return list(np.flatnonzero(np.abs(out.astype(np.float64) - clip).max((0, 2)) > 1e-6))


@pytest.mark.real_data
def test_same_foot_twice_moves_only_the_legs_below_the_hips(real_clips):
    """Both legs (the swap) or one (the copy) change; hips, upper body and root stay exactly."""
    forms = set()
    for clip in real_clips:
        for seed in range(8):
            moved = _moved_joints(MECHANISMS["same_foot_twice"](clip, np.random.default_rng(seed)), clip)
            assert moved in (sorted(LEGS["left"] + LEGS["right"]), LEGS["left"], LEGS["right"])
            forms.add(len(moved))
    assert forms == {3, 6}


@pytest.mark.real_data
def test_bone_stretch_varies_chain_lengths_by_a_few_percent_keeping_directions(real_clips):
    for clip in real_clips:
        for seed in range(6):
            out = MECHANISMS["bone_stretch"](clip, np.random.default_rng(seed)).astype(np.float64)
            ratio = joint_bone_lengths(out, SKEL)[:, 1:] / joint_bone_lengths(clip, SKEL)[:, 1:]
            assert 0.02 < np.abs(ratio - 1.0).max() < 0.09  # a few per cent at the peak, no more
            assert np.abs(np.diff(ratio, axis=0)).max() < 0.65 * np.abs(ratio - 1.0).max()  # a wobble, not a jump
            assert np.abs(bones(out)[0] - bones(clip)[0]).max() < 1e-5  # every bone keeps its direction


@pytest.mark.real_data
def test_lagging_limb_moves_one_limb_which_shows_earlier_poses(real_clips):
    """One arm or leg changes; its pose relative to its limb root looks like the clip's a few frames before."""
    late = 0
    for clip in real_clips:
        for seed in range(6):
            out = MECHANISMS["lagging_limb"](clip, np.random.default_rng(seed)).astype(np.float64)
            moved = _moved_joints(out, clip)
            assert moved in LIMBS
            frames = _changed_frames(out, clip)
            root = SKEL.parents[moved[0]]
            rel = lambda x, t: x[t][:, moved] - x[t][:, [root]]  # noqa: E731
            gaps = [np.linalg.norm(rel(out, frames) - rel(clip, frames - k), axis=-1).mean() for k in range(6)]
            late += int(np.argmin(gaps) > 0)
    assert late >= 0.75 * len(real_clips) * 6
