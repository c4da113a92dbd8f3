"""Corpus refinement on a local Ray (2 CPUs): six shards, one corrupt; a run killed midway, then rerun.

The first run is killed (an exception the driver does not catch) at its fourth rename, i.e. after some shards are
complete and one has its output but not yet its report; the rerun must skip the complete ones without writing them
again, redo the rest, and leave outputs identical to ``refine()`` on each clip.
"""
from __future__ import annotations

import json
import os
from types import SimpleNamespace

import numpy as np
import pytest

ray = pytest.importorskip("ray", reason="Ray is not installed: corpus refinement is the optional extra "
                                        "(pip install -e '.[ray]')")
pytest.importorskip("ray.data", reason="ray is installed without its data extra (pip install -e '.[ray]')")
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")  # Ray's own, about its own settings

from refiner.corpus import corpus_settings, is_complete, refine_corpus, report_path  # noqa: E402
from refiner.corpus import shards as shard_files  # noqa: E402


class _Killed(BaseException):
    """Stands for the process being killed: nothing in the driver catches it."""


@pytest.fixture(scope="module")
def corpus(tmp_path_factory, humanact12):
    """Five shards of clips with held frames (several get refined) in four layouts, and one corrupt file."""
    from refiner.refinement.training.mechanisms import MECHANISMS

    rng = np.random.default_rng(0)
    test = [m for m in humanact12.split("test") if m.n_frames >= 64][:13]
    held = [MECHANISMS["time_hold"](m.joints[:64].astype(np.float64), rng, 1.5).astype(np.float32) for m in test]
    folder = tmp_path_factory.mktemp("corpus") / "in"
    folder.mkdir()
    np.save(folder / "s0.npy", np.stack(held[0:4]))                       # (N, T, J, 3)
    np.save(folder / "s1.npy", held[4])                                   # one clip (T, J, 3)
    np.savez(folder / "s2.npz", joints=np.stack([c[:48] for c in held[5:8]]), labels=[m.action for m in test[5:8]])
    np.save(folder / "s3.npy", np.stack([c[:40] for c in held[8:10]]))
    np.save(folder / "s4.npy", np.stack(held[10:13]))
    (folder / "s5.npy").write_bytes(b"\x93NUMPY\x01\x00 truncated")          # corrupt
    return folder


@pytest.fixture(scope="module")
def runs(corpus, tmp_path_factory):
    """The killed run, then the rerun: the state between them and the rerun's writes."""
    out = tmp_path_factory.mktemp("corpus") / "out"
    shards = sorted(corpus.glob("*.np?"))
    ray.init(num_cpus=2, include_dashboard=False, object_store_memory=200 * 2**20, log_to_driver=False)
    mp = pytest.MonkeyPatch()
    try:
        renames = []

        def killing_replace(src, dst):
            if len(renames) == 3:
                raise _Killed
            renames.append(os.path.basename(dst))
            os.replace(src, dst)

        mp.setattr(shard_files, "os", SimpleNamespace(replace=killing_replace))
        with pytest.raises(_Killed):
            refine_corpus(corpus, out, workers=2, batch_size=4)
        complete = {s.name: _stat(out, s) for s in shards if is_complete(s, out, corpus_settings())}
        left_over = sorted(p.name for p in out.iterdir())

        written = []

        def recording_replace(src, dst):
            written.append(os.path.basename(dst))
            os.replace(src, dst)

        mp.setattr(shard_files, "os", SimpleNamespace(replace=recording_replace))
        summary = refine_corpus(str(corpus / "*.np?"), out, workers=2, batch_size=4)  # a glob, this time
    finally:
        mp.undo()
        ray.shutdown()
    return SimpleNamespace(out=out, shards=shards, complete=complete, left_over=left_over, written=written,
                           summary=summary, killed_after=renames)


def _stat(out, shard):
    """(inode, mtime) of a complete shard's output and report: changed when either is written again."""
    closing = json.loads(report_path(shard, out).read_text().splitlines()[-1])
    return [(os.stat(p).st_ino, os.stat(p).st_mtime_ns) for p in (out / closing["output"], report_path(shard, out))]


def test_the_kill_left_a_half_written_run(runs):
    assert 1 <= len(runs.complete) <= 2, runs.killed_after
    assert len(runs.left_over) > 2 * len(runs.complete)  # something beyond the complete shards' files: a half-written one


def test_rerun_finishes_every_shard_and_reports_the_corrupt_one(runs):
    valid = [s for s in runs.shards if s.name != "s5.npy"]
    assert all(is_complete(s, runs.out, corpus_settings()) for s in valid)
    assert not any(is_complete(s, runs.out, corpus_settings(stack=True)) for s in valid)  # other settings: redo
    assert list(runs.summary.failed) == [str(runs.shards[-1])]
    assert "s5.npy" in runs.summary.failed[str(runs.shards[-1])]
    failure = json.loads(report_path(runs.shards[-1], runs.out).read_text())
    assert failure["status"] == "failed" and "not a readable" in failure["error"]
    assert runs.summary.skipped == len(runs.complete)
    assert runs.summary.refined + runs.summary.skipped == 5
    assert not [p.name for p in runs.out.iterdir() if p.name.endswith(".tmp")]


def test_no_shard_is_written_twice(runs):
    assert len(runs.written) == len(set(runs.written)), runs.written
    for name, before in runs.complete.items():  # complete before the rerun: neither file touched
        shard = next(s for s in runs.shards if s.name == name)
        assert _stat(runs.out, shard) == before
        assert not {f"{shard.stem}.npy", f"{shard.stem}.report.jsonl"} & set(runs.written)


def test_outputs_equal_refine_on_each_clip(runs):
    import refiner
    from refiner.cli.refine import load_input

    changed = 0
    for shard in runs.shards[:-1]:
        motions, batched = load_input(shard)
        out = np.load(runs.out / f"{shard.stem}.npy")
        assert out.shape == ((len(motions),) if batched else ()) + motions[0].joints.shape
        lines = [json.loads(line) for line in report_path(shard, runs.out).read_text().splitlines()]
        for i, (m, line) in enumerate(zip(motions, lines)):
            expected, report = refiner.refine(m.joints, action=m.action, return_report=True)
            np.testing.assert_array_equal(out[i] if batched else out, expected)
            assert {k: v for k, v in line.items() if k not in ("clip", "frames_changed")} == json.loads(json.dumps(report.to_dict()))
            changed += int(report.changed_frames.sum())
        assert lines[-1]["status"] == "done" and lines[-1]["clips"] == len(motions)
    assert changed > 0  # the comparison covers refined frames, not only untouched ones
    assert runs.summary.frames_changed <= changed
