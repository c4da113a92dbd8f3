"""The evaluation benchmark suites (`flaws`, `sanity`) in their quick configuration."""
from __future__ import annotations

import json
import re

import pytest

from refiner.bench import SUITES
from refiner.cli import main


def _row(text: str, first: str) -> list[str]:
    """Cells of the first Markdown table row whose first cell is ``first``."""
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells and cells[0] == first:
            return cells
    raise AssertionError(f"no row {first!r} in:\n{text}")


def test_suites_are_registered():
    assert {"flaws", "sanity"} <= set(SUITES)


@pytest.mark.real_data
def test_flaw_records_on_a_few_clips(humanact12):
    """The flaws bench's records on 4 held-out clips and 3 families: identity is the flaw, oracles fix it."""
    from refiner.baselines import IdentityRefiner, SavgolRefiner
    from refiner.bench_flaws import ORACLES, flaw_records
    from refiner.pipeline import Refiner

    clips = humanact12.split("test").motions[:40:10]
    model = Refiner.pretrained("humanact12", split="train")
    clean, records = flaw_records(clips, {"identity": IdentityRefiner(), "savgol": SavgolRefiner()},
                                  model=model, families=["transition_jitter", "frozen_transition", "foot_sliding"])
    assert clean[0][:3] == ["identity", 0.0, 0.0] and clean[1][1] > 0.0 and clean[1][2] == 1.0
    by = {(r["family"], r["refiner"]): r for r in records}
    assert {r["refiner"] for r in records} == {"identity", "savgol", *ORACLES}
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


@pytest.mark.real_data
def test_bench_sanity_quick(capsys):
    from conftest import shared_data_dir

    assert main(["bench", "sanity", "--quick", "--data", str(shared_data_dir())]) == 0
    out = capsys.readouterr().out
    rows = {name: _row(out, name) for name in ("test vs train", "test vs train, matched",
                                               "train vs train, matched (floor)")}
    fid = {k: float(re.match(r"[-\d.]+", v[1]).group()) for k, v in rows.items()}
    acc = {k: float(re.match(r"[-\d.]+", v[2]).group()) for k, v in rows.items()}
    assert all(a >= 99.0 for a in acc.values()), acc
    assert fid["train vs train, matched (floor)"] < fid["test vs train, matched"] < fid["test vs train"] < 2.0


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
