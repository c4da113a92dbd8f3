"""``motion-refiner demo`` on the tiny configuration: every file, consistent numbers, the printed table."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from refiner.cli.main import main

PER_ACTION = ("{}.gif", "{}_keyframes.png", "{}_scores.png", "{}_summary.png", "{}_before.npy", "{}_after.npy", "{}_report.json")


pytestmark = pytest.mark.usefixtures("one_torch_thread")

@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """The quick demo through the CLI, once: ``(folder, printed text)``."""
    import contextlib
    import io

    import torch

    out = tmp_path_factory.mktemp("demo")
    buffer = io.StringIO()
    threads = torch.get_num_threads()
    try:
        with contextlib.redirect_stdout(buffer):
            code = main(["demo", "--out", str(out), "--quick", "--no-mp4"])
    finally:
        torch.set_num_threads(threads)  # the CLI sets one thread for its process
    assert code == 0
    return out, buffer.getvalue()


@pytest.mark.real_data
def test_quick_demo_writes_every_file(demo_run):
    from PIL import Image

    out, printed = demo_run
    for stem in ("01_walk", "10_boxing"):
        for pattern in PER_ACTION:
            path = out / pattern.format(stem)
            assert path.is_file() and path.stat().st_size > 0, path
        before, after = np.load(out / f"{stem}_before.npy"), np.load(out / f"{stem}_after.npy")
        assert before.shape == after.shape == (60, 24, 3)
        np.testing.assert_allclose(before[0, 0], 0.0, atol=1e-6)
        report = json.loads((out / f"{stem}_report.json").read_text())
        assert report["n_frames"] == 60 and len(report["flaw_probability"]) == 60  # the default refiner's
        assert report["threshold_quantity"] == "flaw_probability" and 0 < report["threshold"] < 1
        changed = np.zeros(60, dtype=bool)
        for c in report["changes"]:
            changed[c["start"]:c["stop"]] = True
        # Only reported frames may move; untouched frames are bit-identical.
        np.testing.assert_array_equal(before[~changed], after[~changed])
        with Image.open(out / f"{stem}.gif") as gif:
            assert gif.n_frames == 24  # the quick animation shows the first 24 frames
        with Image.open(out / f"{stem}_keyframes.png") as png:
            assert 2 * png.size[1] < png.size[0] < 10 * png.size[1]  # a strip: two rows, 6 to 12 columns
    summary = json.loads((out / "summary.json").read_text())
    assert [r["action_name"] for r in summary["rows"]] == ["walk", "boxing"]
    for row in summary["rows"]:
        assert 0.0 <= row["confidence_before"] <= 1.0 and 0.0 <= row["confidence_after"] <= 1.0
        assert row["frames_changed"] <= row["frames"] and row["frames_flagged"] <= row["frames"]
        report = json.loads((out / f"{row['action']:02d}_{row['action_name']}_report.json").read_text())
        changed = np.zeros(60, dtype=bool)
        for c in report["changes"]:
            changed[c["start"]:c["stop"]] = True
        assert row["frames_changed"] == int(changed.sum())
        assert row["frames_flagged"] == len(report["flagged_frames"])
    assert "| walk |" in printed and "| boxing |" in printed and "confidence before" in printed
    assert (out / "summary.md").read_text().count("\n|") >= 4


@pytest.mark.real_data
def test_demo_recogniser_confidence_matches_a_direct_call(demo_run):
    """The table's 'before' confidence is the recogniser's softmax of the saved clip (fixed hidden state)."""
    from refiner.evaluation.evaluators import load_recognizer

    out, _ = demo_run
    summary = json.loads((out / "summary.json").read_text())
    rec = load_recognizer("humanact12", hidden="fixed")
    clips = np.stack([np.load(out / f"{r['action']:02d}_{r['action_name']}_before.npy") for r in summary["rows"]])
    logits = rec.predict_logits(clips, crop="start").astype(np.float64)
    p = np.exp(logits - logits.max(1, keepdims=True))
    p /= p.sum(1, keepdims=True)
    for i, r in enumerate(summary["rows"]):
        assert abs(p[i, r["action"]] - r["confidence_before"]) < 1e-3


@pytest.mark.real_data
@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg not on PATH")
def test_demo_writes_mp4_when_ffmpeg_exists(tmp_path):
    from refiner.cli.demo import run_demo

    result = run_demo(tmp_path, actions=["jump"], quick=True)
    assert (tmp_path / "03_jump.mp4").is_file() and "03_jump.mp4" in result.rows[0].files


def test_demo_rejects_unknown_generator_and_action(tmp_path):
    from refiner.cli.demo import run_demo

    with pytest.raises(ValueError, match="unknown action 'fly'"):
        run_demo(tmp_path, actions=["fly"])
    with pytest.raises(ValueError, match="unknown reference generator"):
        run_demo(tmp_path, generator="no_such_kind")


def test_strip_shows_even_frames_and_one_per_flagged_run():
    from refiner.cli.demo import strip_frames

    np.testing.assert_array_equal(strip_frames(60, [], 4), [0, 20, 39, 59])
    np.testing.assert_array_equal(strip_frames(60, [30, 31, 32, 50], 4), [0, 20, 31, 39, 50, 59])
    assert len(strip_frames(60, np.arange(60), 8)) == 9  # a clip changed throughout: one run, its middle frame
    np.testing.assert_array_equal(strip_frames(60, np.arange(0, 60, 2), 4), [0, 2, 4, 6, 20, 39, 59])  # 30 runs: 4


def test_summary_row_says_total_for_counts_and_mean_for_confidence():
    from refiner.cli.demo import DemoRow, format_table

    rows = [DemoRow(action=a, action_name=n, frames=60, frames_changed=c, frames_flagged=1,
                    confidence_before=b, confidence_after=b, predicted_before=n, predicted_after=n, files=[])
            for a, n, c, b in ((0, "warm_up", 59, 0.2), (1, "walk", 0, 0.6))]
    last = format_table(rows).splitlines()[-1]
    assert last.startswith("| **total; mean confidence** | 59/120 | 2/120 | 0.400 | 0.400 |")


def test_a_demo_that_changed_nothing_says_why():
    from refiner.cli.demo import DemoRow, unchanged_note

    def row(changed, flagged):
        return DemoRow(action=0, action_name="walk", frames=60, frames_changed=changed, frames_flagged=flagged,
                       confidence_before=0.5, confidence_after=0.5, predicted_before="walk", predicted_after="walk")
    assert unchanged_note([row(3, 5), row(0, 0)]) == ""
    assert "no frame was flagged" in unchanged_note([row(0, 0), row(0, 0)])
    assert "7 flagged frames left as given" in unchanged_note([row(0, 7), row(0, 0)])
    assert "1 flagged frame left as given" in unchanged_note([row(0, 1)])


@pytest.mark.real_data
def test_demo_refuses_to_overwrite_its_files_without_force(demo_run, tmp_path, capsys):
    """Like `refine`: existing outputs are never replaced without --force, and nothing is written first."""
    from refiner.cli.demo import run_demo

    out, _ = demo_run
    before = (out / "summary.json").read_bytes()
    assert main(["demo", "--out", str(out), "--quick", "--no-mp4"]) == 2
    err = capsys.readouterr().err
    assert "refusing to overwrite 01_walk.gif" in err and "--force" in err
    assert (out / "summary.json").read_bytes() == before
    (tmp_path / "03_jump.gif").write_bytes(b"stale")
    (tmp_path / "notes.txt").write_text("not the demo's")  # other files do not block the demo
    with pytest.raises(ValueError, match="refusing to overwrite 03_jump.gif"):
        run_demo(tmp_path, actions=["jump"], quick=True, mp4=False)
    result = run_demo(tmp_path, actions=["jump"], quick=True, mp4=False, overwrite=True)
    assert (tmp_path / "03_jump.gif").stat().st_size > 1000 and result.rows[0].action_name == "jump"
