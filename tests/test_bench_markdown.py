"""docs/benchmarks.md is what ``motion-refiner bench markdown`` makes of the committed records in docs/records."""
from __future__ import annotations

import json
import shutil

import pytest

from refiner.cli.bench_markdown import RECIPE, SUITES_SHOWN, benchmarks_markdown
from refiner.cli.main import main

from conftest import REPO

RECORDS = REPO / "docs" / "records"


def test_committed_page_is_in_step_with_the_records():
    """Regenerate in memory: any hand edit of the page, or a record changed without regenerating, fails here."""
    page = (REPO / "docs" / "benchmarks.md").read_text()
    assert benchmarks_markdown(RECORDS) == page, (
        "docs/benchmarks.md is out of step with docs/records: run `" + RECIPE[-1] + "` from the repository root.")
    for command in RECIPE:  # the page says how it is made
        assert command in page


def test_the_command_writes_the_page(tmp_path, capsys):
    out = tmp_path / "docs" / "benchmarks.md"
    assert main(["bench", "markdown", "--records", str(RECORDS), "--out", str(out)]) == 0
    assert out.read_text() == benchmarks_markdown(RECORDS)
    assert "written from the records" in capsys.readouterr().out


def test_own_weights_are_named(tmp_path):
    for suite in SUITES_SHOWN:
        record = json.loads((RECORDS / f"{suite}.json").read_text())
        record["weights"] = {"folder": "/w", "sets": ["humanact12-motion"]}
        (tmp_path / f"{suite}.json").write_text(json.dumps(record))
    page = benchmarks_markdown(tmp_path)
    assert "`/w` (humanact12-motion), looked in before the shipped ones" in page and "shipped weights (" not in page


@pytest.mark.parametrize("damage, words", [("missing", "no bench record"), ("not json", "is not JSON"),
                                           ("quick", "--quick run")])
def test_bad_records_are_value_errors_and_nothing_is_written(tmp_path, capsys, damage, words):
    for suite in SUITES_SHOWN:
        shutil.copy(RECORDS / f"{suite}.json", tmp_path / f"{suite}.json")
    noharm = tmp_path / "noharm.json"
    if damage == "missing":
        noharm.unlink()
    elif damage == "not json":
        noharm.write_text("{")
    else:
        noharm.write_text(json.dumps({**json.loads(noharm.read_text()), "quick": True}))
    with pytest.raises(ValueError, match=words):
        benchmarks_markdown(tmp_path)
    out = tmp_path / "page.md"
    assert main(["bench", "markdown", "--records", str(tmp_path), "--out", str(out)]) != 0
    assert words in capsys.readouterr().err and not out.exists()


def test_readme_table_is_in_step_with_the_records():
    """The README's table of current figures is the one the records make (`bench markdown --readme README.md`)."""
    from refiner.cli.bench_markdown import measured_table, with_measured

    readme = (REPO / "README.md").read_text()
    assert with_measured(readme, measured_table(RECORDS)) == readme, (
        "README.md's measured table is out of step with docs/records: run `" + RECIPE[-1] + "`.")
    with pytest.raises(ValueError, match="measured"):
        with_measured("no block here", "| table |")
