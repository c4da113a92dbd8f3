"""MDM adapter: results.npy in MDM's exact layout, refined through the CLI, written back in that layout."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from refiner.adapters import mdm
from refiner.adapters.humanml3d import canonicalize_humanml3d
from refiner.cli.main import main
from refiner.core.motion import Motion
from refiner.core.rotations import yup_to_ydown
from refiner.core.skeleton_conversion import convert

pytestmark = pytest.mark.usefixtures("one_torch_thread")

T, LENGTHS = 80, (80, 50, 72)  # MDM pads every clip to the batch's frames; lengths say how many are real


def humanml3d_clip(motion, n: int) -> np.ndarray:
    """A real HumanAct12 clip as HumanML3D joints ``(n, 22, 3)``: y up, frame 0 at x = z = 0 facing +z, floor at 0."""
    joints = canonicalize_humanml3d(convert(motion.joints[:n], "humanact12", "humanml3d"))
    joints[..., 1] -= joints[..., 1].min()
    return joints.astype(np.float32)


def results_dict(clips) -> dict:
    """What MDM's sample/generate.py passes to np.save: motion (N, 22, 3, T) float32, lengths int64, text, counts."""
    rng = np.random.default_rng(0)
    motion = rng.normal(0.0, 0.3, size=(len(clips), 22, 3, T)).astype(np.float32)  # padding: the model's own frames
    for i, c in enumerate(clips):
        motion[i, ..., :len(c)] = c.transpose(1, 2, 0)
    return {"motion": motion, "text": ["a person walks", "a person jumps", "a person lifts a dumbbell"],
            "lengths": np.array([len(c) for c in clips], dtype=np.int64), "num_samples": 3, "num_repetitions": 1}


@pytest.fixture(scope="module")
def clips(humanact12):
    """Three held-out clips (subjects 11-12), two with a 20-frame hold (a freeze, then a jump) for the refiner."""
    long = [m for m in humanact12.split("test").motions if m.n_frames >= T]
    out = [humanml3d_clip(long[i], k) for i, k in zip((3, 0, 8), LENGTHS)]
    for c in (out[0], out[2]):
        c[25:45] = c[25]
    return out


def changed_frames(clip_report: dict) -> np.ndarray:
    """``(T,)`` bool: the frames a report's kept changes cover (padding never)."""
    changed = np.zeros(T, dtype=bool)
    for c in clip_report["changes"]:
        changed[c["start"]:c["stop"]] = True
    return changed


@pytest.mark.real_data
def test_results_npy_round_trip_keeps_mdm_layout(clips, tmp_path, capsys):
    """refine results.npy --adapter mdm: MDM's own loader reads the output; only the refined frames differ, and they
    are the refiner's own output on the HumanML3D joints (whichever skeleton the clips were refined on)."""
    import refiner

    src = tmp_path / "mdm_out" / "results.npy"
    src.parent.mkdir()
    original = results_dict(clips)
    np.save(src, original)
    before_bytes = src.read_bytes()
    outputs = {}
    for skeleton in ("humanact12", "humanml3d"):  # the default: through the adapter's conversion; or as given
        out_dir = tmp_path / skeleton
        args = ["refine", str(src), "--adapter", "mdm", "-o", str(out_dir), "--report", "--skeleton", skeleton]
        assert main(args) == 0, capsys.readouterr().err
        assert src.read_bytes() == before_bytes  # the input file is untouched
        refined = np.load(out_dir / "results.npy", allow_pickle=True).item()  # MDM's own code path (vis_utils.npy2obj)
        assert list(refined) == list(original)
        assert refined["motion"].shape == original["motion"].shape and refined["motion"].dtype == np.float32
        assert refined["lengths"].dtype == original["lengths"].dtype
        np.testing.assert_array_equal(refined["lengths"], original["lengths"])
        assert refined["text"] == original["text"]
        assert (refined["num_samples"], refined["num_repetitions"]) == (3, 1)
        report = json.loads((out_dir / "results.report.json").read_text())
        assert [c["n_frames"] for c in report["clips"]] == list(LENGTHS)
        for i, clip_report in enumerate(report["clips"]):
            changed = changed_frames(clip_report)
            new, old = refined["motion"][i], original["motion"][i]
            np.testing.assert_array_equal(new[..., ~changed], old[..., ~changed])  # unflagged and padding: same bits
        outputs[skeleton] = refined["motion"]
    assert (outputs["humanml3d"] != original["motion"]).any(), "no frame refined: the write-back went untested"
    assert "frames changed" in capsys.readouterr().out
    for i, (clip, k) in enumerate(zip(clips, LENGTHS)):
        direct = refiner.refine(clip, skeleton="humanml3d")  # (k, 22, 3): MDM's frame, refined in memory
        np.testing.assert_array_equal(outputs["humanml3d"][i, ..., :k], direct.transpose(1, 2, 0))
        np.testing.assert_allclose(outputs["humanact12"][i, ..., :k], direct.transpose(1, 2, 0), atol=1e-6)


