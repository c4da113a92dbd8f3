import pickle

import numpy as np
import pytest

from refiner.io.datasets import HUMANACT12_ACTIONS, load_humanact12, parse_humanact12_name

pytestmark = pytest.mark.real_data


def test_npz_has_all_clips(humanact12):
    assert len(humanact12) == 1191 and humanact12.n_frames == 90099
    assert sorted(humanact12.names) == humanact12.names
    assert set(humanact12.actions.tolist()) == set(range(12))
    assert len(humanact12.action_names) == 12 and humanact12.action_names[1] == "walk"
    m = humanact12[0]
    assert m.skeleton == "humanact12" and m.fps == 20.0


def test_split_by_subject(humanact12):
    train, test = humanact12.split("train"), humanact12.split("test")
    assert (len(train), len(test)) == (919, 272)
    assert set(train.subjects.tolist()) == set(range(1, 11)) and set(test.subjects.tolist()) == {11, 12}
    with pytest.raises(ValueError, match="unknown split"):
        humanact12.split("val")


def test_cmu_split_holds_out_whole_subjects_and_every_action_but_step():
    from conftest import shared_data_dir

    from refiner.io.datasets import CMU_ACTIONS, CMU_TEST_SUBJECTS, load_cmu_mocap

    cmu = load_cmu_mocap(shared_data_dir() / "cmu_mocap" / "cmu_mocap_labeled_joints.npz")
    train, test = cmu.split("train"), cmu.split("test")
    assert (len(train), len(test)) == (815, 273)
    assert set(test.subjects.tolist()) == set(CMU_TEST_SUBJECTS)
    assert not set(train.subjects.tolist()) & set(CMU_TEST_SUBJECTS)
    share = np.bincount(test.actions, minlength=8) / np.bincount(cmu.actions, minlength=8)
    step = CMU_ACTIONS.index("step")
    assert share[step] == 0 and all(0.2 <= share[a] <= 0.3 for a in range(8) if a != step), share


def test_three_sources_give_identical_clips(humanact12, tmp_path):
    """A folder of Action2Motion .npy clips and ACTOR's pkl give the same clips as the packed npz."""
    pick = list(range(0, 1191, 150))
    folder = tmp_path / "humanact12"
    folder.mkdir()
    for i in pick:
        np.save(folder / f"{humanact12.names[i]}.npy", humanact12[i].numpy())
    from_folder = load_humanact12(folder)
    pkl = tmp_path / "humanact12poses.pkl"
    with open(pkl, "wb") as f:
        pickle.dump({"joints3D": [humanact12[i].numpy() for i in pick],
                     "y": [int(humanact12[i].action) for i in pick]}, f)
    from_pkl = load_humanact12(pkl, names=[humanact12.names[i] for i in pick])
    for k, i in enumerate(pick):
        assert from_folder[k] == humanact12[i]
        assert from_pkl[k] == humanact12[i]
    assert from_folder.names == from_pkl.names == [humanact12.names[i] for i in pick]
    assert (from_pkl.subjects == humanact12.subjects[pick]).all()


def test_pkl_refuses_code(tmp_path):
    class Evil:
        def __reduce__(self):
            return (print, ("pwned",))

    path = tmp_path / "evil.pkl"
    path.write_bytes(pickle.dumps({"joints3D": [Evil()], "y": [0]}))
    with pytest.raises(ValueError, match="refusing|not an ACTOR"):
        load_humanact12(path)


def test_loader_errors(tmp_path):
    with pytest.raises(ValueError, match="no HumanAct12 data"):
        load_humanact12(tmp_path / "missing.npz")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no .npy clips"):
        load_humanact12(tmp_path / "empty")
    bad = tmp_path / "bad"
    bad.mkdir()
    np.save(bad / "P01G01R01F0001T0064A0101.npy", np.zeros((5, 22, 3)))
    with pytest.raises(ValueError, match="J=24"):
        load_humanact12(bad)
    with pytest.raises(ValueError, match="not a HumanAct12 clip name"):
        parse_humanact12_name("walk_01")


def test_name_parsing():
    info = parse_humanact12_name("P11G02R03F0010T0070A1203")
    assert info["subject"] == 11 and info["action"] == 11 and info["fine_code"] == "1203"
    assert HUMANACT12_ACTIONS[info["action"]] == "throw"
