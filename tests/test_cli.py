import json
import math

import numpy as np
import pytest
from conftest import bench_json

from refiner.cli.main import main


@pytest.mark.real_data
def test_concepts_command(tmp_path, capsys):
    from conftest import shared_data_dir

    data = shared_data_dir() / "humanact12" / "humanact12_joints.npz"
    code = main(["concepts", "--dataset", "humanact12", "--data", str(data), "--split", "test",
                 "--out", str(tmp_path / "c"), "--n-clusters", "4"])
    out = capsys.readouterr().out
    assert code == 0
    assert "clips        272" in out and "transitions" in out and "walk=4" in out
    meta = json.loads((tmp_path / "c" / "concepts.json").read_text())
    assert meta["summary"]["clips"] == 272


def test_bad_data_path_is_a_clean_error(tmp_path, capsys):
    code = main(["concepts", "--data", str(tmp_path / "none.npz"), "--out", str(tmp_path / "c")])
    assert code == 2
    assert "no HumanAct12 data" in capsys.readouterr().err


def _finite(*values) -> bool:
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in values)


@pytest.mark.real_data
def test_bench_concepts_quick(tmp_path, humanact12):
    """Every 40th clip: larger penalties give fewer, longer transitions and a worse fit; more clusters fit closer."""
    rec = bench_json("concepts", tmp_path)
    used = humanact12.subset(range(0, len(humanact12), 40))
    assert rec["clips"] == len(used) and rec["frames"] == used.n_frames
    assert rec["segment_seconds"] > 0
    lam = rec["penalties"]
    assert [r["penalty"] for r in lam] == [100.0, 200.0, 300.0, 400.0]
    for key in ("transitions_per_clip", "mean_transition_frames", "mpjpe_cm", "mpjpe_mean_of_actions_cm"):
        assert all(_finite(r[key]) and r[key] > 0 for r in lam), key
    assert all(a["transitions_per_clip"] >= b["transitions_per_clip"] for a, b in zip(lam, lam[1:]))
    assert all(a["mpjpe_cm"] <= b["mpjpe_cm"] for a, b in zip(lam, lam[1:]))
    assert lam[0]["mpjpe_cm"] < 2.0  # the spline reconstruction is within a couple of cm (paper: 0.89)
    assert [r["action"] for r in rec["kmeans"]] == [humanact12.action_names[a] for a in np.unique(used.actions)]
    for row in rec["kmeans"]:
        dist = [v for v in row["distance_cm"].values() if v is not None]
        assert row["anchors"] >= 2 and dist and all(_finite(v) and v >= 0 for v in dist)
        assert dist[-1] < dist[0] or len(dist) == 1
    report = (tmp_path / "REPORT.md").read_text()
    assert f"| 200 | {lam[1]['transitions_per_clip']:.3f} | {lam[1]['mean_transition_frames']:.3f} |" in report


