import numpy as np
import pytest

from refiner.concepts.learning import MotionConcepts, learn_concepts


@pytest.mark.real_data
def test_learn_concepts_roundtrip(humanact12, tmp_path):
    pick = [i for a in range(12) for i in np.flatnonzero(humanact12.actions == a)[::40]]
    small = humanact12.subset(pick)
    concepts = learn_concepts(small, n_clusters=3)
    s = concepts.summary()
    assert s["clips"] == len(small)
    assert s["transitions"] == sum(len(a) - 1 for a in concepts.anchors) == len(concepts.transitions)
    t = concepts.transitions
    for i in range(0, len(t), 7):
        frames = t.transition_frames(i)
        assert len(frames) == t.durations[i] + 1
        np.testing.assert_array_equal(frames[0], t.start[i])
        np.testing.assert_array_equal(frames[-1], t.end[i])
        clip = small[int(t.clips[i])].joints
        np.testing.assert_array_equal(frames, clip[t.start_frames[i] : t.start_frames[i] + t.durations[i] + 1])
    concepts.save(tmp_path / "c")
    back = MotionConcepts.load(tmp_path / "c")
    assert back.config == concepts.config
    for a, b in zip(back.anchors, concepts.anchors):
        np.testing.assert_array_equal(a, b)
    for name in ("start", "end", "durations", "coeffs", "actions", "frames", "offsets"):
        np.testing.assert_array_equal(getattr(back.transitions, name), getattr(t, name))
    for a, b in zip(back.anchor_concepts.centers_, concepts.anchor_concepts.centers_):
        np.testing.assert_array_equal(a, b)