@pytest.mark.real_data
def test_one_sample_array_round_trip(clips, tmp_path, capsys):
    """One sample, ``results['motion'][i]`` saved alone as (22, 3, T): read and written back as such (no pickle)."""
    sample = results_dict(clips)["motion"][0]
    src = tmp_path / "sample00_rep00.npy"
    np.save(src, sample)
    assert main(["refine", str(src), "--adapter", "mdm", "-o", str(tmp_path / "out"), "--report"]) == 0, \
        capsys.readouterr().err
    refined = np.load(tmp_path / "out" / "sample00_rep00.npy", allow_pickle=False)
    assert refined.shape == sample.shape and refined.dtype == sample.dtype
    (clip_report,) = json.loads((tmp_path / "out" / "sample00_rep00.report.json").read_text())["clips"]
    changed = changed_frames(clip_report)
    np.testing.assert_array_equal(refined[..., ~changed], sample[..., ~changed])


def test_put_back_writes_only_the_change_in_mdm_frame():
    """A known change on the HumanAct12-frame motions lands, turned back to y up, on exactly those frames."""
    rng = np.random.default_rng(1)
    results = {"motion": rng.normal(size=(2, 22, 3, 30)).astype(np.float32), "lengths": np.array([30, 12]),
               "text": ["x", "y"], "extra": {"kept": True}}
    copy = {key: results[key].copy() for key in ("motion", "lengths")}
    for skeleton in ("humanact12", "humanml3d"):
        before = mdm.to_motions(results, skeleton=skeleton)
        joints = 24 if skeleton == "humanact12" else 22  # hands added on the way in, dropped on the way back
        assert [m.joints.shape for m in before] == [(30, joints, 3), (12, joints, 3)]
        shift = np.zeros_like(before[1].joints)
        shift[4:7, :22] = [0.01, 0.02, 0.03]
        after = [before[0], Motion(before[1].joints + shift, skeleton=skeleton)]
        new = mdm.put_back(results, before, after)
        assert new is not results and new["extra"] is results["extra"] and list(new) == list(results)
        expected = results["motion"].copy()
        step = yup_to_ydown(np.array([0.01, 0.02, 0.03])) if skeleton == "humanact12" else np.array([0.01, 0.02, 0.03])
        expected[1, :, :, 4:7] = (expected[1, :, :, 4:7].astype(np.float64) + step[None, :, None]).astype(np.float32)
        np.testing.assert_allclose(new["motion"], expected, atol=1e-6)
        changed = np.zeros(30, dtype=bool)
        changed[4:7] = True
        np.testing.assert_array_equal(new["motion"][1][..., ~changed], results["motion"][1][..., ~changed])
        np.testing.assert_array_equal(new["motion"][0], results["motion"][0])
    for key in ("motion", "lengths"):  # the input is never modified
        np.testing.assert_array_equal(results[key], copy[key])


def test_action_to_motion_files_are_humanact12():
    motion = np.random.default_rng(2).normal(size=(2, 24, 3, 60)).astype(np.float32)
    motions = mdm.to_motions({"motion": motion, "lengths": np.array([60, 60])})
    assert [m.skeleton for m in motions] == ["humanact12"] * 2
    np.testing.assert_array_equal(motions[0].joints, motion[0].transpose(2, 0, 1))
    with pytest.raises(ValueError, match="converts to skeleton 'humanact12'"):
        mdm.to_motions(motion, skeleton="humanml3d")


