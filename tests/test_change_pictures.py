"""Pictures of a refinement drawn from its report: flags only where a detector flagged, changes by step, the summary's
numbers equal to the metrics, image sizes and panels."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from refiner.core.motion import Motion
from refiner.evaluation.clip_summary import clip_figures, summary_figure
from refiner.evaluation.ground_metrics import foot_skating_ratio, ground_height
from refiner.evaluation.metrics import mpjpe
from refiner.evaluation.physics import bone_length_variation, jerk
from refiner.io import viz
from refiner.io.change_marks import STEP_COLOURS, read_marks
from refiner.io.change_scene import CONTACT_M, make_scene
from refiner.io.change_views import key_frames
from refiner.io.skeleton_drawing import FLAG
from refiner.refinement.report import RefinementReport

T = 41


def _red(image: np.ndarray) -> np.ndarray:
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return (r > 170) & (g < 90) & (b < 90)


def _report(flagged=(), changes=(), not_kept=()) -> dict:
    """A report's dict: flaw probability 0.05 but 0.9 on the ``flagged`` frames, threshold 0.7."""
    p = np.full(T, 0.05)
    p[list(flagged)] = 0.9
    return {"n_frames": T, "flaw_probability": p.tolist(), "threshold": 0.7, "flagged_frames": list(flagged),
            "changes": list(changes), "not_kept": list(not_kept), "notes": ["a note"]}


@pytest.fixture
def pair(tiny_clip):
    after = tiny_clip.copy()
    after[8:15] += np.array([0.05, 0.0, 0.0], np.float32)
    return Motion(tiny_clip), Motion(after)


def test_flags_are_the_detectors_not_the_changed_frames():
    report = _report(flagged=[10, 11, 12], changes=[{"step": "concept_snap", "start": 0, "stop": T},
                                                     {"step": "infill", "start": 8, "stop": 15, "kept": True}],
                     not_kept=[{"step": "infill", "start": 20, "stop": 25, "reason": "jerk"}])
    for given in (report, RefinementReport(mode="full", **{k: v for k, v in report.items()})):
        marks = read_marks(given, T)
        assert np.flatnonzero(marks.flagged).tolist() == [10, 11, 12]  # not the whole clip the snap changed
        assert marks.changed(True).all()
        assert np.flatnonzero(marks.changed(False)).tolist() == list(range(20, 25))
        assert marks.at(11).step == "infill"  # the most local kept change
        assert marks.at(22).step == "concept_snap" and marks.at(22).kept  # a kept change over one not kept
        assert [c.reason for c in marks.changes if not c.kept] == ["jerk"]


def test_marks_skip_entries_they_do_not_know():
    report = _report(changes=[{"step": "infill", "start": None, "stop": 4}, {"start": "3", "stop": 9}, [1, 2],
                              {"frames": [1, 2]}, {"step": "infill", "start": 30, "stop": 99},
                              {"step": "new_step", "start": 5.0, "stop": 7}],
                     not_kept=[{"step": "infill", "start": 2, "stop": 6, "reason": "jerk, slide"}])
    report.update(flagged_anchors=[3, 500], flagged_transitions=[[0, 6], [6, 12], "x"], anchors=[0, 6, 12],
                  transition_residuals_cm=[1.0, 3.0], transition_thresholds_cm=[2.0, 2.0])
    marks = read_marks(report, T)
    assert [(c.step, c.start, c.stop, c.kept) for c in marks.changes] == [
        ("infill", 30, T, True), ("new_step", 5, 7, True), ("infill", 2, 6, False)]
    assert marks.changes[2].reason == "jerk, slide"
    # anchor 3 and transition 6-12 (residual above its threshold); not 0-6 (re-timed after an anchor only)
    assert np.flatnonzero(marks.flagged).tolist() == [3, 7, 8, 9, 10, 11]
    assert marks.colour("new_step") not in STEP_COLOURS.values()
    explicit = read_marks({**report, "flagged_frames": [1, 2, 500]}, T)
    assert np.flatnonzero(explicit.flagged).tolist() == [1, 2, 3, 7, 8, 9, 10, 11]  # the detector's, with the anchors'
    assert not read_marks(None, T).flagged.any() and read_marks(None, T).changes == []
    assert not read_marks({**_report(), "flaw_probability": [0.9] * T}, T).flagged.any()  # scores alone flag nothing
    cropped = marks.crop(6)
    assert cropped.n_frames == 6 and [(c.start, c.stop) for c in cropped.changes] == [(5, 6), (2, 6)]


def test_change_figure_panels_titles_and_frames(pair, tmp_path):
    before, after = pair
    report = _report(flagged=[10, 11, 12], changes=[{"step": "infill", "start": 8, "stop": 15}],
                     not_kept=[{"step": "infill", "start": 20, "stop": 25, "reason": "jerk"}])
    fig = viz.change_figure(before, after, report, tmp_path / "k.png", frames=[5, 11, 22], title="jump")
    assert len(fig.axes) == 2 * 3 + 2 + 1  # front and side key frames, the feet from above and the side, timeline
    fronts, sides = fig.axes[:3], fig.axes[3:6]
    assert [ax.get_title() for ax in fronts] == ["t=5", "t=11 flagged", "t=22"]
    assert fronts[0].title.get_color() == "black" and fronts[1].title.get_color() == FLAG
    spine = {t: ax.spines["top"] for t, ax in zip((5, 11, 22), fronts)}
    assert spine[11].get_edgecolor()[:3] == pytest.approx(_rgb(STEP_COLOURS["infill"]))
    assert spine[11].get_linestyle() == "-" and spine[22].get_linestyle() != "-"  # 22: a change not kept
    assert spine[5].get_linewidth() < spine[11].get_linewidth()
    assert [ax.get_xlabel() for ax in sides] == ["", "infill", "infill not kept"]
    # Both poses in one panel: the before one faint, the after one solid, in the bones' own colours.
    ghost, solid = fronts[1].collections[-2:]
    assert ghost.get_alpha() < 0.5 and solid.get_alpha() in (None, 1.0)
    image = np.asarray(Image.open(tmp_path / "k.png").convert("RGB"))
    assert image.shape[1] > image.shape[0] > 400


