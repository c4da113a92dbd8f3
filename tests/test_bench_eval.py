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
def test_bench_flaws_quick(tmp_path, capsys):
    from conftest import shared_data_dir

    assert main(["bench", "flaws", "--quick", "--data", str(shared_data_dir()), "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "## Flaws (HumanAct12 subjects 11-12" in out and "severities [2]" in out
    clean = out.split("### Change on clean clips")[1].split("###")[0]
    identity = _row(clean, "identity")
    assert float(identity[1]) == 0.0 and abs(float(identity[4])) < 1e-6  # identity moves nothing
    assert float(_row(clean, "spline_fit")[1]) > float(_row(clean, "savgol")[1]) > 0.0
    summary = out.split("### Mean over families and severities")[1].split("###")[0]
    for name in ("identity", "savgol", "gaussian", "spline_fit"):
        cells = _row(summary, name)
        assert 0.5 < float(cells[1]) < 20.0 and 50.0 <= float(cells[4]) <= 100.0
    records = json.loads((tmp_path / "flaws.json").read_text())["flawed"]
    assert {r["family"] for r in records} == {"wrong_anchor", "anchor_drift", "transition_jitter",
                                              "frozen_transition", "reversed_transition", "time_warp",
                                              "foot_sliding"}
    # the corrupted clips (identity) are off the clean ones by a measurable amount in every family
    assert all(r["mpjpe_cm"] > 0.2 for r in records if r["refiner"] == "identity")
    assert ("ours_full" in {r["refiner"] for r in records}) or "`ours_full` skipped" in out


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
