"""Concept snap: anchors land on (or the given share of the way to) their action's nearest concept, the root path
and the frames of unsnapped clips stay as given, bones stay rigid, and the option refuses what it cannot do."""
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
    cmu = Refiner.pretrained("cmu_mocap", split="train")
    with pytest.raises(ValueError, match="concept_snap"):  # weights without anchor concepts
        Refiner(None, None, None, None, None, None, cmu.flaw_recognizer, cmu.flaw_repairer, cmu.flaw_classifier,
                skeleton="cmu_mocap", action_names=cmu.action_names, concept_snap=1.0)
    with pytest.raises(ValueError, match="concept_snap"):
        Refiner.pretrained("humanact12", split="train", method="concepts", concept_snap=0.5)
    with pytest.raises(ValueError, match="concept_snap"):
        Refiner.pretrained("humanact12", split="train", concept_snap=2)


@pytest.mark.real_data
def test_a_converted_skeleton_snaps_with_a_humanact12_action_name(humanact12):
    from refiner.core.skeletons import convert

    clip = humanact12[int(np.flatnonzero(humanact12.subjects == 12)[5])]
    x = convert(clip.joints[:60], "humanact12", "uestc")
    refiner = Refiner.pretrained("uestc", concept_snap=1.0)
    assert refiner.concept_snap == 1.0 and Refiner.pretrained("uestc").concept_snap == 0.0
    _, named = refiner.refine(x, action=humanact12.action_names[clip.action], return_report=True)
    _, indexed = refiner.refine(x, action=int(clip.action), return_report=True)  # an index: UESTC's own label
    assert "concept_snap" in [c["step"] for c in named.changes]
    assert np.linalg.norm(refiner.refine(x, action=humanact12.action_names[clip.action]) - x, axis=-1).mean() > 0.01
    assert "concept_snap" not in [c["step"] for c in indexed.changes]


@pytest.mark.real_data
def test_the_cmu_weights_snap_onto_their_own_concepts():
    """The CMU weights ship their repair network's anchor concepts (K-means on CMU clips), so the option
    serves the permissively licensed skeleton too; the concepts are the network's, value for value."""
    from conftest import shared_data_dir

    from refiner.io.datasets import load_cmu_mocap

    refiner = Refiner.pretrained("cmu_mocap", split="train", concept_snap=1.0)
    tokens = refiner.flaw_repairer.concepts_
    for a, centres in enumerate(refiner.anchor_concepts.centers_):
        np.testing.assert_allclose(centres, tokens[a, : len(centres)], atol=1e-3)  # float16 tokens
    clip = load_cmu_mocap(shared_data_dir() / "cmu_mocap" / "cmu_mocap_labeled_joints.npz").split("test").motions[3]
    x = clip.joints[:100].copy()
    out, report = refiner.refine(x, action=int(clip.action), return_report=True)
    base = Refiner.pretrained("cmu_mocap", split="train").refine(x, action=int(clip.action))
    np.testing.assert_array_equal(x, clip.joints[:100])
    assert "concept_snap" in [c["step"] for c in report.changes]
    assert 0.01 < np.linalg.norm(out - base, axis=-1).mean() < 0.3
    lengths = bone_lengths(out, "cmu_mocap")
    assert (lengths.std(0) / lengths.mean(0)).max() < 1e-3


@pytest.fixture(scope="module")
def a2m_samples():
    """The 20 real Action2Motion xyz-VAE samples (HumanAct12 joints) and their labels."""
    from conftest import shared_dir

    from refiner.plugins.manager import convert

    folder = shared_dir() / "samples" / "action2motion"
    if not (folder / "humanact12_xyz_vae_samples.npy").is_file():
        pytest.fail(f"Action2Motion samples not found in {folder}; set MOTION_REFINER_DATA.")
    labels = np.load(folder / "humanact12_xyz_vae_labels.npy").astype(np.int64).ravel()
    motions = convert("action2motion", np.load(folder / "humanact12_xyz_vae_samples.npy"), representation="xyz",
                      recenter=True)
    return np.stack([m.joints for m in motions]), labels


@pytest.mark.real_data
def test_misread_snap_moves_only_the_clips_that_read_as_another_action(a2m_samples):
    """Generator output refined as RefinedGenerator refines it: the clips the recognition network reads as another
    action than their label are snapped onto their action's concepts (the report says which action it read), the
    others come back exactly as without the option, and the HumanAct12 recogniser reads the result as its label
    far more often (77 % generated; 78.75 % without the snap, 90.25 % with it, 20 hidden states)."""
    from conftest import shared_dir

    from refiner.evaluation.evaluators import load_recognizer
    from refiner.refinement.inputs import GENERATOR_OPTIONS

    joints, labels = a2m_samples
    given = joints.copy()
    assert GENERATOR_OPTIONS["misread_snap"] == 1.0
    options = {k: v for k, v in GENERATOR_OPTIONS.items() if k != "misread_snap"}
    out, reports = Refiner.pretrained("humanact12", split="train", **GENERATOR_OPTIONS).refine(
        joints, action=list(labels), return_report=True)
    plain = Refiner.pretrained("humanact12", split="train", **options).refine(joints, action=list(labels))
    np.testing.assert_array_equal(joints, given)
    misread = np.array([r.recognized_action != r.action for r in reports])
    assert 3 <= misread.sum() <= 10, misread.sum()  # a third of the samples show another action
    for b, report in enumerate(reports):
        snaps = [c for c in report.changes if c["step"] == "concept_snap"]
        assert 0.0 <= report.action_probability <= 1.0
        if misread[b]:
            assert len(snaps) == 1 and "reads as another action" in snaps[0]["reason"], report.changes
            assert np.linalg.norm(out[b] - plain[b], axis=-1).mean() > 0.01
        else:
            assert not snaps
            np.testing.assert_array_equal(out[b], plain[b])
    recognizer = load_recognizer("humanact12", hidden="random", directory=shared_dir() / "evaluators")

    def accuracy(x):
        return np.mean([recognizer.predict(x, crop="start", random_state=s) == labels for s in range(5)])

    assert accuracy(out) >= 0.85 and accuracy(out) > accuracy(plain) + 0.05, (accuracy(out), accuracy(plain))
    transition = Refiner.pretrained("humanact12", split="train", **GENERATOR_OPTIONS).refine(
        joints[:4], action=list(labels[:4]), mode="transition")  # an anchor refinement: not in that mode
    np.testing.assert_array_equal(transition, Refiner.pretrained("humanact12", split="train", **options).refine(
        joints[:4], action=list(labels[:4]), mode="transition"))


def test_misread_snap_is_refused_where_it_cannot_run_and_on_by_default_for_generators():
    from refiner.refinement.refined_generator import _default_refiner

    with pytest.raises(ValueError, match="misread_snap"):
        Refiner.pretrained("humanact12", split="train", misread_snap=1.5)
    with pytest.raises(ValueError, match="misread_snap"):
        Refiner.pretrained("humanact12", split="train", misread_snap="yes")
    with pytest.raises(ValueError, match="misread_snap needs method='learned'"):
        Refiner.pretrained("humanact12", split="train", method="concepts", misread_snap=1.0)
    default = _default_refiner("humanact12")
    assert default.misread_snap == 1.0 and default.texture == "all"
    assert Refiner.pretrained("humanact12").misread_snap == 0.0  # refine() may be given mocap: off
