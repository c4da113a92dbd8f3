"""``motion-refiner refine``: round trip on a real clip, reports, GIF and BVH, batches, failures, no overwrite."""
from __future__ import annotations

import json

import numpy as np
import pytest

from refiner.cli.main import main


pytestmark = pytest.mark.usefixtures("one_torch_thread")

@pytest.fixture(scope="module")
def clip(humanact12):
    """A real 60-frame HumanAct12 clip (subject 11, held out), first-frame root at the origin."""
    test = humanact12.split("test")
    motion = next(m for m in test.motions if m.n_frames >= 60 and m.action == 1)
    return motion.crop(0, 60).normalized().joints.copy()


@pytest.mark.real_data
def test_round_trip_with_report_gif_and_bvh(clip, tmp_path, capsys):
    from refiner.io.bvh import load_bvh

    src = tmp_path / "walk.npy"
    np.save(src, clip)
    out = tmp_path / "out" / "walk_refined.npy"
    code = main(["refine", str(src), "-o", str(out), "--action", "walk", "--report", "--gif", "--bvh"])
    assert code == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    # a real held-out walk needs nothing, and the user is told so rather than left to guess
    assert "(0 of 60 frames changed)" in printed and "refined 1 of 1 file(s), 0 of 60 frames changed" in printed
    np.testing.assert_array_equal(np.load(src), clip)  # the input is untouched
    refined = np.load(out)
    assert refined.shape == clip.shape and refined.dtype == np.float32
    report = json.loads((tmp_path / "out" / "walk_refined.report.json").read_text())
    (clip_report,) = report["clips"]
    assert clip_report["action"] == 1 and clip_report["n_frames"] == 60 and report["mode"] == "full"
    assert report["method"] == "motion" and clip_report["threshold_quantity"] == "flaw_probability"
    changed = np.zeros(60, dtype=bool)
    for c in clip_report["changes"]:
        changed[c["start"]:c["stop"]] = True
    np.testing.assert_array_equal(refined[~changed], clip[~changed])
    assert np.abs(refined - clip).max() < 0.25  # real mocap is barely moved
    joints, names = load_bvh(tmp_path / "out" / "walk_refined.bvh")
    assert names[0] == "pelvis" and joints.shape == (60, 24, 3)
    assert np.linalg.norm(joints - refined, axis=-1).max() < 1e-3  # within 1 mm
    assert (tmp_path / "out" / "walk_refined.gif").stat().st_size > 1000
    from PIL import Image

    with Image.open(tmp_path / "out" / "walk_refined.gif") as gif:
        assert gif.size[0] == 2 * 320  # two panels of the default 320 px (was 307 px in all)


@pytest.mark.real_data
def test_refuses_to_overwrite_without_force(clip, tmp_path, capsys):
    src, out = tmp_path / "a.npy", tmp_path / "b.npy"
    np.save(src, clip[:30])
    np.save(out, np.zeros(3))
    assert main(["refine", str(src), "-o", str(out), "--method", "concepts", "--mode", "transition"]) == 1
    err = capsys.readouterr().err
    assert "refusing to overwrite" in err and "--force" in err
    np.testing.assert_array_equal(np.load(out), np.zeros(3))
    assert main(["refine", str(src), "-o", str(out), "--method", "concepts", "--mode", "transition", "--force"]) == 0
    assert np.load(out).shape == (30, 24, 3)


