"""Rigid motion: round trips, subtrees, and blends of directions."""
import numpy as np

from refiner.core.bone_directions import blend_directions, from_bone_directions, subtree_bones, to_bone_directions
from refiner.core.skeletons import bone_lengths, get_skeleton


def test_round_trip_is_exact(rng):
    x = rng.normal(size=(2, 7, 24, 3))
    root, dirs, lengths = to_bone_directions(x, "humanact12")
    assert root.shape == (2, 7, 3) and dirs.shape == (2, 7, 23, 3) and lengths.shape == (2, 7, 23)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(from_bone_directions(root, dirs, lengths, "humanact12"), x, atol=1e-12)


def test_any_directions_keep_the_given_lengths(rng):
    lengths = rng.uniform(0.05, 0.5, size=19)
    out = from_bone_directions(np.zeros((5, 3)), rng.normal(size=(5, 19, 3)), lengths, "cmu_mocap")
    np.testing.assert_allclose(bone_lengths(out, "cmu_mocap"), np.broadcast_to(lengths, (5, 19)), atol=1e-12)


def test_subtree_of_the_left_shoulder_is_the_arm():
    skel = get_skeleton("humanact12")
    bones = skel.bones[subtree_bones(skel, skel.index("left_shoulder"))]
    names = {skel.joint_names[c] for c in bones[:, 1]}
    assert names == {"left_elbow", "left_wrist", "left_hand"}
    assert len(subtree_bones(skel, skel.index("pelvis"))) == 23


def test_blend_of_directions_is_unit_and_ends_at_its_inputs():
    a, b = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    w = np.linspace(0, 1, 5)
    d = blend_directions(np.broadcast_to(a, (5, 3)), np.broadcast_to(b, (5, 3)), w)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0)
    np.testing.assert_allclose(d[0], a)
    np.testing.assert_allclose(d[-1], b)
