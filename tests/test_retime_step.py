"""Re-timing a flagged run at an even pace: a stalled stretch of a steady walk comes back steady, frames outside the
run and every frame's bone lengths stay as given; a run grows over the frozen frames next to it, and only over them;
a run in which the body never stands still is passed over."""
from __future__ import annotations

import numpy as np
import pytest

from refiner.core.bone_directions import retimed, to_bone_directions
from refiner.core.signal import pace
from refiner.refinement.steps.retime import (RetimeConfig, calibrated_stillness, caught_up_freezes, even_pace,
                                             holding_still, still_grown)


def _steady(tiny_clip, n=40, speed=0.03):
    """A pose carried along x at ``speed`` metres per frame: ``(n, 24, 3)``."""
    pose = tiny_clip[0].astype(np.float64)
    return pose[None] + np.arange(n)[:, None, None] * np.array([speed, 0.0, 0.0])


def test_a_stall_comes_back_at_an_even_pace(tiny_clip):
    clean = _steady(tiny_clip)
    times = np.arange(len(clean), dtype=np.float64)
    times[10:26] = 10 + 16 * np.linspace(0, 1, 17)[:-1] ** 3  # slowed to a near stop, then rushing
    stalled = retimed(clean, times, "humanact12")
    frames = np.zeros(len(clean), bool)
    frames[10:26] = True
    given = stalled.copy()
    out = even_pace(stalled, frames, "humanact12")
    np.testing.assert_array_equal(stalled, given)
    assert np.abs(stalled - clean).max() > 0.1
    np.testing.assert_allclose(out, clean, atol=1e-6)
    np.testing.assert_array_equal(out[~frames], stalled[~frames])


def test_each_frame_keeps_its_own_bone_lengths(tiny_clip):
    clip = tiny_clip.astype(np.float64)
    frames = np.zeros(len(clip), bool)
    frames[5:15] = True
    out = even_pace(clip, frames, "humanact12")
    assert np.abs(out[5:15] - clip[5:15]).max() > 1e-3  # the run moved
    np.testing.assert_allclose(to_bone_directions(out, "humanact12")[2], to_bone_directions(clip, "humanact12")[2],
                               atol=1e-9)


def test_a_still_run_is_left_as_given(tiny_clip):
    still = np.repeat(tiny_clip[:1].astype(np.float64), 12, axis=0)
    frames = np.zeros(12, bool)
    frames[3:8] = True
    np.testing.assert_array_equal(even_pace(still, frames, "humanact12"), still)


FREEZES = RetimeConfig(threshold=0.5, still_m=0.003)


def _frozen(tiny_clip):
    """A steady clip frozen on frame 10 until frame 20, where it jumps to where the motion is."""
    clean = _steady(tiny_clip)
    frozen = clean.copy()
    frozen[10:20] = clean[10]
    return clean, frozen


def test_a_run_grows_over_the_frozen_frames_next_to_it_and_no_further(tiny_clip):
    clean, frozen = _frozen(tiny_clip)
    seed = np.zeros(len(frozen), bool)
    seed[17:22] = True  # a detector that saw the end of the freeze and the jump
    grown = still_grown(frozen, seed, still_m=0.003)
    assert np.flatnonzero(grown).tolist() == list(range(11, 22))  # frames 11-19 did not move; 10 and 22 did
    np.testing.assert_allclose(even_pace(frozen, grown, "humanact12"), clean, atol=1e-6)
    assert np.abs(even_pace(frozen, seed, "humanact12") - clean).max() > 0.05  # the seed alone leaves the freeze
    np.testing.assert_array_equal(still_grown(frozen, seed, still_m=0.0), seed)
    batch = still_grown(np.stack([frozen, clean]), np.stack([seed, seed]), still_m=0.003)
    np.testing.assert_array_equal(batch, np.stack([grown, seed]))


def test_pace_is_the_mean_joint_step(tiny_clip):
    clean = _steady(tiny_clip, speed=0.02)
    p = pace(clean)
    assert p.shape == (len(clean),) and np.isinf(p[0])
    np.testing.assert_allclose(p[1:], 0.02)


