"""The retrace cut: motion that turns back over its own path is found, cut and re-timed; real motion is left."""
import numpy as np
import pytest

from refiner.core.signal import resample
from refiner.evaluation.flaws import reversed_transition
from refiner.refinement.pipeline import Refiner
from refiner.refinement import retrace
from refiner.refinement.report import start_reports
from refiner.refinement.retrace import (MAX_RATIO, MAX_SPAN, MIN_FLAW_PROBABILITY, cut_retrace, cut_retraces,
                                       find_retraces, retrace_window, turn_frames)


def _path(n_frames=48, seed=0):
    """A rigid body of 24 points ``(T, 24, 3)`` turning about the vertical and moving one way (both
    quadratic in time): its bone lengths never change, so the refiner's bone projection keeps it."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n_frames)
    pose = rng.normal(scale=0.3, size=(24, 3))
    angle = 1.5 * t + 0.8 * t**2
    c, s = np.cos(angle), np.sin(angle)
    rot = np.stack([np.stack([c, 0 * c, s], -1), np.stack([0 * c, 1 + 0 * c, 0 * c], -1), np.stack([-s, 0 * c, c], -1)], 1)
    shift = np.outer(t, rng.normal(scale=0.5, size=3)) + np.outer(t**2, rng.normal(scale=0.3, size=3))
    return (np.einsum("tij,kj->tki", rot, pose) + shift[:, None]).astype(np.float32)


def _reversed(x, lo, hi, amplitude=2.5):
    """Frames ``lo..hi`` re-timed by ``u + a sin(2 pi u) / (2 pi)``: part of them plays backwards."""
    out = x.copy()
    u = np.linspace(0.0, 1.0, hi - lo + 1)
    out[lo : hi + 1] = resample(x, lo + (hi - lo) * (u + amplitude * np.sin(2 * np.pi * u) / (2 * np.pi)))
    return out


def _err(a, b):
    return 100 * float(np.linalg.norm(a - b, axis=-1).mean())


def test_a_seeded_loop_is_found_and_cut_and_the_input_kept():
    clean = _path()
    flawed = _reversed(clean, 12, 32)
    given = flawed.copy()
    assert turn_frames(clean).size == 0 and find_retraces(clean) == []
    with pytest.raises(ValueError, match=r"\(T, J, 3\)"):
        turn_frames(flawed.reshape(len(flawed), -1))
    batch = turn_frames(np.stack([clean, flawed]))
    assert batch[0].size == 0 and np.array_equal(batch[1], turn_frames(flawed))
    loops = find_retraces(flawed)
    assert len(loops) == 1
    loop = loops[0]
    assert 12 <= loop.start < loop.turn < loop.back_turn < loop.resume <= 32 and loop.ratio < MAX_RATIO
    repaired, (lo, hi) = cut_retrace(flawed, loop)
    np.testing.assert_array_equal(flawed, given)  # the input is not modified
    assert (repaired[:lo] == flawed[:lo]).all() and (repaired[hi + 1 :] == flawed[hi + 1 :]).all()
    assert _err(repaired, clean) < 0.5 * _err(flawed, clean)


def test_a_path_that_returns_another_way_is_no_retrace():
    """Out along one arc and back along another (a real reach and return): turns, but no retrace."""
    t = np.linspace(0.0, 2 * np.pi, 50)[:, None, None]
    rng = np.random.default_rng(3)
    a, b = rng.normal(scale=0.2, size=(2, 1, 24, 3))
    x = (a * (1 - np.cos(t)) + b * np.sin(t)).astype(np.float32)  # an ellipse per joint: back by the other side
    assert find_retraces(x) == []
    back_and_forth = (a * (1 - np.cos(t))).astype(np.float32)  # exactly the same way back: a retrace geometrically
    assert turn_frames(back_and_forth).size >= 1


def test_a_loop_longer_than_the_span_limit_is_left():
    """A whole repetition (a 60-frame transition played back over half of itself) is no glitch to cut."""
    clean = _path(100, seed=1)
    flawed = _reversed(clean, 10, 80)
    assert find_retraces(flawed, max_back=40) == []
    (loop,) = find_retraces(flawed, max_back=40, max_span=100)
    assert loop.resume - loop.start > MAX_SPAN


class _Classifier:
    """Stands in for the flaw classifier: the same probability everywhere."""

    def __init__(self, probability):
        self.probability, self.threshold_ = probability, 0.95

    def predict(self, joints):
        return np.full(np.shape(joints)[:2], self.probability)


class _Refiner:
    def __init__(self, probability, retiming="flagged"):
        self.flaw_classifier, self.retiming, self.skeleton = _Classifier(probability), retiming, "humanact12"


def _cut(refiner, clips):
    reports = start_reports(clips.shape[1], [None] * len(clips), "full", (), batched=True)
    return cut_retraces(refiner, clips, reports, "full"), reports


def test_the_classifier_gate_and_the_option_decide():
    clean = _path(60)
    flawed = _reversed(clean, 12, 32)[None]
    for refiner, cut in ((_Refiner(MIN_FLAW_PROBABILITY - 0.01), False), (_Refiner(MIN_FLAW_PROBABILITY), True),
                         (_Refiner(1.0, retiming="stalls"), False)):
        out, reports = _cut(refiner, flawed)
        assert (not np.array_equal(out, flawed)) == cut == bool(reports[0].changes)
    out, reports = _cut(_Refiner(1.0), flawed)
    assert "moved" in reports[0].changes[0]["reason"] and _err(out[0], clean) < _err(flawed[0], clean)
    np.testing.assert_array_equal(cut_retraces(_Refiner(1.0), flawed, reports, "anchor"), flawed)  # a transition step


def test_a_given_flaw_probability_is_used_in_place_of_the_classifier(monkeypatch):
    """The pipeline passes the probability it has: the same cut, and clips never flagged are not searched."""
    flawed = np.stack([_reversed(_path(60), 12, 32), _reversed(_path(60, seed=3), 12, 32)])
    cut, _ = _cut(_Refiner(1.0), flawed)
    assert not np.array_equal(cut[1], flawed[1])  # both clips hold a loop
    reports = start_reports(60, [None, None], "full", (), batched=True)
    given = np.stack([np.full(60, 1.0), np.full(60, MIN_FLAW_PROBABILITY - 0.01)])
    searched = []
    monkeypatch.setattr(retrace, "find_retraces", lambda joints, **kw: searched.append(1) or find_retraces(joints, **kw))
    out = cut_retraces(_Refiner(0.0), flawed, reports, "full", given)  # the stand-in classifier would refuse both
    np.testing.assert_array_equal(out[0], cut[0])
    np.testing.assert_array_equal(out[1], flawed[1])
    assert reports[0].changes and not reports[1].changes and len(searched) == 1  # the unflagged clip: not searched


def test_two_loops_are_cut_apart_and_nothing_outside_their_windows_changes():
    clean = _path(120, seed=2)
    flawed = _reversed(_reversed(clean, 10, 30), 70, 92)
    out, reports = _cut(_Refiner(1.0), flawed[None])
    windows = [(c["start"], c["stop"]) for c in reports[0].changes]
    assert len(windows) == 2 and (windows[0][1] <= windows[1][0] or windows[1][1] <= windows[0][0])
    inside = np.zeros(len(clean), bool)
    for lo, hi in windows:
        inside[lo:hi] = True
    np.testing.assert_array_equal(out[0][~inside], flawed[~inside])
    assert _err(out[0], clean) < 0.5 * _err(flawed, clean)
    loops = find_retraces(flawed)
    assert [retrace_window(flawed, loop) for loop in loops] == sorted(
        (lo, hi - 1) for lo, hi in windows)


@pytest.fixture(scope="module")
def model():
    return Refiner.pretrained("humanact12", split="train")


@pytest.mark.real_data
def test_real_clips_of_the_held_out_subjects_are_never_cut(humanact12, model):
    """Real back-and-forth motion (a dumbbell lifted and lowered) retraces its path too, but is not flagged."""
    looped = 0
    for motion in humanact12.split("test").motions:
        clip = motion.joints[None]
        looped += bool(find_retraces(clip[0], max_span=100))
        reports = start_reports(motion.n_frames, [None], "full", model.action_names, batched=True)
        np.testing.assert_array_equal(cut_retraces(model, clip, reports, "full"), clip)
        assert not reports[0].changes
    assert looped >= 3  # some real clips retrace as exactly as the threshold asks: the span and the gate keep them


@pytest.mark.real_data
def test_seeded_reversals_of_real_clips_are_cut_and_come_closer(humanact12, model):
    test = humanact12.split("test")
    clips = [m for m in test.motions if m.n_frames >= 40][:24]
    flawed = [reversed_transition(m, 2, random_state=k).motion for k, m in enumerate(clips)]
    before = np.mean([_err(f.joints, m.joints) for f, m in zip(flawed, clips)])
    refined, cut, stalls_only = [], 0, Refiner.pretrained("humanact12", split="train", retiming="stalls")
    for f, m in zip(flawed, clips):
        out, report = model.refine(f, action=m.action, return_report=True)
        refined.append(_err(out.joints, m.joints))
        changes = [c for c in report.changes if c.get("repair") == "retrace_cut"]
        cut += bool(changes)
        assert all("retraced its path" in c["reason"] for c in changes)
    assert cut >= 8
    assert np.mean(refined) < 0.8 * before
    off = [stalls_only.refine(f, action=m.action, return_report=True)[1] for f, m in zip(flawed[:6], clips[:6])]
    assert not any(c.get("repair") == "retrace_cut" for r in off for c in r.changes)


@pytest.mark.real_data
def test_a_jump_in_the_recording_is_not_spread_over_a_cut(humanact12, model):
    """Held-out clip 146 teleports its root 1.2 m between frames 31 and 32, right after a seeded reversal's rush:
    the cut's window stops before the jump, and no frame ends up more than 30 cm from the clean clip (122 cm when
    the window grew over it)."""
    from refiner.concepts.segmentation import segment

    from refiner.refinement.pipeline import Refiner

    clips = humanact12.split("test").motions
    clean = clips[146]
    flawed = reversed_transition(clean, 2, random_state=146, segmentation=segment(clean.joints)).motion  # bench flaws'
    cutting = Refiner.pretrained("humanact12", split="train", retiming="flagged")  # no timing estimator: the cut
    out, report = cutting.refine(flawed, action=clean.action, return_report=True)
    assert any(c.get("repair") == "retrace_cut" and c["stop"] <= 32 for c in report.changes)
    assert np.linalg.norm(out.joints - clean.joints, axis=-1).mean(-1).max() < 0.3
    out, report = model.refine(flawed, action=clean.action, return_report=True)  # the estimator re-times it first
    assert all(c["stop"] <= 32 for c in report.changes if c.get("repair") == "estimated_retime")
    assert np.linalg.norm(out.joints - clean.joints, axis=-1).mean(-1).max() < 0.3
