"""The corpus run's files and its boundary, without Ray: shard lists, completeness, and the missing-extra message."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from refiner.corpus import find_shards, is_complete, refine_corpus, report_path
from refiner.corpus.shards import write_failure, write_shard


def _report(n_frames: int, changed: int = 0) -> dict:
    return {"n_frames": n_frames, "frames_changed": changed, "changes": []}


def test_find_shards_takes_a_folder_or_a_glob_and_refuses_clashes(tmp_path):
    for name in ("a/x.npy", "a/y.npz", "b/x.npy", "a/notes.txt"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_bytes(b"")
    assert [p.name for p in find_shards(tmp_path / "a")] == ["x.npy", "y.npz"]
    assert [p.name for p in find_shards(str(tmp_path / "a" / "*.npy"))] == ["x.npy"]
    with pytest.raises(ValueError, match="same output"):
        find_shards(str(tmp_path / "*" / "x.npy"))
    with pytest.raises(ValueError, match="no .npy or .npz shards"):
        find_shards(str(tmp_path / "c*"))
    with pytest.raises(ValueError, match="IN must be"):
        find_shards(tmp_path / "missing")


def test_a_shard_is_complete_only_with_its_report_closed_and_its_output_intact(tmp_path):
    shard = tmp_path / "s.npy"
    out = tmp_path / "out"
    out.mkdir()
    clips = [np.zeros((30, 24, 3), np.float32), np.ones((30, 24, 3), np.float32)]
    np.save(shard, np.stack(clips))
    assert not is_complete(shard, out)
    closing = write_shard(shard, out, clips, True, [_report(30, 2), _report(30)])
    assert closing["status"] == "done" and closing["frames_changed"] == 2
    assert is_complete(shard, out)
    np.testing.assert_array_equal(np.load(out / "s.npy"), np.stack(clips))
    assert sorted(p.name for p in out.iterdir()) == ["s.npy", "s.report.jsonl"]  # no temporary file left

    lines = report_path(shard, out).read_text().splitlines()
    report_path(shard, out).write_text("\n".join(lines[:-1]) + "\n" + lines[-1][:20])  # report cut short
    assert not is_complete(shard, out)
    report_path(shard, out).write_text("\n".join(lines) + "\n")
    np.save(out / "s.npy", np.stack(clips)[:1])  # output rewritten by something else
    assert not is_complete(shard, out)

    write_failure(shard, out, "ValueError: broken")
    assert not is_complete(shard, out)


def test_a_shard_other_than_the_one_refined_is_not_complete(tmp_path):
    """A shard regenerated under the same name, or another folder's shard of that name, is redone, not skipped."""
    out = tmp_path / "out"
    out.mkdir()
    clips = [np.zeros((30, 24, 3), np.float32)]
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    np.save(tmp_path / "a" / "s.npy", np.stack(clips))
    np.save(tmp_path / "b" / "s.npy", np.stack(clips) + 1)
    write_shard(tmp_path / "a" / "s.npy", out, clips, True, [_report(30)])
    assert is_complete(tmp_path / "a" / "s.npy", out)
    assert not is_complete(tmp_path / "b" / "s.npy", out)  # same stem, other content
    np.save(tmp_path / "a" / "s.npy", np.stack(clips) + 2)  # the generator wrote the shard again
    assert not is_complete(tmp_path / "a" / "s.npy", out)


def test_clips_of_different_lengths_go_to_an_npz(tmp_path):
    clips = [np.zeros((30, 24, 3), np.float32), np.zeros((40, 24, 3), np.float32)]
    np.savez(tmp_path / "r.npz", a=clips[0], b=clips[1])
    out = tmp_path / "out"
    out.mkdir()
    closing = write_shard(tmp_path / "r.npz", out, clips, True, [_report(30), _report(40)])
    assert closing["output"] == "r.npz" and is_complete(tmp_path / "r.npz", out)
    with np.load(out / "r.npz") as f:
        assert [f[k].shape[0] for k in sorted(f.files)] == [30, 40]


def test_bad_arguments_are_value_errors(tmp_path):
    with pytest.raises(ValueError, match="workers"):
        refine_corpus(tmp_path, tmp_path / "out", workers=0)
    np.save(tmp_path / "s.npy", np.zeros((30, 24, 3), np.float32))
    with pytest.raises(ValueError, match="holds input shards"):
        refine_corpus(tmp_path, tmp_path)


def test_without_ray_the_command_says_how_to_install_it(tmp_path, monkeypatch, capsys):
    from refiner.cli.main import main

    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now fails, as where the extra is not installed
    assert main(["refine-corpus", str(tmp_path), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "motion-refiner[ray]" in err and "pip install" in err


def test_nothing_imports_ray_without_a_corpus_run():
    code = "import sys, refiner, refiner.cli.main, refiner.corpus; print('ray' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_the_bench_section_shows_every_row():
    from refiner.cli.bench_tables import SECTIONS

    rows = [{"name": "refine DIR", "wall_s": 10.0, "clips_per_s": 32.0},
            {"name": "Ray, 2 workers", "wall_s": 8.0, "clips_per_s": 40.0, "pipeline_s": 4.0, "pipeline_clips_per_s": 80.0}]
    text = SECTIONS["corpus"]({"clips": 320, "frames": 19200, "shards": 5, "cpus": 2, "rows": rows, "notes": ["a note"]})
    assert "| refine DIR | 10.0 | 32.0 | - |" in text and "| Ray, 2 workers | 8.0 | 40.0 | 80.0 |" in text
    assert "320 clips of 60 frames in 5 shards" in text and text.endswith("a note")