def test_still_m_is_the_pace_few_clean_frames_stay_below(humanact12):
    clips = [m.joints for m in humanact12.split("train")][:200]
    still_m = calibrated_stillness(clips, share=0.01)
    assert 0.0005 < still_m < 0.01  # capture noise keeps a standing body moving by millimetres a frame
    frames = np.concatenate([pace(c)[1:] for c in clips])
    assert abs(np.mean(frames < still_m) - 0.01) < 0.002
    assert calibrated_stillness(clips, share=0.1) > still_m


def test_the_shipped_refiner_grows_its_re_timing_runs():
    from refiner.refinement.motion_refiner import MotionRefiner

    refiner = MotionRefiner.pretrained("humanact12")
    assert 0.0005 < refiner.config.still_m < 0.01
    assert MotionRefiner.pretrained("humanact12", still_m=0.0).config.still_m == 0.0


def test_the_step_flags_the_grown_frames_for_every_part(tiny_clip):
    from refiner.refinement.steps.infill import InfillConfig
    from refiner.refinement.steps.retime import RetimeStep

    clean, frozen = _frozen(tiny_clip)
    step = RetimeStep(_Seeded(), RetimeConfig(threshold=0.5, margin=1, still_m=0.003))
    _, flagged = step.detect(frozen[None], [None])
    assert np.flatnonzero(flagged[0].any(1)).tolist() == list(range(11, 22))
    assert flagged[0, 11:17].all() and not flagged[0, 17:22, 1:].any()  # seeded frames keep their own parts
    _, seeded = RetimeStep(_Seeded(), InfillConfig(threshold=0.5, margin=1)).detect(frozen[None], [None])
    assert np.flatnonzero(seeded[0].any(1)).tolist() == list(range(17, 22))


class _Seeded:
    """A detector sure of frames 18-20 of the first bone only."""

    skeleton = "humanact12"

    def scan(self, clips, actions):
        p = np.zeros(np.shape(clips)[:2] + (24,))
        p[:, 18:21, 0] = 1.0
        return None, p


def test_only_runs_holding_a_still_frame_are_kept():
    frames = np.zeros((2, 12), bool)
    frames[:, 2:5] = frames[:, 7:10] = True
    still = np.zeros((2, 12), bool)
    still[0, 8] = still[1, 0] = True  # the second clip's still frame lies outside its runs
    out = holding_still(frames, still)
    assert np.flatnonzero(out[0]).tolist() == [7, 8, 9] and not out[1].any()
    with pytest.raises(ValueError, match="shape"):
        holding_still(frames, still[0])


def test_a_run_that_never_stops_is_passed_over_and_reported(tiny_clip):
    from refiner.refinement.steps.retime import RetimeStep

    clean, frozen = _frozen(tiny_clip)
    step = RetimeStep(_Seeded(), RetimeConfig(threshold=0.5, margin=1, still_m=0.003))
    assert not step.detect(clean[None], [None])[1].any()
    assert step.detect(frozen[None], [None])[1].any()
    out, changes, _ = step.refine(clean[None], [None])
    np.testing.assert_array_equal(out[0], clean)
    assert [(c["start"], c["stop"], c["kept"], c.get("passed_over")) for c in changes[0]] == [(17, 22, False, True)]


def test_a_freeze_is_found_where_a_jump_catches_it_up(tiny_clip):
    clean, frozen = _frozen(tiny_clip)  # frozen over 11-19, the jump at 20
    np.testing.assert_array_equal(np.flatnonzero(caught_up_freezes(frozen, FREEZES)), np.arange(11, 21))
    skipped = clean.copy()  # a skip: 6 frames ahead at frame 10, then a wait until the clip catches up at 26
    skipped[10:26] = clean[np.minimum(np.arange(10, 26) + 6, 26)]
    found = caught_up_freezes(skipped, FREEZES)
    np.testing.assert_array_equal(np.flatnonzero(found), np.arange(10, 27))  # frame 26 is the wait's last
    np.testing.assert_allclose(even_pace(skipped, found, "humanact12"), clean, atol=1e-6)
    waited = clean.copy()  # a body that stops and then goes on at its pace has lost no time: no jump, no freeze
    waited[10:20] = clean[10]
    waited[20:] = clean[11:len(clean) - 9]
    assert not caught_up_freezes(waited, FREEZES).any()
    assert not caught_up_freezes(clean, FREEZES).any()
    np.testing.assert_array_equal(caught_up_freezes(np.stack([frozen, clean]), FREEZES)[1], np.zeros(len(clean), bool))