def test_a_whole_clip_change_without_flags_draws_no_red(pair, tmp_path):
    before, after = pair
    report = _report(changes=[{"step": "concept_snap", "start": 0, "stop": T}])
    viz.change_figure(before, after, report, tmp_path / "k.png", n_keyframes=4)
    image = np.asarray(Image.open(tmp_path / "k.png").convert("RGB"))
    assert _red(image).sum() == 0
    blue = (image[..., 2] > 150) & (image[..., 0] < 80)  # the left side's bones keep their colour
    assert blue.sum() > 200


def test_animate_change_size_frames_and_flag(pair, tmp_path):
    before, after = pair
    out = viz.animate_change(before, after, _report(flagged=[10, 11, 12], changes=[{"step": "infill", "start": 8,
                                                                                      "stop": 15}]),
                             path=tmp_path / "a.gif", mp4=False, panel_size=2.0, dpi=80)
    assert out == [tmp_path / "a.gif"]
    with Image.open(out[0]) as gif:
        assert gif.size == (2 * 160, 160 + 32) and gif.n_frames == T  # front | side, caption and timeline
        frames = []
        for i in (5, 11):
            gif.seek(i)
            frames.append(np.asarray(gif.convert("RGB")))
    assert _red(frames[1]).sum() > _red(frames[0]).sum() + 10  # "flagged" in the caption of frame 11 only
    viz.animate_change(before, after, _report(changes=[{"step": "concept_snap", "start": 0, "stop": T}]),
                       path=tmp_path / "b.gif", mp4=False, panel_size=2.0, dpi=80)
    with Image.open(tmp_path / "b.gif") as gif:
        for i in (0, 20):
            gif.seek(i)
            assert _red(np.asarray(gif.convert("RGB"))).sum() == 0
    with pytest.raises(ValueError, match="share a skeleton and shape"):
        viz.animate_change(before, after.crop(0, 20), path=tmp_path / "c.gif", mp4=False)


def test_summary_numbers_are_the_metrics(pair, tmp_path):
    before, after = pair
    report = _report(flagged=[10, 11, 12], changes=[{"step": "infill", "start": 8, "stop": 15}])
    fig = summary_figure(before, after, report, tmp_path / "s.png", confidence=(0.8, 0.6), title="jump")
    bars = [[p.get_height() for p in ax.patches] for ax in fig.axes]
    ground = ground_height(before)
    moved = np.abs(after.joints - before.joints).max((1, 2)) > 0
    expected = [[jerk(before), jerk(after)],
                [foot_skating_ratio(before, ground=ground), foot_skating_ratio(after, ground=ground)],
                [100 * bone_length_variation(before), 100 * bone_length_variation(after)],
                [100 * mpjpe(after, before), 100 * mpjpe(after, before, mask=moved)],
                [0.8, 0.6]]
    assert len(bars) == 5
    for got, want in zip(bars, expected):
        np.testing.assert_allclose(got, want, rtol=1e-9)
    assert "flagged 3 of 41 frames; changed 7 (infill 7)" in fig._suptitle.get_text()
    assert clip_figures(before, after)["frames_moved"] == 7
    assert len(summary_figure(before, before).axes) == 4
    assert Image.open(tmp_path / "s.png").size[0] > 600


def test_the_scene_stands_on_the_metrics_ground_and_contact_height(pair):
    """io may not import the metrics: its ground and contact height are checked equal to theirs here."""
    import inspect

    before, after = pair
    assert make_scene(before, after, "humanact12").ground == pytest.approx(ground_height(before), abs=1e-9)
    assert CONTACT_M == inspect.signature(foot_skating_ratio).parameters["height_threshold"].default


def test_score_plot_shades_changes_and_crosses_flags(tmp_path):
    report = _report(flagged=[10, 11], changes=[{"step": "infill", "start": 8, "stop": 14}],
                     not_kept=[{"step": "infill", "start": 20, "stop": 25, "reason": "jerk"}])
    marks = read_marks(report, T)
    fig = viz.plot_scores(report["flaw_probability"], 0.7, flagged=marks.flagged, changes=marks, fps=20,
                          path=tmp_path / "p.png", label="flaw probability")
    ax = fig.axes[0]
    names = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "infill: changed" in names and "infill: not kept" in names
    crosses = {line.get_label(): line for line in ax.get_lines()}["flagged"]
    np.testing.assert_allclose(crosses.get_xdata(), [0.5, 0.55])  # frames 10 and 11 at 20 fps
    with pytest.raises(ValueError, match="T=41"):
        viz.plot_scores(report["flaw_probability"], 0.7, changes=marks.crop(20))


def test_key_frames_leave_out_an_even_frame_next_to_a_changed_run():
    mask = np.zeros(60, bool)
    mask[26:39] = mask[45:57] = True
    assert key_frames(60, mask, 8).tolist() == [0, 8, 17, 25, 32, 42, 50, 59]  # not 34 and 51, beside 32 and 50


def _rgb(colour: str) -> tuple[float, float, float]:
    from matplotlib.colors import to_rgb

    return to_rgb(colour)
