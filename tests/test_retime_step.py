"""Re-timing a flagged run at an even pace: a stalled stretch of a steady walk comes back steady, frames outside the
run and every frame's bone lengths stay as given."""
from __future__ import annotations

import numpy as np

from refiner.core.bone_directions import retimed, to_bone_directions
from refiner.refinement.steps.retime import even_pace


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