def good():
    return {"motion": np.zeros((2, 22, 3, 20), np.float32), "lengths": np.array([20, 10]), "text": ["a", "b"]}


@pytest.mark.parametrize("bad, words", [
    ({k: v for k, v in good().items() if k != "motion"}, "must hold the key 'motion'"),
    ({**good(), "motion": np.zeros((2, 20, 22, 3), np.float32)}, r"shape \(N, 22, 3, T\)"),
    ({**good(), "motion": np.zeros((2, 21, 3, 20), np.float32)}, "KIT-ML's 21 joints"),
    ({**good(), "motion": np.where(np.arange(20) == 3, np.nan, 0.0).astype(np.float32) * np.ones((2, 22, 3, 1))},
     "clip 0 holds NaN or Inf in its 20 valid frames"),
    ({**good(), "lengths": np.array([20, 21])}, r"lengths` must be in 2..20"),
    ({**good(), "lengths": np.array([20])}, "must be 2 integers"),
    ({"motion": np.zeros((0, 22, 3, 20), np.float32), "lengths": np.zeros(0, np.int64)}, "holds no clips"),
    ({"thetas": 0, "root_translation": 0, "vertices": 0, "motion": 0}, "per-sample SMPL fit"),
])
def test_malformed_results_are_value_errors(bad, words):
    with pytest.raises(ValueError, match=words):
        mdm.to_motions(bad)


def test_nan_in_padding_is_left_alone():
    results = good()
    results["motion"][1, ..., 15] = np.nan  # beyond lengths[1] = 10: never read, never written
    assert [m.n_frames for m in mdm.to_motions(results)] == [20, 10]


def test_write_refined_writes_the_path_it_is_given_whole(tmp_path):
    """The hook writes exactly ``path`` (np.save would add .npy to a bare name), by rename, and MDM's loader reads it."""
    results = good()
    before = mdm.to_motions(results, skeleton="humanml3d")
    after = [before[0], Motion(before[1].joints + 0.5, skeleton="humanml3d")]
    target = tmp_path / "refined_results"
    assert mdm.refiner_write_refined(path=target, output=results, before=before, after=after) == target
    assert sorted(p.name for p in tmp_path.iterdir()) == ["refined_results"]  # no .npy twin, no temporary file
    written = np.load(target, allow_pickle=True).item()
    np.testing.assert_array_equal(written["motion"][0], results["motion"][0])
    np.testing.assert_allclose(written["motion"][1, ..., :10], 0.5)
    np.testing.assert_array_equal(written["motion"][1, ..., 10:], 0.0)  # padding as given


class _RunsCode:
    def __reduce__(self):
        return (os.system, ("echo pwned",))


def test_a_pickle_naming_code_is_refused_before_anything_runs(tmp_path, capsys):
    src = tmp_path / "results.npy"
    np.save(src, np.array({"motion": _RunsCode()}, dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match="only arrays are loaded"):
        mdm.read_results(src)
    assert main(["refine", str(src), "--adapter", "mdm", "-o", str(tmp_path / "out")]) == 1
    captured = capsys.readouterr()
    assert "only arrays are loaded" in captured.err and "pwned" not in captured.out
    assert not (tmp_path / "out").exists()


@pytest.mark.real_data
def test_a_writer_that_declines_gets_the_joints_written(clips, tmp_path, capsys, monkeypatch):
    """A plugin's own-format writer may return None (it wrote nothing): the CLI then writes the refined joints."""
    from refiner.plugins.manager import PluginManager

    monkeypatch.setattr(PluginManager, "write_refined", lambda self, *a, **k: None)
    src = tmp_path / "sample00_rep00.npy"
    np.save(src, results_dict(clips)["motion"][0])
    assert main(["refine", str(src), "--adapter", "mdm", "-o", str(tmp_path / "out")]) == 0, capsys.readouterr().err
    joints = np.load(tmp_path / "out" / "sample00_rep00.npy")
    assert joints.ndim == 4 and joints.shape[-2:] == (24, 3)  # (1, T, J, 3) joints, not MDM's (22, 3, T)
