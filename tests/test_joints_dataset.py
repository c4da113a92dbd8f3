"""`--dataset joints`: user clips from a folder or an .npz, and `motion-refiner train` on them."""
from __future__ import annotations

import csv
from collections import OrderedDict

import numpy as np
import pytest

from refiner.io.joints_dataset import load_joints_dataset


def _write_folder(folder, clips, labels, subjects=None):
    folder.mkdir(parents=True, exist_ok=True)
    for k, clip in enumerate(clips):
        np.save(folder / f"c{k:02d}.npy", clip)
    with open(folder / "labels.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["name", "action"] + (["subject"] if subjects is not None else []))
        for k, a in enumerate(labels):
            w.writerow([f"c{k:02d}", a] + ([subjects[k]] if subjects is not None else []))
    return folder


@pytest.fixture(scope="module")
def uestc_clips(humanact12):
    """12 real walk / run clips converted to the 18-joint UESTC layout, 40 frames each."""
    picks = [i for a in (1, 2) for i in np.flatnonzero(humanact12.actions == a)[:6]]
    clips = [humanact12.motions[i].to("uestc").joints[:40].copy() for i in picks]
    return clips, ["walk"] * 6 + ["run"] * 6


@pytest.mark.real_data
def test_folder_loads_with_names_skeleton_and_subjects(tmp_path, uestc_clips):
    clips, labels = uestc_clips
    data = load_joints_dataset(_write_folder(tmp_path / "d", clips, labels, subjects=[3] * 6 + [4] * 6))
    assert data.name == "joints" and len(data) == 12
    assert data.action_names == ("run", "walk")  # sorted names
    assert data.actions.tolist() == [1] * 6 + [0] * 6
    assert data.subjects.tolist() == [3] * 6 + [4] * 6
    assert {m.skeleton for m in data} == {"uestc"}  # 18 joints name one skeleton
    np.testing.assert_array_equal(data[4].joints, clips[4])


def test_npz_object_and_padded_forms_agree(tmp_path, rng):
    clips = [rng.normal(size=(n, 20, 3)).astype(np.float32) for n in (30, 25, 41)]
    ragged = np.empty(3, dtype=object)
    ragged[:] = clips
    np.savez(tmp_path / "a.npz", clips=ragged, actions=[0, 1, 1], action_names=["walk", "run"], skeleton="cmu_mocap")
    padded = np.zeros((3, 41, 20, 3), dtype=np.float32)
    for k, c in enumerate(clips):
        padded[k, : len(c)] = c
    np.savez(tmp_path / "b.npz", clips=padded, lengths=[30, 25, 41], actions=[0, 1, 1], subjects=[1, 2, 3],
             action_names=["walk", "run"])
    a, b = load_joints_dataset(tmp_path / "a.npz"), load_joints_dataset(tmp_path / "b.npz")
    assert a.action_names == b.action_names == ("walk", "run")
    assert [m.n_frames for m in a] == [m.n_frames for m in b] == [30, 25, 41]
    assert all(m.skeleton == "cmu_mocap" for m in a) and b.subjects.tolist() == [1, 2, 3]
    for ma, mb, c in zip(a, b, clips):
        np.testing.assert_array_equal(ma.joints, c)
        np.testing.assert_array_equal(mb.joints, c)


def test_bad_inputs_raise_clear_errors(tmp_path, rng):
    good = [rng.normal(size=(30, 18, 3)) for _ in range(4)]
    with pytest.raises(ValueError, match="has no labels.csv"):
        (tmp_path / "empty").mkdir()
        load_joints_dataset(tmp_path / "empty")
    folder = _write_folder(tmp_path / "mismatch", good, [0, 1, 0, 1])
    (folder / "c03.npy").unlink()
    with pytest.raises(ValueError, match=r"labels.csv has 4 rows for 3 .npy clips.*labels without a clip: \['c03'\]"):
        load_joints_dataset(folder)
    with pytest.raises(ValueError, match=r"clip 'c01' must have shape \(T, J, 3\)"):
        load_joints_dataset(_write_folder(tmp_path / "shape", [good[0], good[1][:, :, :2]], [0, 1]))
    nan = [c.copy() for c in good]
    nan[2][5, 3, 1] = np.nan
    with pytest.raises(ValueError, match="clip 'c02'.*NaN"):
        load_joints_dataset(_write_folder(tmp_path / "nan", nan, [0, 1, 0, 1]))
    with pytest.raises(ValueError, match="unknown skeleton 'ntu25'; known: cmu_mocap"):
        load_joints_dataset(_write_folder(tmp_path / "ok", good, [0, 1, 0, 1]), skeleton="ntu25")
    with pytest.raises(ValueError, match="skeleton 'humanact12' has 24 joints but the clips have 18"):
        load_joints_dataset(tmp_path / "ok", skeleton="humanact12")
    np.savez(tmp_path / "few.npz", clips=np.stack(good), actions=[0, 1, 0])
    with pytest.raises(ValueError, match=r"one action per clip \(4 clips\); got 3"):
        load_joints_dataset(tmp_path / "few.npz")
    np.savez(tmp_path / "idx.npz", clips=np.stack(good), actions=[0, 1, 2, 0], action_names=["a", "b"])
    with pytest.raises(ValueError, match=r"action indices must be in 0..1"):
        load_joints_dataset(tmp_path / "idx.npz")
    np.savez(tmp_path / "j7.npz", clips=np.zeros((2, 10, 7, 3)), actions=[0, 1])
    with pytest.raises(ValueError, match="7 joints, which names no single skeleton"):
        load_joints_dataset(tmp_path / "j7.npz")
    np.savez(tmp_path / "nokey.npz", clips=np.stack(good))
    with pytest.raises(ValueError, match="lacks the key 'actions'"):
        load_joints_dataset(tmp_path / "nokey.npz")


def test_object_arrays_load_no_code(tmp_path):
    """A pickled object other than arrays inside `clips` is refused before anything is called."""
    evil = np.empty(1, dtype=object)
    evil[0] = OrderedDict(a=1)  # pickled as a call of collections.OrderedDict
    np.savez(tmp_path / "evil.npz", clips=evil, actions=[0])
    with pytest.raises(ValueError, match="only arrays are loaded"):
        load_joints_dataset(tmp_path / "evil.npz")


@pytest.mark.real_data
def test_train_tiny_on_a_generated_folder(tmp_path, uestc_clips, one_torch_thread):
    """`motion-refiner train --dataset joints` trains the paper's modules on 12 clips; the result
    loads, refines an 18-joint clip and says whose licence applies."""
    from refiner import Refiner
    from refiner.cli.main import main

    clips, labels = uestc_clips
    data = _write_folder(tmp_path / "clips", clips, labels)
    out = tmp_path / "out"
    assert main(["train", "--dataset", "joints", "--data", str(data), "--config", "tiny", "--out", str(out)]) == 0
    refiner = Refiner.load(out)
    assert refiner.skeleton == "uestc" and refiner.manifest["dataset"] == "joints" and refiner.method == "concepts"
    assert "user-supplied" in refiner.manifest["licence"]
    before = clips[3].copy()
    refined = refiner.refine(clips[3])
    assert refined.shape == clips[3].shape and np.isfinite(refined).all()
    np.testing.assert_array_equal(clips[3], before)
    # an untrained tiny model: only that it keeps the clip in place on average (metres)
    assert np.linalg.norm(refined - clips[3], axis=-1).mean() < 0.5


def test_train_has_no_learned_method_options(tmp_path, capsys):
    """The learned method's training (``--whole``, ``--learned``, ``--base``, ``--jobs``) is gone; the concepts method's stays."""
    from refiner.cli.main import main

    for option in (["--whole"], ["--learned"], ["--base", str(tmp_path)], ["--jobs", "2"]):
        with pytest.raises(SystemExit) as exit_:
            main(["train", *option, "--dataset", "joints", "--data", str(tmp_path), "--out", str(tmp_path / "out")])
        assert exit_.value.code == 2 and option[0] in capsys.readouterr().err
