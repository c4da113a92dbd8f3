import numpy as np
import pytest

from refiner import Skeleton, get_skeleton, list_skeletons, register_skeleton
from refiner.core.skeletons import bone_lengths


@pytest.mark.parametrize("name, n_joints, up", [("humanact12", 24, "-y"), ("uestc", 18, "-y"),
                                                ("humanml3d", 22, "+y"), ("cmu_mocap", 20, "+y")])
def test_builtin_skeletons(name, n_joints, up):
    s = get_skeleton(name)
    assert s.n_joints == n_joints and s.up == up and s.root == 0
    assert len(s.bones) == n_joints - 1


def test_parents_match_generator_formats_tables():
    assert get_skeleton("humanact12").parents == (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)
    assert get_skeleton("uestc").parents == (-1, 0, 1, 2, 3, 1, 5, 6, 1, 0, 9, 10, 0, 12, 13, 14, 11, 8)
    assert get_skeleton("humanml3d").parents == get_skeleton("humanact12").parents[:22]


@pytest.mark.real_data
def test_real_bone_lengths_are_constant(humanact12):
    """The humanact12 parents describe rigid bones of the real data (a wrong parent would not be)."""
    for m in humanact12.motions[::40]:
        lengths = bone_lengths(m.joints, "humanact12")
        assert (lengths.std(0) / lengths.mean(0)).max() < 1e-3


@pytest.mark.real_data
def test_cmu_parents_are_rigid():
    from conftest import shared_data_dir

    from refiner.io.datasets import load_cmu_mocap

    cmu = load_cmu_mocap(shared_data_dir() / "cmu_mocap" / "cmu_mocap_labeled_joints.npz")
    assert len(cmu) == 1088 and cmu.n_frames == 204079
    rel_std = np.max([b.std(0) / b.mean(0) for b in (bone_lengths(m.joints, "cmu_mocap") for m in cmu.motions[::20])], 0)
    assert np.median(rel_std) < 1e-3  # most bones rigid; hand and toe tips wobble up to ~15 % in the data
    assert rel_std.max() < 0.2
    # y is up: the head is above the ankles in metres, a plausible 1.3-2.0 m apart
    first = cmu[0].joints[0]
    assert 1.0 < first[3, 1] - first[14, 1] < 2.0


def test_register_and_errors():
    s = Skeleton("toy3", ("root", "a", "b"), (-1, 0, 1), up="+y", forward="+z")
    register_skeleton(s)
    assert "toy3" in list_skeletons() and get_skeleton("toy3") is s
    with pytest.raises(ValueError, match="already registered"):
        register_skeleton(s)
    register_skeleton(s, overwrite=True)
    with pytest.raises(ValueError, match="unknown skeleton 'nope'"):
        get_skeleton("nope")
    with pytest.raises(ValueError, match="exactly one root"):
        Skeleton("bad", ("a", "b"), (-1, -1))
    with pytest.raises(ValueError, match="earlier joint"):
        Skeleton("bad", ("a", "b"), (-1, 5))
    with pytest.raises(ValueError, match="has no joint"):
        get_skeleton("humanact12").index("tail")
