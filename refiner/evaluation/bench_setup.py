"""What every ``motion-refiner bench`` suite shares: the data it reads, one thread, progress, and its record.

A suite is a function ``(data, out, quick, *, progress=None, ...) -> dict``: it measures, writes its
figures as ``<suite>.json`` in ``out`` (:func:`write_record`) and returns the same record. It prints
nothing; ``progress``, when given, is called as ``progress(event, payload)`` with figures as soon as
they are known (the command line prints them, see :mod:`refiner.cli.bench`).
"""
from __future__ import annotations

import json
from contextlib import contextmanager
from pathlib import Path
from typing import Callable

from threadpoolctl import threadpool_limits

from refiner.io.datasets import load_humanact12

__all__ = ["Progress", "ignore_progress", "write_record", "one_thread", "load_bench_humanact12",
           "load_humanact12_and_recognizer", "summary_record"]

#: ``progress(event, payload)``: a suite's figures as they come (event names are listed by each suite).
Progress = Callable[[str, dict], None]


def ignore_progress(event: str, payload: dict) -> None:
    """The default ``progress``: drop the event."""


def write_record(out: Path | None, suite: str, record: dict) -> dict:
    """Write a suite's figures as ``<suite>.json`` in ``out`` (nothing when ``out`` is None); returns ``record``."""
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        (Path(out) / f"{suite}.json").write_text(json.dumps(record, indent=1))
    return record


@contextmanager
def one_thread():
    """Torch and BLAS on one thread, restored after; also a decorator. The networks are small: one
    thread is several times faster on CPU, and on a busy machine two can be 30-100 times slower."""
    import torch  # here, not at the top: importing a suite (``motion-refiner --help``) must not load torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with threadpool_limits(1):
            yield
    finally:
        torch.set_num_threads(threads)


def load_bench_humanact12(data: Path | None):
    """HumanAct12 from ``data`` (the folder holding ``humanact12/``), or from the default data folder."""
    return load_humanact12(None if data is None else Path(data) / "humanact12" / "humanact12_joints.npz")


def load_humanact12_and_recognizer(data: Path | None, *, hidden: str):
    """HumanAct12 and the Action2Motion recogniser, from ``data`` (folder holding humanact12/) or the defaults."""
    from refiner.evaluation.evaluators import load_recognizer  # imports torch: see one_thread

    dataset = load_bench_humanact12(data)
    recognizer = load_recognizer("humanact12", hidden=hidden,
                                 directory=None if data is None else Path(data).parent / "evaluators")
    return dataset, recognizer


def summary_record(summary: dict) -> dict:
    """An evaluation summary as JSON: metric -> ``[mean, 95 % half-width]``."""
    return {k: [float(m), float(h)] for k, (m, h) in summary.items()}
