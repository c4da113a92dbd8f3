"""Train the whole refiner, the paper's parts and the learned steps, in parallel processes, and assemble it.

Each part is trained by its own ``motion-refiner train ... --only PART`` process (one thread each: on CPU the
networks are small, and one process per core is what scales), longest first, ``jobs`` at a time; then this process
trains the closed-form parts, calibrates every threshold on the split's held-out subjects and writes the refiner.
Finished parts are kept in ``out/parts`` (and ``out/paper``), so a rerun resumes; each process logs to ``out/logs``.
"""
from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["TrainJob", "whole_refiner_jobs", "run_jobs", "train_whole_refiner"]

log = logging.getLogger(__name__)

#: Core-minutes each job takes with the "fast" configuration on a 2-core CPU, two jobs at a time (HumanAct12, train
#: split): the order in which jobs start (longest first keeps the last one from running alone for long).
JOB_MINUTES = {"paper": 30, "timing_estimator": 22, "flaw_repairer": 14, "flaw_recognizer": 12, "pose_prior": 11,
               "texture_filter": 7, "noise": 3, "flaw_classifier": 2}


@dataclass(frozen=True)
class TrainJob:
    """One process's work: ``commands`` (argument lists of ``motion-refiner``) run one after another."""

    name: str
    commands: tuple[tuple[str, ...], ...]


def whole_refiner_jobs(out: Path, common: tuple[str, ...]) -> list[TrainJob]:
    """The jobs that train every part of a refiner into ``out``, longest first. ``common`` are the arguments every
    ``motion-refiner train`` call shares (dataset, data, split, config, seed, device)."""
    learned = ("train", *common, "--out", str(out), "--learned", "--only")
    jobs = [TrainJob("paper", (("train", *common, "--out", str(out / "paper")),)),
            # the noise residual is trained behind this run's noise filter
            TrainJob("noise", ((*learned, "noise_filter"), (*learned, "noise_residual")))]
    jobs += [TrainJob(name, ((*learned, name),)) for name in ("timing_estimator", "flaw_repairer", "texture_filter",
                                                               "pose_prior", "flaw_recognizer", "flaw_classifier")]
    return sorted(jobs, key=lambda j: -JOB_MINUTES[j.name])


def run_jobs(jobs: list[TrainJob], n_jobs: int, log_dir: Path, *, threads: int = 1, poll: float = 2.0) -> dict:
    """Run ``jobs`` in ``n_jobs`` parallel processes (``threads`` torch / BLAS threads each), in the given order,
    each to ``log_dir/<name>.log``. Returns ``{name: seconds}``; a ``RuntimeError`` names the first job that failed
    (the others are left to finish, so their parts are kept for a rerun). Interrupted (Ctrl-C, an error here), it
    stops the processes it started before it returns: no trainer is left running on its own."""
    if n_jobs < 1:
        raise ValueError(f"`jobs` must be a positive int; got {n_jobs}.")
    log_dir.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, **{k: str(threads) for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")}}
    queue, running, seconds, failed = list(jobs), {}, {}, []

    def start(job: TrainJob, step: int):
        cmd = [sys.executable, "-m", "refiner", *job.commands[step]]
        with open(log_dir / f"{job.name}.log", "a") as handle:  # the child keeps its own copy of the descriptor
            handle.write(f"$ {' '.join(cmd)}\n")
            handle.flush()
            return subprocess.Popen(cmd, stdout=handle, stderr=subprocess.STDOUT, env=env)

    try:
        _run_queue(queue, running, seconds, failed, n_jobs, start, poll)
    except BaseException:
        for _, _, _, proc in running.values():
            proc.terminate()
        for _, _, _, proc in running.values():
            proc.wait()
        raise
    if failed:
        raise RuntimeError(f"training job {failed[0]!r} failed: see {log_dir / (failed[0] + '.log')}; "
                           "rerun the same command to resume from the finished parts.")
    return seconds


def _run_queue(queue, running, seconds, failed, n_jobs, start, poll) -> None:
    """:func:`run_jobs`' loop: start jobs while there is room, move each on to its next command or record it."""
    while queue or running:
        while queue and len(running) < n_jobs and not failed:
            job = queue.pop(0)
            log.info("started %s", job.name)
            running[job.name] = (job, 0, time.perf_counter(), start(job, 0))
        time.sleep(poll)
        for name, (job, step, t0, proc) in list(running.items()):
            if proc.poll() is None:
                continue
            del running[name]
            if proc.returncode != 0:
                failed.append(name)
                log.error("%s failed (exit %d): see its log", name, proc.returncode)
            elif step + 1 < len(job.commands) and not failed:
                running[name] = (job, step + 1, t0, start(job, step + 1))
            elif step + 1 == len(job.commands):
                seconds[name] = round(time.perf_counter() - t0, 1)
                log.info("finished %s in %.1f min", name, seconds[name] / 60)
        if failed and not running:
            break


def train_whole_refiner(dataset, out: str | Path, common: tuple[str, ...], *, split: str = "all", n_jobs: int = 2,
                        config: str = "default", random_state: int = 0, device: str = "auto"):
    """Train every part of a refiner on ``dataset`` in ``n_jobs`` processes (:func:`run_jobs`), then calibrate and
    assemble it in ``out`` (the paper's refiner, in ``out/paper``, is its base). ``common``: the ``motion-refiner
    train`` arguments naming the dataset, split, config, seed and device. Writes ``out/train_whole.json`` (seconds
    per job, wall-clock seconds in all) and returns the refiner."""
    from refiner.refinement.train_learned import train_learned_refiner  # imports torch

    out = Path(out)
    t0 = time.perf_counter()
    seconds = run_jobs(whole_refiner_jobs(out, common), n_jobs, out / "logs")
    t1 = time.perf_counter()
    refiner = train_learned_refiner(dataset, out, split=split, base=out / "paper", config=config, device=device,
                                    random_state=random_state)
    record = {"jobs": n_jobs, "config": config, "split": split, "job_seconds": seconds,
              "parallel_seconds": round(t1 - t0, 1), "assembly_seconds": round(time.perf_counter() - t1, 1),
              "wall_seconds": round(time.perf_counter() - t0, 1)}
    (out / "train_whole.json").write_text(json.dumps(record, indent=1))
    log.info("whole refiner in %.1f min (%d jobs): %s", record["wall_seconds"] / 60, n_jobs, out)
    return refiner
