"""``motion-refiner bench markdown``: ``docs/benchmarks.md`` written from the bench records, the only way it is made.

The records are the ``<suite>.json`` files ``motion-refiner bench SUITE --out DIR`` writes (:data:`SUITES_SHOWN`,
committed under ``docs/records/``); each suite's section is the one ``bench`` prints
(:data:`refiner.cli.bench_tables.SECTIONS`), so the page and a fresh run's ``REPORT.md`` never disagree.
"""
from __future__ import annotations

import json
from pathlib import Path

from refiner.cli.bench_tables import SECTIONS

__all__ = ["SUITES_SHOWN", "RECIPE", "benchmarks_markdown", "write_benchmarks_markdown"]

#: The suites the page shows, in order.
SUITES_SHOWN = ("heldout", "noharm")

#: The commands that make the records and the page (the page's header repeats them).
RECIPE = ("motion-refiner bench heldout --stride 2 --out docs/records",
          "motion-refiner bench noharm --out docs/records",
          "motion-refiner bench markdown --records docs/records --out docs/benchmarks.md")


def _record(records: Path, suite: str) -> dict:
    """``records/<suite>.json``; ``ValueError`` naming the file when it is missing, not JSON or a quick run's."""
    path = records / f"{suite}.json"
    if not path.is_file():
        raise ValueError(f"no bench record {str(path)!r}: write it with "
                         f"`motion-refiner bench {suite} --out {records}`.")
    try:
        record = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"bench record {str(path)!r} is not JSON: {e}") from e
    if not isinstance(record, dict):
        raise ValueError(f"bench record {str(path)!r} must hold a JSON object.")
    if record.get("quick"):  # the tiny test configuration must never reach the published page
        raise ValueError(f"bench record {str(path)!r} comes from a --quick run; run the suite without --quick.")
    return record


def _weights(records: dict[str, dict]) -> str:
    """Whose weights the records measured, in words (``bench --weights`` stores them in each record)."""
    own = {f"`{r['weights']['folder']}` ({', '.join(r['weights']['sets'])})"
           for r in records.values() if "weights" in r}
    if not own:
        return "the shipped weights (`refiner/weights/<skeleton>-motion`)"
    return "weights " + "; ".join(sorted(own)) + ", looked in before the shipped ones"


def benchmarks_markdown(records) -> str:
    """The text of ``docs/benchmarks.md`` from the records folder ``records`` (``<suite>.json`` per shown suite).

    Raises
    ------
    ValueError
        A record is missing, not a JSON object or from a ``--quick`` run.
    """
    records = Path(records)
    recs = {suite: _record(records, suite) for suite in SUITES_SHOWN}
    commands = "\n".join(RECIPE)
    header = (
        "# Benchmark figures\n\n"
        "Generated from the bench records in `docs/records/` (one JSON per suite) with "
        f"{_weights(recs)}; seconds are wall time on the machine that wrote them. Do not edit by hand: to measure "
        "again and regenerate this page, run from the repository root:\n\n"
        f"```\n{commands}\n```"
    )
    return "\n\n".join([header, *(SECTIONS[suite](recs[suite]) for suite in SUITES_SHOWN)]) + "\n"


def write_benchmarks_markdown(records, out) -> Path:
    """Write :func:`benchmarks_markdown` of ``records`` to the file ``out`` (its folder is made); returns ``out``."""
    out = Path(out)
    text = benchmarks_markdown(records)  # read every record before anything is written
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    return out
