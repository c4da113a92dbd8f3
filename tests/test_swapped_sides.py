"""Left/right confusion: legs that show each other's motion over a window are found by the jumps into and out of
it, and swapped back where the flaw classifier finds that more real."""
import numpy as np
import pytest

import refiner.refinement.swapped_sides as swapped_sides
from refiner.core.skeletons import Skeleton, bone_lengths, get_skeleton
from refiner.refinement.pipeline import Refiner
from refiner.refinement.swapped_sides import blend_weights, limb_pair, sides_swapped, swapped_window, unblended


def _walk(humanact12):
    """A held-out walking clip (subject 11, 109 frames)."""
    i = int(np.flatnonzero((humanact12.subjects == 11) & (humanact12.actions == 1))[0])
    return humanact12[i]


def _swapped_over(x, a, b):
    pair = limb_pair("humanact12")
    out = np.array(x, copy=True)
    out[a:b] = sides_swapped(x[a:b], *pair)
    return out


def test_every_shipped_skeleton_has_matching_legs():
    for name in ("humanact12", "uestc", "cmu_mocap", "humanml3d"):
        skel = get_skeleton(name)
        left, right = limb_pair(name)
        assert len(left) == len(right) >= 3
        for l, r in zip(left, right):
            assert skel.joint_names[l].replace("left", "right") == skel.joint_names[r]
    assert limb_pair("humanact12", "shoulder")[0].tolist() == [16, 18, 20, 22]
    assert limb_pair("humanact12", "no_such_joint") is None
    assert limb_pair(Skeleton("legless_test", ("root", "a", "b"), (-1, 0, 1))) is None  # the step then leaves clips alone


@pytest.mark.real_data
def test_swapping_twice_gives_the_clip_back_and_each_leg_the_others_lengths(humanact12):
    x = _walk(humanact12).joints.astype(np.float64)
    left, right = limb_pair("humanact12")
    once = sides_swapped(x, left, right)
    np.testing.assert_allclose(sides_swapped(once, left, right), x, atol=1e-9)
    others = np.setdiff1d(np.arange(24), np.r_[left, right])
    np.testing.assert_array_equal(once[:, others], x[:, others])
    lengths, swapped = bone_lengths(x, "humanact12"), bone_lengths(once, "humanact12")
    bones = get_skeleton("humanact12").bones
    child = {int(c): k for k, (_, c) in enumerate(bones)}
    for l, r in zip(left[1:], right[1:]):  # the bones below the hips
        np.testing.assert_allclose(swapped[:, child[int(l)]], lengths[:, child[int(r)]], rtol=1e-9)
    with pytest.raises(ValueError, match=r"\(T, J, 3\)"):
        swapped_window(x[0], left, right)


@pytest.mark.real_data
def test_the_window_is_found_by_the_jumps_into_and_out_of_it(humanact12):
    x = _walk(humanact12).joints.astype(np.float64)
    pair = limb_pair("humanact12")
    ratio, a, b = swapped_window(_swapped_over(x, 30, 45), *pair)
    assert (a, b) == (30, 45) and ratio < 0.5, (ratio, a, b)
    assert swapped_window(x, *pair)[0] > swapped_sides.SWAPS["swapped_legs"][2]  # the clean walk offers no window
    assert swapped_window(_swapped_over(x, 30, 45), *pair, lo=50)[1:] != (30, 45)  # only inside [lo, hi)
    assert swapped_window(x[:4], *pair) == (np.inf, -1, -1)  # no room for a window with a frame on each side


@pytest.mark.real_data
def test_refine_swaps_the_legs_back(humanact12, monkeypatch):
    clip = _walk(humanact12)
    x = clip.joints
    bad = _swapped_over(x, 30, 45).astype(np.float32)
    given = bad.copy()
    model = Refiner.pretrained("humanact12", split="train")
    out, report = model.refine(bad, action=clip.action, return_report=True)
    np.testing.assert_array_equal(bad, given)  # the input is not modified
    err = lambda y: np.linalg.norm(y - x, axis=-1).mean()  # noqa: E731
    assert err(out) < 0.2 * err(bad), (err(out), err(bad))
    assert [(c["start"], c["stop"]) for c in report.changes if c.get("repair") == "swapped_legs"] == [(30, 45)]
    assert err(model.refine(bad, action=clip.action, mode="anchor")) > 0.8 * err(bad)  # a transition step
    monkeypatch.setattr(swapped_sides, "SWAPS", {})  # off
    assert err(model.refine(bad, action=clip.action)) > 0.8 * err(bad)


