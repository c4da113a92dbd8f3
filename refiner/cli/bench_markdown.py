"""``motion-refiner bench markdown``: ``docs/benchmarks.md`` and the README's table of current figures, written from
the bench records (the only way either is made).

The records are the ``<suite>.json`` files ``motion-refiner bench SUITE --out DIR`` writes (:data:`SUITES_SHOWN`,
committed under ``docs/records/``); each suite's section is the one ``bench`` prints
(:data:`refiner.cli.bench_tables.SECTIONS`), so the page and a fresh run's ``REPORT.md`` never disagree.
"""
from __future__ import annotations

import json
from pathlib import Path

from refiner.cli.bench_tables import SECTIONS
from refiner.evaluation.bench_noharm import A2M_SETS

__all__ = ["SUITES_SHOWN", "RECIPE", "MEASURED", "benchmarks_markdown", "measured_table", "with_measured",
           "write_benchmarks_markdown"]

#: The suites the page shows, in order.
SUITES_SHOWN = ("heldout", "noharm", "generators", "speed", "corpus")

#: The commands that make the records and the page (the page's header repeats them).
RECIPE = ("motion-refiner bench heldout --stride 2 --out docs/records",
          "motion-refiner bench noharm --out docs/records",
          "motion-refiner bench generators --out docs/records",
          "motion-refiner bench speed --out docs/records",
          "motion-refiner bench corpus --out docs/records",
          "motion-refiner bench markdown --records docs/records --out docs/benchmarks.md --readme README.md")

#: The README's table of current figures lies between these two lines.
MEASURED = ("<!-- measured: made by `motion-refiner bench markdown --readme README.md`, do not edit -->", "<!-- /measured -->")



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


def measured_table(records) -> str:
    """The README's table of current figures against issue 44's targets, from the records folder ``records``;
    ``ValueError`` when a record lacks a figure the table shows."""
    records = Path(records)
    try:
        return _measured(*(_record(records, suite) for suite in SUITES_SHOWN))
    except (KeyError, IndexError, TypeError) as e:
        raise ValueError(f"a bench record in {str(records)!r} lacks a figure the README's table shows ({e!r}); "
                         "make the records again with this version.") from e


def _measured(h: dict, n: dict, g: dict, sp: dict, co: dict) -> str:
    fam, mech = h["families"], h["mechanisms"]
    angle = ", ".join(f"`{k}` {r['refined']:+.1f}" for k, r in mech.items() if r["family"] == "angle")
    folds = [h["clean"][k] for k in h["clean"] if k != "all"]
    sets = n["sets"]
    touched = [f"{k} {100 * s['after']['clips_changed']:.1f} %" for k, s in sets.items() if s["after"]["clips_changed"]]
    worse = [k for k, s in sets.items() if s["verdict"]["violated"]]
    bones = [f"{k} {s['after']['bone_length_variation_pct']:.1f} %" for k, s in sets.items()
             if s["after"]["bone_length_variation_pct"] >= 1.0]
    real = [sets[k] for k in A2M_SETS if k in sets]
    acc = [sum(s[w]["accuracy_pct"] for s in real) / max(1, len(real)) for w in ("before", "after")]
    fid = [(k.split("/")[0], g["rows"][k]["metrics"]["fid"], g["rows"][k.replace("generated", "refined")]["metrics"]["fid"])
           for k in g["rows"] if k.endswith("/generated") and k.replace("generated", "refined") in g["rows"]]
    speed = sp["devices"][0]
    corpus = "; ".join(f"{r['name']} {r['clips_per_s']:.0f}" for r in co["rows"])
    rows = [
        (f"held-out mechanisms, mean % of added MPJPE removed (`bench heldout`, {h['clips']} clips)",
         f"**{h['heldout_mean']:+.1f} %** (linear in-fill on the same flags {h['linear_mean']:+.1f} %)", ">= 40 %"),
        ("families: " + " / ".join(fam), " / ".join(f"{v:+.1f}" for v in fam.values()) + " %", "none below 0"),
        ("pose flaws made in joint angles (angle family)", f"{fam['angle']:+.1f} % ({angle})", ">= 30 %"),
        ("mechanisms written blind (default weights)", ", ".join(f"`{k}` {r['refined']:+.1f} %" for k, r in h["blind"].items()), ""),
        ("clean held-out clips: default / fold weights (cm moved, clips touched)",
         f"{h['clean']['all']['cm_moved']:.3f} cm, {100 * h['clean']['all']['clips_touched']:.1f} % / at most "
         f"{max(c['cm_moved'] for c in folds):.3f} cm, {100 * max(c['clips_touched'] for c in folds):.1f} %", "< 0.3 cm, <= 5 %"),
        (f"no-harm suite, {len(sets)} sets (`bench noharm`)", f"sets worse on some figure: {', '.join(worse) or 'none'}; "
         f"clips changed: {', '.join(touched) or 'none'}", "every set: no harm"),
        ("bone-length variation after refinement", "sets at 1 % or more: " + (", ".join(bones) or "none"), "< 1 %"),
        (f"real sets' accuracy, mean of {len(real)}", f"{acc[0]:.1f} -> {acc[1]:.1f} %", "up on average"),
        (f"FID generated -> refined ({g['n_replications']} replications, 95 % interval; `bench generators`)",
         "; ".join(f"{k} {a[0]:.3f} ± {a[1]:.3f} -> {b[0]:.3f} ± {b[1]:.3f}" for k, a, b in fid), "not worse"),
        (f"speed, 60 frames: batch 1 / batch {sp['batch']} (`bench speed`)",
         f"{speed['median_ms']:.1f} ms / {speed['clips_per_s']:.0f} clips/s", "<= 15 ms / >= 500 clips/s"),
        ("cost by clip length, batch 1, µs per frame (`bench speed`)",
         ", ".join(f"{r['frames']} frames {r['us_per_frame']:.0f}" for r in sp.get("lengths", [])) or "not measured",
         "linear in clip length"),
        (f"corpus, {co['clips']} clips in {co['shards']} shards, clips/s (`bench corpus`)", corpus, ""),
    ]
    return "\n".join(["| figure (command) | value | target (issue 44) |", "|---|---|---|",
                      *(f"| {a} | {b} | {c} |" for a, b, c in rows)])


def with_measured(readme: str, table: str) -> str:
    """``readme`` text with the block between the :data:`MEASURED` lines replaced by ``table``."""
    start, stop = MEASURED
    if readme.count(start) != 1 or readme.count(stop) != 1 or readme.index(start) > readme.index(stop):
        raise ValueError(f"the README must hold the lines {start!r} and {stop!r} once each, in that order.")
    head, rest = readme.split(start)
    return f"{head}{start}\n{table}\n{stop}{rest.split(stop, 1)[1]}"


def write_benchmarks_markdown(records, out, readme=None) -> Path:
    """Write :func:`benchmarks_markdown` of ``records`` to the file ``out`` (its folder is made) and, with ``readme``,
    the :func:`measured_table` into that file's measured block; returns ``out``."""
    out = Path(out)
    text = benchmarks_markdown(records)  # read every record before anything is written
    readme_text = with_measured(Path(readme).read_text(), measured_table(records)) if readme else None
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    if readme:
        Path(readme).write_text(readme_text)
    return out
