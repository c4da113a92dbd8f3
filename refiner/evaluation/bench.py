"""``motion-refiner bench``: the benchmark suites, by name (speed and quality targets live here).

Every suite is a function ``(data, out, quick, *, progress=None, ...) -> dict`` that returns its figures
as a record and, with ``out``, writes them as ``<suite>.json`` (:mod:`refiner.evaluation.bench_setup`).
The suites print nothing: the command line (:mod:`refiner.cli.bench`) prints their tables and progress
and writes ``REPORT.md``. Each suite is a module of its own, its record described there:
:mod:`~refiner.evaluation.bench_concepts`, :mod:`~refiner.evaluation.bench_refiner` (``refiner`` and
``speed``), :mod:`~refiner.evaluation.bench_sanity`, :mod:`~refiner.evaluation.bench_flaws`,
:mod:`~refiner.evaluation.bench_samples`, :mod:`~refiner.evaluation.bench_skeletons`,
:mod:`~refiner.evaluation.bench_generators`, :mod:`~refiner.evaluation.bench_noharm` and
:mod:`~refiner.evaluation.bench_corpus`.
"""
from __future__ import annotations

from typing import Callable

from refiner.evaluation.bench_concepts import bench_concepts
from refiner.evaluation.bench_corpus import bench_corpus
from refiner.evaluation.bench_flaws import bench_flaws
from refiner.evaluation.bench_generators import bench_generators
from refiner.evaluation.bench_heldout import bench_heldout
from refiner.evaluation.bench_noharm import bench_noharm
from refiner.evaluation.bench_refiner import bench_refiner, bench_speed
from refiner.evaluation.bench_samples import bench_samples
from refiner.evaluation.bench_sanity import bench_sanity
from refiner.evaluation.bench_setup import one_thread, write_record
from refiner.evaluation.bench_skeletons import bench_skeletons

__all__ = [
    "SUITES",
    "write_record",
    "one_thread",
    "bench_concepts",
    "bench_refiner",
    "bench_speed",
    "bench_sanity",
    "bench_heldout",
    "bench_flaws",
    "bench_samples",
    "bench_skeletons",
    "bench_generators",
    "bench_noharm",
    "bench_corpus",
]

#: Suite name (``motion-refiner bench NAME``) -> suite, in the order ``bench all`` runs them.
SUITES: dict[str, Callable[..., dict]] = {
    "concepts": bench_concepts,
    "refiner": bench_refiner,
    "speed": bench_speed,
    "sanity": bench_sanity,
    "heldout": bench_heldout,
    "flaws": bench_flaws,
    "samples": bench_samples,
    "skeletons": bench_skeletons,
    "generators": bench_generators,
    "noharm": bench_noharm,
    "corpus": bench_corpus,
}