@pytest.mark.real_data
def test_relabelled_arms_trade_places_back(humanact12):
    """The training flaw ``mirror``: the arms' joints trade places as they are (no reflection) over a window."""
    clip = _walk(humanact12)
    x = clip.joints
    arms = limb_pair("humanact12", "collar")
    traded = sides_swapped(x, *arms, mirrored=False)
    np.testing.assert_array_equal(traded[:, arms[0]], x[:, arms[1]])
    np.testing.assert_array_equal(sides_swapped(traded, *arms, mirrored=False), x)
    bad = np.array(x, copy=True)
    bad[40:60] = traded[40:60]
    assert swapped_window(bad, *arms, mirrored=False)[1:] == (40, 60)
    assert swapped_window(x, *arms, mirrored=False)[0] > swapped_sides.SWAPS["relabelled_arms"][2]
    out, report = Refiner.pretrained("humanact12", split="train").refine(bad, action=clip.action, return_report=True)
    assert np.linalg.norm(out - x, axis=-1).mean() < 0.1 * np.linalg.norm(bad - x, axis=-1).mean()
    assert [(c["start"], c["stop"]) for c in report.changes if c.get("repair") == "relabelled_arms"] == [(40, 60)]


def _blended(x, pair, a, b, weight, ramp=4):
    """``x`` with ``pair``'s sides blended by ``weight`` over ``a..b-1`` (smoothstep ramps of ``ramp`` frames), as the
    training flaw ``mirror`` blends them: ``left' = (1 - w) left + w right``."""
    from refiner.core.signal import smoothstep

    t = np.arange(len(x), dtype=float)
    w = weight * smoothstep(np.clip((t - a + 1) / ramp, 0, 1)) * smoothstep(np.clip((b - t) / ramp, 0, 1))
    out = np.array(x, np.float64, copy=True)
    left, right = pair
    out[:, left] = (1 - w)[:, None, None] * x[:, left] + w[:, None, None] * x[:, right]
    out[:, right] = (1 - w)[:, None, None] * x[:, right] + w[:, None, None] * x[:, left]
    return out, w


@pytest.mark.real_data
def test_a_blended_relabelling_is_read_from_the_hips_and_undone(humanact12, monkeypatch):
    clip = _walk(humanact12)
    x = clip.joints.astype(np.float64)
    legs, arms = limb_pair("humanact12", "hip"), limb_pair("humanact12", "collar")
    assert blend_weights(x, *legs, "humanact12") is None and blend_weights(x, *arms, "humanact12") is None
    assert blend_weights(_swapped_over(x, 30, 45), *legs, "humanact12") is None  # whole swaps: SWAPS tell which kind
    bad, w = _blended(x, legs, 30, 60, 0.8)
    found = blend_weights(bad, *legs, "humanact12")
    np.testing.assert_allclose(found[w >= swapped_sides.SLIGHT], w[w >= swapped_sides.SLIGHT], atol=1e-4)
    undone, frames = unblended(bad, *legs, "humanact12")
    sure = np.abs(1 - 2 * w) >= swapped_sides.DEGENERATE
    np.testing.assert_allclose(undone[sure], x[sure], atol=1e-4)
    assert frames[30:60].all() and not frames[:25].any()
    both, _ = _blended(bad, arms, 30, 60, 0.8)
    out, report = Refiner.pretrained("humanact12", split="train").refine(both.astype(np.float32), action=clip.action,
                                                                         return_report=True)
    err = lambda y: np.linalg.norm(y - x, axis=-1).mean()  # noqa: E731
    assert err(out) < 0.3 * err(both), (err(out), err(both))
    assert {c.get("repair") for c in report.changes} >= {"unblended_legs", "unblended_arms"}
    monkeypatch.setattr(swapped_sides, "BLENDS", False)  # off: the swaps alone cannot tell a blend
    assert err(Refiner.pretrained("humanact12", split="train").refine(both.astype(np.float32), action=clip.action)) > \
        0.5 * err(both)