@pytest.mark.real_data
@pytest.mark.slow
def test_bench_refiner_and_speed_quick(tmp_path, humanact12):
    """Every 16th held-out clip: real clips barely move, anchors are found, latency and throughput are measured."""
    rec = bench_json("refiner", tmp_path / "refiner")
    assert rec["clips"] == len(humanact12.split("test").motions[::16])
    assert _finite(rec["real_mpjpe_change_cm"]) and 0.0 <= rec["real_mpjpe_change_cm"] < 0.3
    assert 0 <= rec["real_clips_changed"] <= rec["clips"]
    b = rec["boundary_acceleration"]
    assert b["real_p99"] > 0 and 0 <= b["above_real_p99"] <= b["boundaries"] <= rec["clips"]
    assert (b["max"] is None) if b["boundaries"] == 0 else (b["max"] >= b["median"] >= 0)
    assert 0.5 < rec["anchor_precision"] <= 1.0 and 0.0 < rec["anchor_recall"] <= 1.0
    lat = rec["latency"]
    assert lat["clips"] == 5 and 0 < lat["median_ms"] <= lat["p90_ms"] and lat["threads"] >= 1
    auc = rec["anchor_quality_auc"]
    assert set(auc) == {"anchor_drift", "wrong_anchor"}
    assert all(v["pairs"] > 0 and 0.0 <= v["pose"] <= 1.0 and 0.0 <= v["encoder"] <= 1.0 for v in auc.values())
    assert auc["anchor_drift"]["pose"] > 0.5  # the pose mixture tells a drifted anchor from a real one
    parts = {k: v for k, v in rec["parameters"].items() if k != "total"}
    assert parts and all(v > 0 for v in parts.values()) and rec["parameters"]["total"] == sum(parts.values())
    report = (tmp_path / "refiner" / "REPORT.md").read_text()
    assert f"| (c) anchor recognition precision (±2 frames) | {rec['anchor_precision']:.3f} |" in report

    speed = bench_json("speed", tmp_path / "speed")
    assert speed["clips"] == 8 and speed["batch"] == 8 and speed["parameters"] == rec["parameters"]
    cpu = speed["devices"][0]
    assert cpu["device"] == "cpu" and 0 < cpu["median_ms"] <= cpu["p90_ms"]
    assert cpu["clips_per_s"] > 0 and cpu["peak_mib"] > 0
    assert [r["frames"] for r in speed["lengths"]] == [60, 240, 960, 3840]
    assert all(r["us_per_frame"] == pytest.approx(1000 * r["median_ms"] / r["frames"]) for r in speed["lengths"])
    assert f"| cpu | {cpu['name']} | {cpu['median_ms']:.3f} | {cpu['p90_ms']:.3f} |" in (
        tmp_path / "speed" / "REPORT.md").read_text()


@pytest.mark.real_data
@pytest.mark.slow
def test_bench_generators_quick(tmp_path):
    """3 samples per action from each reference generator, before and after refinement, and real clips; the
    shipped generators' samples are recognised well above chance (1/12)."""
    from refiner.reference import GENERATOR_KINDS

    rec = bench_json("generators", tmp_path)
    assert rec["per_action"] == 3 and rec["n_replications"] == 2 and rec["reference_clips"] > 0
    rows = rec["rows"]
    assert set(rows) == {f"{k}/{label}" for k in GENERATOR_KINDS for label in ("generated", "refined")} | {"real"}
    for key, row in rows.items():
        m = row["metrics"]
        assert row["samples"] == 3 * 12, key
        assert _finite(*m["fid"]) and m["fid"][0] > 0 and m["fid"][1] >= 0, key
        assert 0.0 <= m["accuracy"][0] <= 1.0 and m["diversity"][0] > 0, key
        phys = row["physics"]
        assert phys["acceleration"] > 0 and 0 <= phys["foot_skating"] <= 1 and phys["bone_length_variation"] >= 0, key
        if key.endswith("/refined"):
            assert 0.0 <= row["frames_changed"] <= 1.0 and row["changes_per_clip"] >= 0, key
            assert row["refine_seconds_per_clip"] > 0, key
        else:
            assert "frames_changed" not in row, key
    # real held-out clips are closer to the reference than any generator's samples
    assert all(rows["real"]["metrics"]["fid"][0] < row["metrics"]["fid"][0] for k, row in rows.items() if k != "real")
    assert rows["real"]["metrics"]["accuracy"][0] > 0.9
    assert all(rows[f"{k}/generated"]["metrics"]["accuracy"][0] > 0.3 for k in GENERATOR_KINDS)
    # mocap bones are rigid; the joint generators' stretch
    assert rows["real"]["physics"]["bone_length_variation"] < 1e-3
    assert rows["mdm/generated"]["physics"]["bone_length_variation"] > 10 * rows["real"]["physics"]["bone_length_variation"]
    # the default refiner changes frames only in its reported changes: unchanged clips keep their figures exactly
    for k in GENERATOR_KINDS:
        if rows[f"{k}/refined"]["frames_changed"] == 0:
            assert rows[f"{k}/refined"]["physics"] == rows[f"{k}/generated"]["physics"], k
