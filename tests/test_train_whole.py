"""Parallel training jobs: which parts, in which order, and how failures are reported."""
import time
from pathlib import Path

import pytest

from refiner.refinement.train_learned import LEARNED_PARTS
from refiner.refinement.train_whole import JOB_MINUTES, TrainJob, run_jobs, whole_refiner_jobs


def test_jobs_cover_every_part_longest_first(tmp_path):
    jobs = whole_refiner_jobs(tmp_path, ("--dataset", "humanact12"))
    assert [JOB_MINUTES[j.name] for j in jobs] == sorted((JOB_MINUTES[j.name] for j in jobs), reverse=True)
    trained = [c[c.index("--only") + 1] for j in jobs for c in j.commands if "--only" in c]
    # the amplitude restorer is closed form and fitted at assembly; the timing estimator and residual are options
    assert set(trained) == (set(LEARNED_PARTS) - {"amplitude_restorer"}) | {"timing_estimator", "noise_residual"}
    assert len(trained) == len(set(trained))
    noise = next(j for j in jobs if j.name == "noise")
    assert [c[-1] for c in noise.commands] == ["noise_filter", "noise_residual"]  # the residual behind this filter
    paper = next(j for j in jobs if j.name == "paper")
    assert paper.commands[0][paper.commands[0].index("--out") + 1] == str(tmp_path / "paper")


def test_run_jobs_runs_in_parallel_and_names_a_failure(tmp_path):
    ok = [TrainJob(f"help{k}", (("train", "--help"),)) for k in range(2)]
    t0 = time.perf_counter()
    seconds = run_jobs(ok, 2, tmp_path / "logs", poll=0.1)
    assert set(seconds) == {"help0", "help1"}
    assert time.perf_counter() - t0 < 0.9 * sum(seconds.values())  # side by side, not one after the other
    assert "--whole" in (tmp_path / "logs" / "help1.log").read_text()
    bad = [TrainJob("broken", (("train", "--no-such-option"),)), *ok[:1]]
    with pytest.raises(RuntimeError, match="'broken' failed"):
        run_jobs(bad, 2, tmp_path / "logs2", poll=0.1)
    with pytest.raises(ValueError, match="jobs"):
        run_jobs(ok, 0, Path(tmp_path))
