"""The evaluation benchmark suites (`flaws`, `sanity`) in their quick configuration."""
from __future__ import annotations

import json
import math

import pytest
from conftest import bench_json

from refiner.cli.main import main
from refiner.evaluation.bench import SUITES


def test_suites_are_registered():
    assert {"flaws", "sanity"} <= set(SUITES)


@pytest.mark.real_data
def test_flaw_records_on_a_few_clips(humanact12):
    """The flaws bench's records on 4 held-out clips and 3 families: identity is the flaw, the oracle fixes a stall."""
    from refiner.evaluation.baselines import IdentityRefiner, SavgolRefiner
    from refiner.evaluation.bench_flaws import ORACLES, flaw_records

    clips = humanact12.split("test").motions[:40:10]
    clean, records = flaw_records(clips, {"identity": IdentityRefiner(), "savgol": SavgolRefiner()},
                                  families=["transition_jitter", "frozen_transition", "foot_sliding"])
    assert clean[0][:3] == ["identity", 0.0, 0.0] and clean[1][1] > 0.0 and clean[1][2] == 1.0
    by = {(r["family"], r["refiner"]): r for r in records}
    assert ORACLES == ("oracle_linear",) and {r["refiner"] for r in records} == {"identity", "savgol", *ORACLES}
    for family in ("transition_jitter", "frozen_transition", "foot_sliding"):
        ident = by[(family, "identity")]
        assert ident["mpjpe_cm"] > 0.2 and ident["removed_pct"] == 0.0
        # the error is where the flaw is: its frames are off by far more than the clip on average
        assert ident["mpjpe_flawed_cm"] > 1.5 * ident["mpjpe_cm"]
    # linear interpolation over the true flaw frames helps a stall but throws away jittered motion
    assert by[("frozen_transition", "oracle_linear")]["removed_pct"] > 5.0
    assert by[("transition_jitter", "oracle_linear")]["removed_pct"] < -100.0
    _, records = flaw_records(clips[:2], {"identity": IdentityRefiner()}, oracles=False, families=["transition_jitter"])
    assert {r["refiner"] for r in records} == {"identity"}


@pytest.mark.real_data
@pytest.mark.slow
def test_bench_flaws_quick(tmp_path):
    """4 held-out clips, every family: no refiner is skipped, identity is the flaw, the default leaves clean clips alone."""
    from refiner.evaluation.baselines import FLAW_REFINERS
    from refiner.evaluation.bench_flaws import ORACLES
    from refiner.evaluation.flaws import FLAW_FAMILIES

    rec = bench_json("flaws", tmp_path)
    assert rec["skipped"] == {}, rec["skipped"]  # a refiner that could not be built fails the test
    assert rec["clips"] == 4 and rec["severities"] == [2] and rec["families"] == list(FLAW_FAMILIES)
    names = [*FLAW_REFINERS, *ORACLES]
    assert "held_out_families" not in rec and set(FLAW_REFINERS) >= {"ours_full", "ours_concepts", "ours_concept_snap"}
    assert list(rec["clean"]) == list(FLAW_REFINERS)
    by = {(r["family"], r["refiner"]): r for r in rec["flawed"]}
    assert len(rec["flawed"]) == len(by) == len(FLAW_FAMILIES) * len(names)
    assert set(by) == {(f, n) for f in FLAW_FAMILIES for n in names}
    for r in rec["flawed"]:
        assert math.isfinite(r["removed_pct"]) and r["mpjpe_cm"] >= 0 and r["mpjpe_flawed_cm"] >= 0, r
    for clean in rec["clean"].values():
        assert math.isfinite(clean["mpjpe_change_cm"]) and clean["mpjpe_change_cm"] >= 0
        assert 0.0 <= clean["share_changed"] <= 1.0
    assert rec["clean"]["identity"] == {"mpjpe_change_cm": 0.0, "share_changed": 0.0}
    assert rec["clean"]["savgol"]["mpjpe_change_cm"] > 0 and rec["clean"]["savgol"]["share_changed"] == 1.0
    snap = rec["clean"]["ours_concept_snap"]  # the option moves every anchor of clean clips too (documented)
    assert snap["share_changed"] == 1.0 and snap["mpjpe_change_cm"] > 1.0
    for family in FLAW_FAMILIES:
        assert by[(family, "identity")]["removed_pct"] == 0.0 and by[(family, "identity")]["mpjpe_cm"] > 0.2
    summary = rec["summary"]["2"]
    assert list(summary) == names
    for name in names:  # the summary is the mean of the per-family figures
        values = [by[(f, name)]["removed_pct"] for f in FLAW_FAMILIES]
        assert summary[name]["mean_removed_pct"] == pytest.approx(sum(values) / len(values))
    assert summary["identity"]["mean_removed_pct"] == 0.0
    # the default refiner (and the concepts method) leave clean clips nearly alone and do better than both filters
    for name in ("ours_full", "ours_concepts"):
        assert rec["clean"][name]["mpjpe_change_cm"] < 0.3, name
        ours = summary[name]["mean_removed_pct"]
        assert ours > max(summary["savgol"]["mean_removed_pct"], summary["gaussian"]["mean_removed_pct"]), name


