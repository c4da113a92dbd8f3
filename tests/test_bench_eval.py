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
        # linear interpolation over the true flaw frames removes most of a stall or a glide
        assert by[(family, "oracle_linear")]["mpjpe_cm"] < ident["mpjpe_cm"]
    assert by[("transition_jitter", "savgol")]["removed_pct"] > 20.0  # a smoothing filter removes jitter
    assert by[("frozen_transition", "oracle_linear")]["removed_pct"] > 50.0


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
