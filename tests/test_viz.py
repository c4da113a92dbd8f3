"""Tests of refiner.io.viz: rendered pixels of known poses, GIF frame counts, PNG strips and score plots."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from refiner.core.motion import Motion
from refiner.io import viz

# A T-pose in the HumanAct12 frame: metres, y DOWN, facing -z, the subject's left at +x.
_TPOSE = np.array([
    [0.00, 0.00, 0.0],    # pelvis
    [0.10, 0.05, 0.0],    # left_hip
    [-0.10, 0.05, 0.0],   # right_hip
    [0.00, -0.10, 0.0],   # spine1
    [0.10, 0.45, 0.0],    # left_knee
    [-0.10, 0.45, 0.0],   # right_knee
    [0.00, -0.20, 0.0],   # spine2
    [0.10, 0.85, 0.0],    # left_ankle
    [-0.10, 0.85, 0.0],   # right_ankle
    [0.00, -0.30, 0.0],   # spine3
    [0.10, 0.90, -0.1],   # left_foot
    [-0.10, 0.90, -0.1],  # right_foot
    [0.00, -0.50, 0.0],   # neck
    [0.08, -0.45, 0.0],   # left_collar
    [-0.08, -0.45, 0.0],  # right_collar
    [0.00, -0.65, 0.0],   # head
    [0.18, -0.48, 0.0],   # left_shoulder
    [-0.18, -0.48, 0.0],  # right_shoulder
    [0.45, -0.48, 0.0],   # left_elbow
    [-0.45, -0.48, 0.0],  # right_elbow
    [0.70, -0.48, 0.0],   # left_wrist
    [-0.70, -0.48, 0.0],  # right_wrist
    [0.78, -0.48, 0.0],   # left_hand
    [-0.78, -0.48, 0.0],  # right_hand
], dtype=np.float32)


def _tpose(skeleton: str) -> np.ndarray:
    if skeleton == "humanact12":
        return _TPOSE.copy()
    # HumanML3D: y up, facing +z, left still at +x: a half turn about x, hands dropped.
    return _TPOSE[:22] * np.array([1.0, -1.0, -1.0], dtype=np.float32)


def _ink(image: np.ndarray) -> np.ndarray:
    return image.min(axis=-1) < 200


def _red(image: np.ndarray) -> np.ndarray:
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return (r > 170) & (g < 90) & (b < 90)


def _moving_clip(n_frames: int = 10) -> np.ndarray:
    """The T-pose walking along +x and waving its arms, so every frame differs."""
    t = np.arange(n_frames, dtype=np.float32)[:, None, None]
    clip = np.repeat(_TPOSE[None], n_frames, axis=0) + np.array([0.05, 0.0, 0.0], dtype=np.float32) * t
    clip[:, 18:24, 1] += 0.03 * t[:, :, 0]  # arms drop a little every frame (y down)
    return clip


@pytest.mark.parametrize("skeleton", ["humanact12", "humanml3d"])
def test_tpose_pixels(skeleton):
    pose = _tpose(skeleton)
    before = pose.copy()
    image = viz.render_pose_image(pose, skeleton, size=(200, 200))
    np.testing.assert_array_equal(pose, before)
    assert image.shape == (200, 200, 3) and image.dtype == np.uint8
    ink = _ink(image)
    h, w = ink.shape
    assert 0.01 < ink.mean() < 0.2
    for corner in (ink[:20, :20], ink[:20, -20:], ink[-20:, :20], ink[-20:, -20:]):
        assert not corner.any()

    # The arm line: the widest row, spanning most of the width on both sides of the centre.
    rows = ink.sum(axis=1)
    arm_row = int(np.argmax(rows))
    assert rows[arm_row] > 0.6 * w
    assert ink[arm_row - 2 : arm_row + 3, int(0.15 * w)].any() and ink[arm_row - 2 : arm_row + 3, int(0.85 * w)].any()
    # Up in the data is up on screen: arms above the image centre, the head at the very top, in the middle.
    assert arm_row < 0.4 * h
    top = int(np.argmax(ink.any(axis=1)))
    assert top < arm_row
    top_cols = np.flatnonzero(ink[top])
    assert abs(top_cols.mean() - w / 2) < 0.05 * w
    # Pelvis (centre column just below the hips' height) lies below the arms; the feet are at the bottom.
    bottom = h - 1 - int(np.argmax(ink[::-1].any(axis=1)))
    assert bottom > 0.8 * h

    # Facing the viewer: the subject's left arm (blue) on screen right, right arm (green) on screen left.
    left_px = image[arm_row - 2 : arm_row + 3, int(0.8 * w)].astype(int)
    right_px = image[arm_row - 2 : arm_row + 3, int(0.2 * w)].astype(int)
    left_px = left_px[_ink(left_px)]
    right_px = right_px[_ink(right_px)]
    assert len(left_px) and len(right_px)
    assert (left_px[:, 2] > left_px[:, 1] + 40).all()  # blue
    assert (right_px[:, 1] > right_px[:, 0] + 40).all() and (right_px[:, 1] > right_px[:, 2]).all()  # green


def test_render_matches_across_frames():
    """The y-down and y-up versions of one pose give the same picture (hands aside)."""
    a = viz.render_pose_image(_tpose("humanact12")[:22].tolist() + [[0.7, -0.48, 0.0], [-0.7, -0.48, 0.0]],
                              "humanact12", size=(120, 120))
    b = viz.render_pose_image(_tpose("humanml3d"), "humanml3d", size=(120, 120))
    assert (_ink(a) != _ink(b)).mean() < 0.01


def test_render_non_square_and_one_colour():
    image = viz.render_pose_image(_TPOSE, size=(90, 160), color="black")
    assert image.shape == (90, 160, 3)
    ink = image[_ink(image)].astype(int)
    assert (ink.max(axis=1) - ink.min(axis=1)).max() <= 2  # grey levels only: no side colours
    assert (ink.max(axis=1) < 60).sum() > 100  # solid black line cores


def test_draw_pose_segments():
    from matplotlib.figure import Figure

    ax = Figure().add_subplot(1, 1, 1)
    coll = viz.draw_pose(ax, _TPOSE, "humanact12", highlight=True)
    segs = coll.get_segments()
    assert len(segs) == 23
    # Bone pelvis -> spine1 (index 2 of skeleton.bones) goes up the screen by 0.1 m.
    np.testing.assert_allclose(segs[2], [[0.0, 0.0], [0.0, 0.1]], atol=1e-6)
    np.testing.assert_allclose(coll.get_colors()[0][:3], [214 / 255, 39 / 255, 40 / 255], atol=1e-3)
    with pytest.raises(ValueError, match="3-D"):
        viz.draw_pose(ax, _TPOSE, view="3d")


def test_animate_gif_frames(tmp_path):
    before = _moving_clip(10)
    after = Motion(_moving_clip(8))
    out = viz.animate(before, after, flagged=[4], path=tmp_path / "a.gif", mp4=False)
    assert out == [tmp_path / "a.gif"]
    with Image.open(out[0]) as gif:
        assert gif.n_frames == 10  # the longer motion; the shorter one holds its last frame
        frames = []
        for i in range(gif.n_frames):
            gif.seek(i)
            frames.append(np.asarray(gif.convert("RGB")))
    assert _red(frames[4]).sum() > 500  # flagged: red frame and red bones
    assert _red(frames[3]).sum() < 20
    # Bodies do not jump: the panel edges stay put while the body walks across.
    assert (_ink(frames[0]) != _ink(frames[9])).any()


def test_animate_single_and_bad_paths(tmp_path, monkeypatch):
    out = viz.animate(Motion(_moving_clip(5)), path=tmp_path / "one.gif", fps=10, mp4=False)
    with Image.open(out[0]) as gif:
        assert gif.n_frames == 5
        assert gif.info["duration"] == 100
    with pytest.raises(ValueError, match=".gif or .mp4"):
        viz.animate(_moving_clip(5), path=tmp_path / "x.avi")
    monkeypatch.setattr("shutil.which", lambda name: None)
    with pytest.raises(ValueError, match="ffmpeg"):
        viz.animate(_moving_clip(5), path=tmp_path / "x.gif", mp4=True)
    with pytest.raises(ValueError, match="ffmpeg"):
        viz.animate(_moving_clip(5), path=tmp_path / "x.mp4")
    assert not (tmp_path / "x.gif").exists()


def test_keyframe_strip_png(tmp_path):
    clip = _moving_clip(20)
    fig = viz.keyframe_strip([clip, clip + 0.01], flagged=[3], n_keyframes=4, path=tmp_path / "s.png")
    assert len(fig.axes) == 2 * 5  # frames 0, 6, 13, 19 plus flagged 3, two rows
    titles = [ax.get_title() for ax in fig.axes[:5]]
    assert titles == ["t=0", "t=3 (flagged)", "t=6", "t=13", "t=19"]
    image = np.asarray(Image.open(tmp_path / "s.png").convert("RGB"))
    assert image.shape[1] > image.shape[0] > 100
    assert _red(image).sum() > 300
    fig = viz.keyframe_strip(Motion(clip), frames=[5, 1], path=tmp_path / "t.png")
    assert [ax.get_title() for ax in fig.axes] == ["t=5", "t=1"]
    # Fixed limits for the whole motion: every panel has the same limits.
    assert len({ax.get_xlim() for ax in fig.axes}) == 1


def test_keyframe_strip_and_score_plot_titles_and_legends(tmp_path):
    """Both figures can name the action; the strip explains its colours; the threshold names its quantity."""
    fig = viz.keyframe_strip([_moving_clip(20)] * 2, flagged=[3], n_keyframes=3, title="jump: generated vs refined")
    assert fig._suptitle.get_text() == "jump: generated vs refined"
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["left side", "right side", "centre", "flagged frame"]
    fig = viz.plot_scores(np.linspace(0, 1, 30), 0.25, label="anchor probability", title="jump")
    ax = fig.axes[0]
    assert ax.get_title() == "jump"
    assert "anchor probability threshold = 0.25" in [t.get_text() for t in ax.get_legend().get_texts()]


def test_plot_scores_png(tmp_path):
    scores = np.linspace(0.0, 2.0, 30)
    fig = viz.plot_scores(scores, 1.5, anchors=[0, 10, 20, 29], flagged=[29], path=tmp_path / "p.png")
    assert (tmp_path / "p.png").stat().st_size > 1000
    ax = fig.axes[0]
    lines = {line.get_label(): line for line in ax.get_lines()}
    np.testing.assert_allclose(lines["anchor score threshold = 1.5"].get_ydata(), [1.5, 1.5])
    np.testing.assert_allclose(lines["anchors"].get_xdata(), [0, 10, 20, 29])
    np.testing.assert_allclose(lines["flagged"].get_ydata(), [2.0])


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: viz.render_pose_image(np.zeros((23, 3))), "shape"),
        (lambda: viz.render_pose_image(np.zeros((10, 24, 3))), "shape"),
        (lambda: viz.render_pose_image(np.where(np.eye(24, 3) > 0, np.nan, _TPOSE)), "NaN"),
        (lambda: viz.render_pose_image(_TPOSE, size=(0, 10)), "size"),
        (lambda: viz.render_pose_image(_TPOSE, view="top"), "view"),
        (lambda: viz.keyframe_strip(np.zeros((20, 22, 3))), "J=24"),
        (lambda: viz.keyframe_strip(np.zeros((20, 24))), "Motion"),
        (lambda: viz.keyframe_strip(_moving_clip(5), frames=[7]), "frame indices in 0..4"),
        (lambda: viz.keyframe_strip(_moving_clip(5), flagged=np.ones(4, bool)), "length T=5"),
        (lambda: viz.keyframe_strip([_moving_clip(5), _moving_clip(5)], labels=["a"]), "labels"),
        (lambda: viz.plot_scores(np.array([0.1, np.nan]), 0.5), "NaN"),
        (lambda: viz.plot_scores(np.zeros((3, 2)), 0.5), "shape"),
        (lambda: viz.plot_scores(np.zeros(3), float("nan")), "threshold"),
        (lambda: viz.plot_scores(np.zeros(3), 0.5, anchors=[3]), "anchors"),
        (lambda: viz.plot_scores(np.zeros(3), 0.5, anchors=[0.5]), "integer"),
        (lambda: viz.plot_scores(np.zeros(3), 0.5, path="scores.jpg"), ".png"),
        (lambda: viz.keyframe_strip(_moving_clip(5), path="/no/such/folder/s.png"), "does not exist"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_keyframe_strip_nan_motion():
    clip = _moving_clip(5)
    clip[2, 3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        viz.keyframe_strip([_moving_clip(5), clip])
    assert np.isnan(clip[2, 3, 1])  # caller's array untouched


@pytest.mark.real_data
def test_real_clip_upright(humanact12, tmp_path):
    """Real y-down HumanAct12 clips stand upright: the head is drawn above the pelvis and the feet below."""
    from matplotlib.figure import Figure

    skel = humanact12[0].skeleton_info
    bones = [tuple(b) for b in skel.bones.tolist()]
    neck_head = bones.index((skel.index("neck"), skel.index("head")))
    pelvis_hip = bones.index((skel.root, skel.index("left_hip")))
    ankle_foot = bones.index((skel.index("left_ankle"), skel.index("left_foot")))
    for motion in (humanact12[0], humanact12[600]):
        assert (motion.joints[:, skel.index("head"), 1] < motion.joints[:, skel.root, 1]).all()  # y down in the data
        ax = Figure().add_subplot(1, 1, 1)
        for t in (0, motion.n_frames // 2, motion.n_frames - 1):
            segs = viz.draw_pose(ax, motion.joints[t], skel).get_segments()
            head_y, pelvis_y, foot_y = segs[neck_head][1, 1], segs[pelvis_hip][0, 1], segs[ankle_foot][1, 1]
            assert head_y > pelvis_y + 0.3 > foot_y + 0.6
    fig = viz.keyframe_strip(humanact12[0], n_keyframes=3, path=tmp_path / "real.png")
    assert len(fig.axes) == 3 and (tmp_path / "real.png").is_file()