@pytest.mark.real_data
def test_batch_reports_bad_files_and_continues(clip, tmp_path, capsys):
    folder = tmp_path / "in"
    folder.mkdir()
    np.save(folder / "good.npy", np.stack([clip[:40], clip[20:60]]))  # a batch (N, T, J, 3)
    np.save(folder / "bad_shape.npy", np.zeros((10, 5)))
    (folder / "corrupt.npz").write_bytes(b"not a zip file")
    np.save(folder / "nan.npy", np.full((20, 24, 3), np.nan, dtype=np.float32))
    (folder / "notes.txt").write_text("ignored")
    code = main(["refine", str(folder), "-o", str(tmp_path / "out"), "--method", "concepts", "--mode", "anchor"])
    captured = capsys.readouterr()
    assert code == 1
    for name in ("bad_shape.npy", "corrupt.npz", "nan.npy"):
        assert f"FAILED {folder / name}" in captured.err
    assert "(T, J, 3)" in captured.err and "NaN" in captured.err
    assert "refined 1 of 4 file(s), " in captured.out and "frames changed; 3 failed" in captured.out
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["good.npy"]
    assert np.load(tmp_path / "out" / "good.npy").shape == (2, 40, 24, 3)


@pytest.mark.real_data
def test_raw_generator_output_through_an_adapter(clip, tmp_path, capsys):
    from refiner.adapters.action2motion import joints_to_lie, lie_to_joints

    lie = joints_to_lie(clip[None])  # Action2Motion's Lie layout (1, 60, 72)
    np.savez(tmp_path / "a2m.npz", output=lie, action=np.array([1]))
    code = main(["refine", str(tmp_path / "a2m.npz"), "-o", str(tmp_path / "out"), "--adapter", "action2motion",
                 "--option", "representation=lie", "--report"])
    assert code == 0, capsys.readouterr().err
    refined = np.load(tmp_path / "out" / "a2m.npy")
    assert refined.shape == (1, 60, 24, 3)
    report = json.loads((tmp_path / "out" / "a2m.report.json").read_text())
    assert report["adapter"] == "action2motion" and report["clips"][0]["action"] == 1
    decoded = lie_to_joints(lie)[0]  # the adapter's decoding with the default bone lengths
    changed = np.zeros(60, dtype=bool)
    for c in report["clips"][0]["changes"]:
        changed[c["start"]:c["stop"]] = True
    np.testing.assert_allclose(refined[0][~changed], decoded[~changed], atol=1e-5)


def test_usage_errors(tmp_path, capsys):
    np.save(tmp_path / "x.npy", np.zeros((10, 24, 3)))
    assert main(["refine", str(tmp_path / "missing.npy"), "-o", str(tmp_path / "o.npy")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["refine", str(tmp_path / "x.npy"), "-o", str(tmp_path / "o"), "--option", "a=1"]) == 2
    assert "--adapter" in capsys.readouterr().err
    assert main(["refine", str(tmp_path / "x.npy"), "-o", str(tmp_path / "o"), "--adapter", "nope"]) == 2
    assert "unknown adapter 'nope'" in capsys.readouterr().err
    assert main(["refine", str(tmp_path), "-o", str(tmp_path / "o.npy")]) == 2
    assert "must be a folder" in capsys.readouterr().err


@pytest.mark.real_data
def test_inputs_that_would_share_an_output_are_refused_before_writing(clip, tmp_path, capsys):
    folder = tmp_path / "in"
    folder.mkdir()
    np.save(folder / "clip.npy", clip)
    np.savez(folder / "clip.npz", joints=clip)
    out = tmp_path / "out"
    code = main(["refine", str(folder), "-o", str(out), "--force"])
    assert code == 2 and "same output (clip.npy)" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())  # nothing written, so nothing lost


