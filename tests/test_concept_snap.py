"""Concept snap (the concepts method's option): anchors land on (or the given share of the way to) their action's
nearest concept, the root path and the frames of unsnapped clips stay as given, bones stay rigid, and the option
refuses what it cannot do."""
import numpy as np
import pytest

from refiner.concepts.anchors import AnchorConcepts, root_relative
from refiner.core.skeletons import bone_lengths
from refiner.refinement.concept_snap import check_strength, facing, snap_to_concepts, turned
from refiner.refinement.pipeline import Refiner


@pytest.fixture(scope="module")
def concepts(humanact12):
    idx = np.flatnonzero(humanact12.subjects <= 10)[::4]
    poses = np.concatenate([humanact12[i].joints[::10] for i in idx])
    acts = np.concatenate([np.full(len(humanact12[i].joints[::10]), humanact12.actions[i]) for i in idx])
    return AnchorConcepts(4, n_init=1).fit(poses, acts, n_actions=12)


@pytest.mark.real_data
@pytest.mark.parametrize("strength", [1.0, 0.5])
def test_anchors_move_the_given_share_of_the_way_onto_their_concepts(humanact12, concepts, strength):
    clip = humanact12[int(np.flatnonzero(humanact12.subjects == 11)[3])]
    x = clip.joints[:80].copy()
    snapped, anchors, distance = snap_to_concepts(x, clip.action, concepts, strength=strength)
    np.testing.assert_array_equal(x, clip.joints[:80])  # the input is not modified
    assert len(anchors) >= 2 and anchors[0] == 0 and anchors[-1] == len(x) - 1
    moved = np.linalg.norm(snapped[anchors] - x[anchors], axis=-1).mean(-1)
    np.testing.assert_allclose(moved, strength * distance, rtol=1e-3, atol=1e-4)  # the share of the way there
    if strength == 1.0:  # onto a concept (turned to the clip's mean heading, a rotation: pose shapes unchanged)
        rel = root_relative(snapped[anchors])
        shapes = [np.linalg.norm(c[:, None] - c[None], axis=-1) for c in concepts.centers_[clip.action]]
        for pose in rel:
            own = np.linalg.norm(pose[:, None] - pose[None], axis=-1)
            assert min(np.abs(own - c).max() for c in shapes) < 1e-4
    np.testing.assert_allclose(snapped[:, 0], x[:, 0], atol=1e-6)  # the root keeps its path
    assert (distance > 0.01).all()  # a real clip's anchors are not concept poses: the test measures a move


@pytest.mark.real_data
def test_a_clip_turned_as_a_whole_is_snapped_as_it_would_be_unturned(humanact12, concepts):
    clip = humanact12[int(np.flatnonzero(humanact12.subjects == 11)[7])]
    x = clip.joints[:70].astype(np.float64)
    angle = np.full(len(x), np.pi / 2)
    rotated = turned(x, angle, "humanact12")
    diff = facing(rotated[:1], "humanact12") - facing(x[:1], "humanact12")
    np.testing.assert_allclose(np.angle(np.exp(1j * diff)), [np.pi / 2], atol=1e-9)
    plain, anchors, distance = snap_to_concepts(x, clip.action, concepts)
    turned_back = turned(snap_to_concepts(rotated, clip.action, concepts)[0].astype(np.float64), -angle, "humanact12")
    np.testing.assert_allclose(turned_back, plain, atol=1e-4)


def test_strength_is_checked():
    for bad in (-0.1, 1.5, float("nan"), "strong", None):
        with pytest.raises(ValueError, match="concept_snap"):
            check_strength(bad)
    for bad in (True, "1", np.array([0.5])):
        with pytest.raises(ValueError, match="concept_snap"):
            check_strength(bad)
    assert check_strength(0) == 0.0 and check_strength(np.float32(0.5)) == 0.5


@pytest.mark.real_data
def test_the_option_snaps_clips_of_given_actions_only_and_keeps_bones_rigid(humanact12):
    refiner = Refiner.pretrained("humanact12", split="train", concept_snap=1.0)
    plain = Refiner.pretrained("humanact12", split="train")
    idx = np.flatnonzero(humanact12.subjects == 12)[:3]
    batch = np.stack([humanact12[int(i)].joints[:60] for i in idx])
    given = batch.copy()
    actions = [int(humanact12.actions[idx[0]]), None, int(humanact12.actions[idx[2]])]
    out, reports = refiner.refine(batch, action=actions, return_report=True)
    base = plain.refine(batch, action=actions)
    np.testing.assert_array_equal(batch, given)
    steps = [[c["step"] for c in r.changes] for r in reports]
    assert "concept_snap" in steps[0] and "concept_snap" in steps[2] and "concept_snap" not in steps[1]
    np.testing.assert_array_equal(out[1], base[1])  # an inferred action is never snapped to
    half = Refiner.pretrained("humanact12", split="train", concept_snap=0.5).refine(batch, action=actions)
    share = np.linalg.norm(half[0] - base[0], axis=-1).mean() / np.linalg.norm(out[0] - base[0], axis=-1).mean()
    assert 0.35 < share < 0.65, share  # the strength is used: half-way moves about half as far
    transition = refiner.refine(batch, action=actions, mode="transition")  # an anchor refinement: not in that mode
    np.testing.assert_array_equal(transition, plain.refine(batch, action=actions, mode="transition"))
    for b in (0, 2):
        moved = np.linalg.norm(out[b] - base[b], axis=-1).mean()
        assert 0.01 < moved < 0.3, moved  # centimetres to decimetres: every anchor moves to a concept
        lengths = bone_lengths(out[b], "humanact12")
        assert (lengths.std(0) / lengths.mean(0)).max() < 1e-3  # put back on rigid bones
        rel = root_relative(out[b])
        assert np.isfinite(rel).all()


def test_the_option_is_refused_where_it_cannot_run():
    plain = Refiner.pretrained("humanact12", split="train")
    parts = {k: getattr(plain, k) for k in ("recognizer", "anchor_refiner", "transition_generator", "transition_refiner",
                                            "anchor_quality")}
    with pytest.raises(ValueError, match="anchor_concepts"):  # weights without anchor concepts
        Refiner(**parts, anchor_concepts=None, action_names=plain.action_names, concept_snap=1.0)
    for bad in (2, -0.1, "yes", True):
        with pytest.raises(ValueError, match="concept_snap"):
            Refiner.pretrained("humanact12", split="train", concept_snap=bad)
    assert plain.concept_snap == 0.0 and plain.method == "concepts"  # off by default