def test_the_report_says_a_freeze_was_re_timed(humanact12):
    from refiner.refinement.motion_refiner import MotionRefiner

    clip = next(m.joints for m in humanact12.split("test") if m.n_frames >= 80 and m.action == 0)
    frozen = clip.copy()
    frozen[30:45] = clip[30]  # frozen for 14 frames, then a jump to where the motion is
    given = frozen.copy()
    out, report = MotionRefiner.pretrained("humanact12").refine(frozen, action=0, return_report=True)
    np.testing.assert_array_equal(frozen, given)
    runs = [c for c in report.changes + report.not_kept
            if c["step"] == "retime" and c["start"] <= 31 and c["stop"] >= 45]
    assert runs and "14 frames frozen" in runs[0]["reason"]
    assert runs[0]["kept"]
    error = lambda x: np.linalg.norm(x[31:45] - clip[31:45], axis=-1).mean()  # noqa: E731
    assert error(out) < error(frozen) / 1.5


def test_a_freeze_needs_its_frames_and_its_jump(tiny_clip):
    clean, frozen = _frozen(tiny_clip)  # 9 still steps, a jump of 10 steps' path
    assert not caught_up_freezes(frozen, RetimeConfig(threshold=0.5, still_m=0.003, freeze_frames=10)).any()
    assert not caught_up_freezes(frozen, RetimeConfig(threshold=0.5, still_m=0.003, catch_up=1.2)).any()
    assert caught_up_freezes(frozen, RetimeConfig(threshold=0.5, still_m=0.003, catch_up=0.9)).any()
    assert not caught_up_freezes(frozen, RetimeConfig(threshold=0.5, still_m=0.0)).any()


def test_bad_input_is_refused_by_name(tiny_clip):
    clean, frozen = _frozen(tiny_clip)
    with pytest.raises(ValueError, match="frames"):
        still_grown(frozen, np.zeros((2, len(frozen)), bool), 0.003)
    with pytest.raises(ValueError, match="joints"):
        pace(frozen[:, :, 0])
    with pytest.raises(ValueError, match="T >= 2"):
        calibrated_stillness([frozen[:1]], share=0.01)
    with pytest.raises(ValueError, match="no clips"):
        calibrated_stillness([], share=0.01)
    for bad in ({"still_m": -0.001}, {"still_m": float("nan")}, {"freeze_frames": 0}, {"reach": 0.0}):
        with pytest.raises(ValueError):
            RetimeConfig(threshold=0.5, **bad)
    given = frozen.copy()
    still_grown(frozen, np.ones(len(frozen), bool), 0.003)
    caught_up_freezes(frozen, FREEZES)
    np.testing.assert_array_equal(frozen, given)


def test_ground_only_recalibrates_the_shipped_stillness(tmp_path, humanact12):
    import argparse
    import json
    from pathlib import Path

    from refiner.cli.train_motion import train_motion_run

    shipped = Path(__file__).resolve().parents[1] / "refiner" / "weights" / "humanact12-motion" / "manifest.json"
    (tmp_path / "humanact12-motion").mkdir()
    copy = tmp_path / "humanact12-motion" / "manifest.json"
    manifest = json.loads(shipped.read_text())
    copy.write_text(json.dumps({k: v for k, v in manifest.items() if k != "retime"}))
    args = argparse.Namespace(out=tmp_path, dataset="humanact12", data=None, steps=1, folds=False, ground_only=True,
                              jobs=1)
    assert train_motion_run(args) == 0
    written = json.loads(copy.read_text())
    assert written["retime"] == manifest["retime"] and written["ground"] == manifest["ground"]
