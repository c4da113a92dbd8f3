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
    """The flaws bench's records on 4 held-out clips and 3 families: identity is the flaw, oracles fix it."""
    from refiner.evaluation.baselines import IdentityRefiner, SavgolRefiner
    from refiner.evaluation.bench_flaws import ORACLES, flaw_records
    from refiner.refinement.pipeline import Refiner

    clips = humanact12.split("test").motions[:40:10]
    model = Refiner.pretrained("humanact12", split="train")
    clean, records = flaw_records(clips, {"identity": IdentityRefiner(), "savgol": SavgolRefiner()},
                                  model=model, families=["transition_jitter", "frozen_transition", "foot_sliding"])
    assert clean[0][:3] == ["identity", 0.0, 0.0] and clean[1][1] > 0.0 and clean[1][2] == 1.0
    by = {(r["family"], r["refiner"]): r for r in records}
    # the shipped weights have no denoiser and no motion in-filler: no rows for them
    assert model.flaw_denoiser is None and model.motion_infiller is None
    assert {r["refiner"] for r in records} == {"identity", "savgol", *ORACLES} - {"oracle_denoise", "oracle_motion_infill"}
    for family in ("transition_jitter", "frozen_transition", "foot_sliding"):
        ident = by[(family, "identity")]
        assert ident["mpjpe_cm"] > 0.2 and ident["removed_pct"] == 0.0
        # the error is where the flaw is: its frames are off by far more than the clip on average
        assert ident["mpjpe_flawed_cm"] > 1.5 * ident["mpjpe_cm"]
    # linear interpolation over the true flaw frames helps a stall but throws away jittered motion
    assert by[("frozen_transition", "oracle_linear")]["removed_pct"] > 5.0
    assert by[("transition_jitter", "oracle_linear")]["removed_pct"] < -100.0
    # the repair network, shown the true frames of a glide, takes most of it back
    assert by[("foot_sliding", "oracle_given")]["removed_pct"] > 20.0
    # with a denoiser and an in-filler (options, trained here in seconds) their oracle rows join
    from refiner.nn.training import TrainSchedule
    from refiner.refinement.flaw_denoiser import FlawDenoiser
    from refiner.refinement.infilling import MotionInfiller

    tiny = TrainSchedule(n_epochs=1, steps_per_epoch=2, batch_size=8, device="cpu")
    model.flaw_denoiser = FlawDenoiser(hidden=8, n_layers=1, schedule=tiny).fit([m.joints for m in clips])
    model.motion_infiller = MotionInfiller(hidden=8, n_layers=1, schedule=tiny).fit([m.joints for m in clips])
    _, records = flaw_records(clips[:2], {"identity": IdentityRefiner()}, model=model, families=["transition_jitter"])
    assert {r["refiner"] for r in records} == {"identity", *ORACLES}


@pytest.mark.real_data
@pytest.mark.slow
def test_bench_flaws_quick(tmp_path):
    """4 held-out clips, every family: no refiner is skipped, identity is the flaw, ours removes some of it."""
    from refiner.evaluation.baselines import FLAW_REFINERS
    from refiner.evaluation.bench_flaws import ORACLES
    from refiner.evaluation.flaws import FLAW_FAMILIES

    rec = bench_json("flaws", tmp_path)
    assert rec["skipped"] == {}, rec["skipped"]  # a refiner that could not be built fails the test
    assert rec["clips"] == 4 and rec["severities"] == [2] and rec["families"] == list(FLAW_FAMILIES)
    names = [*FLAW_REFINERS, *(o for o in ORACLES if o not in ("oracle_denoise", "oracle_motion_infill"))]  # not shipped
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
    # the learned refiner leaves clean clips nearly alone and removes more of the flaws than both filters
    assert rec["clean"]["ours_full"]["mpjpe_change_cm"] < 0.3
    ours = summary["ours_full"]["mean_removed_pct"]
    assert ours > 0 and ours > max(summary["savgol"]["mean_removed_pct"], summary["gaussian"]["mean_removed_pct"])


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
    """Real Action2Motion samples: the structured record says the bones come back rigid and what changed."""
    from conftest import shared_data_dir

    assert main(["bench", "samples", "--quick", "--data", str(shared_data_dir()), "--out", str(tmp_path)]) == 0
    rec = json.loads((tmp_path / "samples.json").read_text())
    assert rec["generated"]["bone_length_variation"] > 0.02  # the xyz VAE's bones stretch by several %
    assert rec["refined"]["bone_length_variation"] < 0.01
    assert 0.0 <= rec["refined"]["accuracy"] <= 1.0 and rec["frames_changed"] == 1.0
    assert len(rec["reports"]) == 5 and all(r["changes"][0]["step"] == "skeleton" for r in rec["reports"])
    assert all("median bone lengths" in r["changes"][0]["reason"] for r in rec["reports"])
    assert all([c["step"] for c in r["changes"]].count("texture") == 1 for r in rec["reports"])  # generated: every clip
    assert 0.0 <= rec["repaired_frames"] < 1.0  # the whole-clip steps (skeleton, texture) are not repairs
    snapped = rec["snapped"]  # the concept-snap option moves every clip (all have their labels) and keeps bones rigid
    assert snapped["frames_changed"] > 0.9 and snapped["bone_length_variation"] < 0.01
    assert 0.0 <= snapped["accuracy"] <= 1.0
    ntu = rec["ntu13"]  # the 18-joint samples, refined through the HumanAct12 weights with the action unknown
    assert ntu["clips"] == 5 and 0.0 <= ntu["refined"]["accuracy"] <= 1.0
    assert ntu["refined"]["bone_length_variation"] < 0.5 * ntu["generated"]["bone_length_variation"]
    assert all("uestc bone lengths" in r["changes"][0]["reason"] for r in ntu["reports"])


@pytest.mark.real_data
def test_bench_skeletons_quick(tmp_path):
    """One row per skeleton: clean clips untouched, seeded flaws partly removed, natively and through conversion."""
    from conftest import bench_json

    rec = bench_json("skeletons", tmp_path)
    rows = rec["skeletons"]
    assert list(rows) == ["humanact12", "uestc"] and rec["clips"] == 4
    for row in rows.values():
        assert row["clips"] == 4 and row["clean_mpjpe_change_cm"] < 0.3 and 0.0 <= row["clean_clips_changed"] <= 1.0
        assert set(row["removed_pct"]) == {"frozen_transition", "foot_sliding"}
        assert row["mean_removed_pct"] == pytest.approx(sum(row["removed_pct"].values()) / 2)
        assert row["removed_pct"]["foot_sliding"] > 20.0  # the planted feet come back to the ground


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
