"""``motion-refiner bench``: run benchmark suites, print their tables as they finish, write ``REPORT.md``.

The suites (:data:`refiner.evaluation.bench.SUITES`) return records and write ``<suite>.json``; this
module prints their progress lines and Markdown sections (:mod:`refiner.cli.bench_tables`) and, with
``--out``, collects the sections into ``REPORT.md``.

``motion-refiner bench markdown`` runs nothing: it writes ``docs/benchmarks.md`` from the committed records
(:mod:`refiner.cli.bench_markdown`).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from refiner.cli.bench_markdown import write_benchmarks_markdown
from refiner.cli.bench_tables import PROGRESS, SECTIONS
from refiner.core.manifest import refiner_weight_sets
from refiner.evaluation.bench_setup import write_record
from refiner.evaluation.bench import SUITES

__all__ = ["bench_arguments", "bench_run", "run_benchmarks"]


def bench_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("suite", nargs="?", default="all", choices=[*SUITES, "all", "markdown"],
                   help="a suite, all of them, or markdown: write docs/benchmarks.md from the records (runs nothing)")
    p.add_argument("--data", type=Path, default=None, help="folder holding humanact12/ (default: ../shared/data)")
    p.add_argument("--out", type=Path, default=None, help="folder for REPORT.md, plots and <suite>.json (the figures as "
                                                          "records); markdown: the page (default docs/benchmarks.md)")
    p.add_argument("--records", type=Path, default=Path("docs/records"),
                   help="markdown: the folder of the suites' records (default docs/records)")
    p.add_argument("--readme", type=Path, default=None,
                   help="markdown: also write the table of current figures into this README's measured block")
    p.add_argument("--quick", action="store_true", help="tiny configuration (for tests)")
    p.add_argument("--stride", type=int, default=1, help="flaws, skeletons, heldout: keep every N-th held-out clip (skeletons default 4)")
    p.add_argument("--severity", type=int, action="append", choices=[1, 2, 3], help="flaws: only these severities")
    p.add_argument("--weights", type=Path, default=None,
                   help="folder of weight sets named as the shipped ones, looked in first: DIR/humanact12-motion "
                        "replaces the default refiner's motion model, DIR/humanact12-train (e.g. `motion-refiner train "
                        "--split train --out DIR/humanact12-train`) the concepts method's weights; sets it lacks are "
                        "the shipped ones")


def bench_run(args: argparse.Namespace) -> int:
    if args.suite == "markdown":
        out = write_benchmarks_markdown(args.records, args.out or Path("docs/benchmarks.md"), args.readme)
        print(f"{out}{f' and {args.readme}' if args.readme else ''} written from the records in {args.records}")
        return 0
    return run_benchmarks(args.suite, data=args.data, out=args.out, quick=args.quick, stride=args.stride,
                          severities=tuple(args.severity) if args.severity else None, weights=args.weights)


def run_benchmarks(suite: str, *, data: Path | None = None, out: Path | None = None, quick: bool = False,
                   stride: int = 1, severities: tuple[int, ...] | None = None, weights: Path | None = None) -> int:
    """Run ``suite`` (or ``"all"``), printing each suite's progress and section; returns the exit code 0.

    With ``out`` every suite writes ``<suite>.json`` there and the sections are written as ``REPORT.md``. ``weights``:
    a folder of weight sets looked in before the shipped ones (``MotionRefiner.pretrained``, :meth:`refiner.Refiner.pretrained`).
    """
    if weights is not None:
        found = refiner_weight_sets(weights)
        sets = [w["folder"] for w in found if w["folder"] == w["skeleton"] + ("" if w["split"] == "all" else f"-{w['split']}")]
        sets += sorted(p.name for p in Path(weights).glob("*-motion") if (p / "manifest.json").is_file())
        if not sets:  # else every suite would quietly refine with the shipped weights
            raise ValueError(f"`--weights` {weights} holds no weight set named for its skeleton and split (found: "
                             f"{', '.join(w['folder'] for w in found) or 'none'}): give the folder that holds your set "
                             "as humanact12-motion/ or humanact12-train/ (a folder with its manifest.json).")
    names = list(SUITES) if suite == "all" else [suite]
    sections = [] if weights is None else [f"Weights: `{weights}` ({', '.join(sets)}), looked in before the shipped ones."]
    for name in names:
        extra = ({"stride": stride, "severities": severities} if name == "flaws"
                 else {"stride": stride} if name in ("skeletons", "heldout") and stride > 1 else {})
        record = SUITES[name](data, out, quick, progress=_printer(name), weights=weights, **extra)
        if weights is not None:  # the record says whose weights it measured
            record = write_record(out, name, {**record, "weights": {"folder": str(Path(weights).resolve()), "sets": sets}})
        section = SECTIONS[name](record)
        print(section, flush=True)
        print(flush=True)
        sections.append(section)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "REPORT.md").write_text("# motion-refiner benchmark report\n\n" + "\n\n".join(sections) + "\n")
        print(f"report written to {out / 'REPORT.md'}")
    return 0


def _printer(suite: str):
    """The ``progress`` callback of ``suite``: print the line of each event that has one."""
    def progress(event: str, payload: dict) -> None:
        line = PROGRESS.get((suite, event))
        if line is not None:
            print(line(payload), flush=True)

    return progress