@pytest.mark.real_data
def test_single_file_gif_shows_progress_and_takes_a_size(clip, tmp_path, capsys):
    from PIL import Image

    src = tmp_path / "walk.npy"
    np.save(src, clip[:30])
    code = main(["refine", str(src), "-o", str(tmp_path / "o.npy"), "--gif", "--gif-size", "160"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert f"refining {src} and drawing its GIF ..." in captured.out
    assert "drawing o.gif" in captured.err and "30/30" in captured.err  # the frame bar
    with Image.open(tmp_path / "o.gif") as gif:
        assert gif.size == (2 * 160, 160 + 32) and gif.n_frames == 30
    with pytest.raises(SystemExit):
        main(["refine", str(src), "-o", str(tmp_path / "p.npy"), "--gif", "--gif-size", "0"])


@pytest.mark.real_data
def test_batch_file_errors_name_the_clip(clip, tmp_path, capsys):
    batch = np.stack([clip[:40]] * 3)
    batch[2, 7, 4, 1] = np.nan
    np.save(tmp_path / "nan_batch.npy", batch)
    assert main(["refine", str(tmp_path / "nan_batch.npy"), "-o", str(tmp_path / "out")]) == 1
    assert "nan_batch.npy: clip 2 of 3: `joints` contains 1 NaN" in capsys.readouterr().err
    np.save(tmp_path / "cm_batch.npy", np.stack([clip[:40], clip[:40] * 100]))
    assert main(["refine", str(tmp_path / "cm_batch.npy"), "-o", str(tmp_path / "out")]) == 1
    assert "clip 1 of 2" in (err := capsys.readouterr().err) and "centimetres" in err


@pytest.mark.real_data
def test_concept_snap_option(clip, tmp_path, capsys):
    src, out = tmp_path / "walk.npy", tmp_path / "snapped.npy"
    np.save(src, clip)
    snap = ["--method", "concepts", "--action", "walk", "--concept-snap"]
    assert main(["refine", str(src), "-o", str(out), *snap, "1", "--report"]) == 0
    report = json.loads((tmp_path / "snapped.report.json").read_text())
    assert report["method"] == "concepts"
    assert "concept_snap" in [c["step"] for c in report["clips"][0]["changes"]]
    assert np.abs(np.load(out) - clip).max() > 0.01  # the real walk that needs nothing is snapped all the same
    assert main(["refine", str(src), "-o", str(out), *snap, "2", "--force"]) == 2
    assert "concept_snap" in capsys.readouterr().err
    assert main(["refine", str(src), "-o", str(out), "--method", "concepts", "--concept-snap", "1", "--force"]) == 2
    assert "needs `--action`" in capsys.readouterr().err  # no action to snap to


@pytest.mark.real_data
def test_method_option_and_the_concepts_methods_options(clip, tmp_path, capsys):
    """``--method`` picks the refiner; ``--mode``, ``--concept-snap`` and ``--refiner`` are the concepts method's, refused
    with the default; ``--refiner DIR`` loads a saved concepts refiner; the learned method's options are gone."""
    from refiner.refinement.pipeline import Refiner

    src = tmp_path / "walk.npy"
    np.save(src, clip[:40])
    for extra, named in ((["--mode", "anchor"], "--mode"), (["--concept-snap", "1", "--action", "walk"], "--concept-snap"),
                         (["--method", "motion", "--refiner", str(tmp_path)], "--refiner")):
        assert main(["refine", str(src), "-o", str(tmp_path / "x.npy"), *extra]) == 2
        err = capsys.readouterr().err
        assert f"{named} belongs to `--method concepts`" in err
    assert not (tmp_path / "x.npy").exists()
    for gone in (["--texture", "all"], ["--misread-snap", "1"], ["--method", "learned"]):
        with pytest.raises(SystemExit) as exit_:
            main(["refine", str(src), "-o", str(tmp_path / "x.npy"), *gone])
        assert exit_.value.code == 2
        capsys.readouterr()
    saved = tmp_path / "concepts"
    Refiner.pretrained("humanact12", split="train").save(saved)
    assert main(["refine", str(src), "-o", str(tmp_path / "c.npy"), "--refiner", str(saved), "--mode", "anchor",
                 "--report"]) == 0  # --refiner: the concepts method without naming it
    report = json.loads((tmp_path / "c.report.json").read_text())
    assert report["method"] == "concepts" and report["mode"] == "anchor"
    np.testing.assert_array_equal(np.load(tmp_path / "c.npy"),
                                  Refiner.load(saved).refine(clip[:40], mode="anchor"))
