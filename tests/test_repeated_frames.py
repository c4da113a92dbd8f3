"""Repeated frames (a dropped frame, a stutter): found only where a moving body repeats a pose exactly, put back in time."""
import numpy as np
import pytest

from refiner.refinement.pipeline import Refiner
from refiner.refinement.repeated_frames import MAX_REPEAT, repeated_groups


def _stuttered(x, a, b, every=2):
    """``x (T, J, 3)`` with every ``every``-th frame of ``a..b-1`` shown ``every`` times (the frames between dropped)."""
    idx = np.arange(len(x))
    idx[a:b] = a + ((idx[a:b] - a) // every) * every
    return x[idx]


def _moving(n_frames=40, rng=None):
    t = np.linspace(0, 2 * np.pi, n_frames)[:, None, None]
    return np.sin(t + np.arange(24)[None, :, None] * 0.3) * 0.1 + np.arange(3) * 0.05


def test_groups_are_short_repeats_inside_motion():
    x = _moving()
    assert repeated_groups(x) == []
    assert repeated_groups(_stuttered(x, 10, 20)) == [(10, 12), (12, 14), (14, 16), (16, 18), (18, 20)]
    assert repeated_groups(_stuttered(x, 10, 19, every=3)) == [(10, 13), (13, 16), (16, 19)]
    held = x.copy()
    held[10 : 11 + MAX_REPEAT] = x[10]  # a hold longer than a stutter: the timing steps' business
    assert repeated_groups(held) == []
    still = np.repeat(x[:1], 40, axis=0)
    still[20:] += 0.01 * np.arange(20)[:, None, None]
    still[25] = still[24]
    assert repeated_groups(still) == [(24, 26)]
    still[5] = still[4]  # a still body repeats its pose: no motion around it, not a dropped frame
    assert (4, 6) not in repeated_groups(still)
    with pytest.raises(ValueError, match=r"\(T, J, 3\)"):
        repeated_groups(x[0])


@pytest.mark.real_data
def test_refine_puts_a_stutter_back_in_time(humanact12):
    clip = humanact12[int(np.flatnonzero(humanact12.subjects == 11)[2])].joints
    assert repeated_groups(clip) == []  # mocap never repeats a moving frame exactly
    bad = _stuttered(clip, 10, 30)
    given = bad.copy()
    model = Refiner.pretrained("humanact12", split="train")
    out, report = model.refine(bad, action=humanact12[int(np.flatnonzero(humanact12.subjects == 11)[2])].action,
                               return_report=True)
    np.testing.assert_array_equal(bad, given)  # the input is not modified
    err = lambda a: np.linalg.norm(a - clip, axis=-1).mean()  # noqa: E731
    assert err(out) < 0.5 * err(bad), (err(out), err(bad))
    assert [(c["start"], c["stop"]) for c in report.changes if c.get("repair") == "repeated_frames"] == [(11, 30)]
    assert not repeated_groups(out)
    clean_out = model.refine(clip, action=humanact12[int(np.flatnonzero(humanact12.subjects == 11)[2])].action)
    np.testing.assert_array_equal(clean_out, clip)
    anchors_only = model.refine(bad, mode="anchor")
    assert repeated_groups(anchors_only)  # a transition refinement: ``mode="anchor"`` leaves it
