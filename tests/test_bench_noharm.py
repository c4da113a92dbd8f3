"""The no-harm suite (`motion-refiner bench noharm`): generated clips before and after refinement."""
from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import shared_data_dir, shared_dir

from refiner.evaluation.bench import SUITES
from refiner.evaluation.bench_noharm import A2M_SETS, bench_noharm, movement, refine_by_length, verdict

FIGURES = ("jerk", "foot_skating", "penetration_cm", "floating_cm", "bone_length_variation_pct", "accuracy_pct")
_DATA = shared_data_dir() / "humanact12" / "humanact12_joints.npz"
_SAMPLES = shared_dir() / "samples" / "action2motion"
needs_data = pytest.mark.skipif(not (_DATA.is_file() and _SAMPLES.is_dir()),
                                reason=f"real data missing ({_DATA} or {_SAMPLES})")


def test_noharm_is_registered():
    assert SUITES["noharm"] is bench_noharm


def test_verdict_rules():
    before = {"jerk": 100.0, "foot_skating": 0.1, "penetration_cm": 0.0, "floating_cm": 2.0,
              "bone_length_variation_pct": 0.5, "accuracy_pct": 80.0}
    assert verdict(before, dict(before))["violated"] == []
    assert verdict(before, {**before, "jerk": 104.0})["violated"] == []
    assert verdict(before, {**before, "jerk": 106.0})["violated"] == ["jerk"]
    assert verdict(before, {**before, "foot_skating": 0.11, "floating_cm": 2.1})["violated"] == ["foot_skating",
                                                                                                 "floating_cm"]
    assert verdict(before, {**before, "bone_length_variation_pct": 0.9})["violated"] == []  # up, but under 1 %
    assert verdict(before, {**before, "bone_length_variation_pct": 1.0})["violated"] == ["bone_length_variation_pct"]
    assert verdict({**before, "bone_length_variation_pct": 5.0}, before)["violated"] == []  # down is better
    assert verdict(before, {**before, "accuracy_pct": 79.5})["violated"] == []
    assert verdict(before, {**before, "accuracy_pct": 78.0})["violated"] == ["accuracy_pct"]
    no_acc = {k: v for k, v in before.items() if k != "accuracy_pct"}
    assert "accuracy_pct" not in verdict(no_acc, before)


def test_movement_and_batching_by_length(rng):
    clips = [rng.normal(size=(n, 24, 3)).astype(np.float32) for n in (30, 40, 30)]
    calls = []

    def shift_second_half(x, skeleton, actions):
        calls.append((x.shape, skeleton, list(actions)))
        y = x.copy()
        y[:, x.shape[1] // 2:] += 0.01
        return y

    after = refine_by_length(shift_second_half, clips, "humanact12", [0, 1, 2])
    assert calls == [((2, 30, 24, 3), "humanact12", [0, 2]), ((1, 40, 24, 3), "humanact12", [1])]
    assert all(a.shape == c.shape for a, c in zip(after, clips))
    m = movement(clips, after)
    assert m["frames_changed"] == pytest.approx(0.5) and m["clips_changed"] == 1.0
    assert m["cm_moved_changed_frames"] == pytest.approx(np.sqrt(3), rel=1e-3)  # 1 cm on each axis
    assert m["cm_moved"] == pytest.approx(np.sqrt(3) / 2, rel=1e-3)
    assert movement(clips, clips) == {"cm_moved": 0.0, "cm_moved_changed_frames": 0.0, "frames_changed": 0.0,
                                      "clips_changed": 0.0}


@pytest.mark.real_data
@needs_data
def test_bench_noharm_identity(tmp_path):
    """Refinement that changes nothing: after == before everywhere, nothing violated, nothing moved."""
    def identity(clips, skeleton, actions):
        return clips

    rec = bench_noharm(shared_data_dir(), tmp_path, True, refine=identity)
    assert json.loads((tmp_path / "noharm.json").read_text()) == json.loads(json.dumps(rec))
    assert rec["skipped"] == {} and rec["refiner"] == "custom: identity"
    assert list(rec["sets"])[:4] == list(A2M_SETS) and len(rec["sets"]) == 4 + 5
    for name, s in rec["sets"].items():
        before, after = s["before"], s["after"]
        for key in FIGURES:
            assert after[key] == before[key], (name, key)
        assert s["verdict"]["violated"] == [], name
        assert after["cm_moved"] == after["frames_changed"] == after["clips_changed"] == 0.0
        assert 0.0 <= before["accuracy_pct"] <= 100.0 and before["jerk"] > 0
    assert rec["sets"]["a2m_cmu"]["skeleton"] == "cmu_mocap" and rec["sets"]["a2m_ntu13"]["refine_actions"] == "unknown"
    assert "may not match" in rec["sets"]["a2m_humanact12_lie"]["note"]
    assert rec["sets"]["gen_actor"]["clips"] == 12
    real = rec["real"]
    assert real["humanact12"]["accuracy_pct"] > 95 and real["cmu_mocap"]["accuracy_pct"] > 80
    assert "none" in real["uestc"]
    # the CMU samples are in metres now: about the real clips' body size, not 1 / 1.13 of it
    assert 0.5 < rec["sets"]["a2m_cmu"]["before"]["jerk"] / real["cmu_mocap"]["jerk"] < 3


@pytest.mark.real_data
@needs_data
def test_bench_noharm_noise_violates_jerk():
    """Refinement that adds 1 cm of noise per joint and frame: jerk is worse in every set."""
    def noisy(clips, skeleton, actions):
        return clips + np.random.default_rng(0).normal(scale=0.01, size=clips.shape).astype(np.float32)

    rec = bench_noharm(shared_data_dir(), None, True, refine=noisy, sets=["a2m_humanact12_xyz", "a2m_cmu", "gen_actor"])
    assert list(rec["sets"]) == ["a2m_humanact12_xyz", "a2m_cmu", "gen_actor"]
    assert set(rec["real"]) == {"humanact12", "cmu_mocap"}
    for name, s in rec["sets"].items():
        assert s["verdict"]["jerk"] and "jerk" in s["verdict"]["violated"], name
        assert s["after"]["frames_changed"] == 1.0 and s["after"]["clips_changed"] == 1.0
        assert 1.0 < s["after"]["cm_moved"] < 2.5  # E|N(0, 1 cm)^3| = 1.6 cm


@pytest.mark.real_data
@needs_data
def test_bench_noharm_cli_default_refiner(tmp_path):
    """The command line with the shipped refiner: a record, a verdict per set and the section in REPORT.md."""
    from refiner.cli.main import main

    assert main(["bench", "noharm", "--quick", "--data", str(shared_data_dir()), "--out", str(tmp_path)]) == 0
    rec = json.loads((tmp_path / "noharm.json").read_text())
    assert rec["refiner"].startswith("default") and rec["sets"]
    for s in rec["sets"].values():
        assert isinstance(s["verdict"]["violated"], list) and s["after"]["seconds"] >= 0
    assert "## No harm" in (tmp_path / "REPORT.md").read_text()