@pytest.mark.real_data
def test_bench_sanity_quick(tmp_path):
    """Real clips against real clips: FID small and ordered (floor < matched < unmatched), accuracy near 1."""
    rec = bench_json("sanity", tmp_path)
    assert rec["test_clips"] + rec["train_clips"] == 1191 and rec["test_clips"] > 0
    assert rec["n_replications"] == 3 and rec["n_crops"] == 300
    comps = rec["comparisons"]
    assert list(comps) == ["test vs train", "test vs train, matched", "train vs train, matched (floor)"]
    fid = {k: c["metrics"]["fid"] for k, c in comps.items()}
    for k, c in comps.items():
        m = c["metrics"]
        assert all(math.isfinite(v) for v in m["fid"]) and m["fid"][0] > 0 and m["fid"][1] >= 0, k
        assert 0.99 <= m["accuracy"][0] <= 1.0 and m["diversity"][0] > 0 and c["seconds"] > 0, k
    assert fid["train vs train, matched (floor)"][0] < fid["test vs train, matched"][0] < fid["test vs train"][0] < 2.0
    report = (tmp_path / "REPORT.md").read_text()
    assert f"| test vs train | {fid['test vs train'][0]:.3f} ± {fid['test vs train'][1]:.3f} |" in report


@pytest.mark.real_data
def test_bench_samples_quick(tmp_path):
    """Real Action2Motion samples: the structured record says what changed, and frames change only where reported."""
    from conftest import shared_data_dir

    assert main(["bench", "samples", "--quick", "--data", str(shared_data_dir()), "--out", str(tmp_path)]) == 0
    rec = json.loads((tmp_path / "samples.json").read_text())
    assert rec["generated"]["bone_length_variation"] > 0.02  # the xyz VAE's bones stretch by several %
    assert 0.0 <= rec["refined"]["accuracy"] <= 1.0 and 0.0 <= rec["frames_changed"] <= 1.0
    assert len(rec["reports"]) == 5 and [r["label"] for r in rec["reports"]] == [int(r["label"]) for r in rec["reports"]]
    assert all(c["step"] in {"ground", "glide", "retime"} and c["parts"] for r in rec["reports"] for c in r["changes"])
    assert rec["frames_changed"] <= rec["repaired_frames"] + 1e-9  # the default changes only the frames it reports
    snapped = rec["snapped"]  # the concepts method's concept snap moves every clip (all have their labels)
    assert snapped["frames_changed"] > 0.9
    assert 0.0 <= snapped["accuracy"] <= 1.0
    ntu = rec["ntu13"]  # the 18-joint samples, refined through HumanAct12's motion model with the action unknown
    assert ntu["clips"] == 5 and 0.0 <= ntu["refined"]["accuracy"] <= 1.0
    assert ntu["frames_changed"] <= ntu["repaired_frames"] + 1e-9


@pytest.mark.real_data
def test_bench_skeletons_quick(tmp_path):
    """One row per skeleton the default serves: clean clips untouched, natively and through conversion."""
    from conftest import bench_json

    rec = bench_json("skeletons", tmp_path)
    rows = rec["skeletons"]
    assert list(rows) == ["humanact12", "uestc"] and rec["clips"] == 4 and rec["skipped"] == {}
    assert rows["humanact12"]["weights"] == "humanact12" and rows["uestc"]["weights"] == "humanact12, converted"
    for row in rows.values():
        assert row["clips"] == 4 and row["clean_mpjpe_change_cm"] < 0.3 and 0.0 <= row["clean_clips_changed"] <= 1.0
        assert set(row["removed_pct"]) == {"frozen_transition", "foot_sliding"}
        assert row["mean_removed_pct"] == pytest.approx(sum(row["removed_pct"].values()) / 2)
        assert all(-5.0 < v <= 100.0 for v in row["removed_pct"].values())  # the default does no real harm


def test_removed_by_recipe_measures_the_share_removed():
    """Outside-the-benchmark recipes: a refiner that returns the flaw removes 0 %, one that halves it 50 %."""
    from types import SimpleNamespace

    import numpy as np

    from refiner.evaluation.recipes import removed_by_recipe

    clean = [SimpleNamespace(joints=np.zeros((10, 24, 3), np.float32), action=3) for _ in range(3)]
    seen = []

    class Halving:
        def refine(self, flawed, action=None, return_report=False):
            seen.append(action)
            return flawed * 0.5, SimpleNamespace(changes=[{"repair": "x"}])

    records = removed_by_recipe(Halving(), clean, {"shift": lambda x, rng: x + rng.uniform(0.01, 0.02)}, seed=5,
                                counted=lambda report: bool(report.changes))
    r = records["shift"]
    assert math.isclose(r["removed_pct"], 50.0, rel_tol=1e-5) and r["counted"] == 3 and 1.0 < r["before_cm"] < 3.5
    assert seen == [3, 3, 3]
    removed_by_recipe(Halving(), clean, {"same": lambda x, rng: x + 0.01}, seed=0, with_action=False)
    assert seen[-3:] == [None] * 3
