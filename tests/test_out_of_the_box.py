"""A machine with only the installed package: the demo, the Quickstart, ``doctor`` and "not found" messages.

Every test here points ``$MOTION_REFINER_DATA`` (and HOME and the working directory) at an empty
temporary folder, so nothing from ``../shared`` can be found.
"""
from __future__ import annotations

import contextlib
import io
import json
import re

import pytest

from conftest import REPO
from refiner.cli.main import main

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture
def no_shared(tmp_path, monkeypatch):
    """An empty data folder, HOME and working directory: no ../shared anywhere."""
    data = tmp_path / "data"
    data.mkdir()
    monkeypatch.setenv("MOTION_REFINER_DATA", str(data))
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.chdir(tmp_path)
    return data


def _run(argv) -> tuple[int, str]:
    import torch

    buffer, threads = io.StringIO(), torch.get_num_threads()
    try:
        with contextlib.redirect_stdout(buffer):
            code = main(argv)
    finally:
        torch.set_num_threads(threads)  # the demo sets one thread for its process
    return code, buffer.getvalue()


def test_demo_runs_without_shared_data(no_shared, tmp_path):
    """The README's main command (quick settings) needs only the package: GIFs, PNGs and the summary."""
    from refiner.io.datasets import default_data_dir

    assert default_data_dir() == no_shared and not any(no_shared.iterdir())
    out = tmp_path / "runs" / "demo"
    code, printed = _run(["demo", "--out", str(out), "--quick", "--no-mp4"])
    assert code == 0
    for stem in ("01_walk", "10_boxing"):
        for suffix in (".gif", "_keyframes.png", "_scores.png"):
            assert (out / f"{stem}{suffix}").stat().st_size > 0, stem + suffix
    summary = json.loads((out / "summary.json").read_text())
    assert [r["action_name"] for r in summary["rows"]] == ["walk", "boxing"]
    assert all(0.0 <= r["confidence_before"] <= 1.0 for r in summary["rows"])  # the shipped recogniser ran
    assert "| walk |" in (out / "summary.md").read_text() and "walk" in printed


def test_quickstart_runs_as_printed_without_shared_data(no_shared):
    """The README's Quickstart block, executed verbatim."""
    readme = (REPO / "README.md").read_text()
    block = re.search(r"## Quickstart\n.*?```python\n(.*?)```", readme, re.S).group(1)
    assert "load_humanact12()" not in block
    scope: dict = {}
    with contextlib.redirect_stdout(io.StringIO()):
        exec(compile(block, "README.md#quickstart", "exec"), scope)
    assert scope["refined"].shape == (4, 40, 24, 3)
    assert len(scope["motions"]) == 8 and scope["motions"][0].joints.shape == (60, 24, 3)


def test_doctor_reports_weights_evaluators_data_and_torch(no_shared):
    code, printed = _run(["doctor", "--json"])
    assert code == 0
    report = json.loads(printed)
    weights = {w["name"]: w for w in report["weights"]}
    assert set(weights) >= {"humanact12-motion", "humanact12", "humanact12-train", "generators", "evaluators"}
    assert all(w["verified"] and w["error"] is None for w in weights.values())
    assert sorted(weights["generators"]["entries"]) == ["a2m", "a2m-large", "actor", "actor-large", "mdm"]
    assert weights["humanact12-motion"]["kind"].startswith("motion model") and "all" in weights["humanact12-motion"]["entries"]
    assert "recognizer" in weights["humanact12"]["entries"] and "flaw_classifier" not in weights["humanact12"]["entries"]
    evaluators = {e["name"]: e for e in report["evaluators"]}
    assert evaluators["humanact12"]["shipped"] == evaluators["humanact12"]["used"]
    assert evaluators["ntu13"]["used"] is None and evaluators["ntu13"]["data_folder"] == []
    data = report["data"]
    assert data["env"] == "MOTION_REFINER_DATA" and data["env_value"] == str(no_shared)
    sources = {s["name"]: s for s in data["sources"]}
    assert sources["humanact12"]["missing"] == ["humanact12_joints.npz"] and sources["humanact12"]["found"] == []
    assert sources["humanact12"]["folder"] == str(no_shared / "humanact12")
    assert sources["evaluators"]["folder"] == str(no_shared.parent / "evaluators")
    import torch

    assert report["torch"]["version"] == torch.__version__
    assert report["torch"]["cuda_available"] == torch.cuda.is_available()
    assert report["threads"]["torch_threads"] >= 1 and report["threads"]["cpu_count"] >= 1


def test_doctor_prints_each_section(no_shared):
    code, printed = _run(["doctor"])
    assert code == 0
    assert re.search(r"evaluators\s+evaluators\s+verified; humanact12", printed)
    assert re.search(r"humanact12\s+shipped copy: .*humanact12_gru\.safetensors", printed)
    assert f"$MOTION_REFINER_DATA={no_shared}" in printed
    assert "missing humanact12_joints.npz" in printed and "torch " in printed and "threads: " in printed


@pytest.mark.parametrize("loader, files", [
    ("load_humanact12", ["humanact12_joints.npz", "humanact12/"]),
    ("load_cmu_mocap", ["cmu_mocap_labeled_joints.npz", "cmu_mocap/", "mocap.cs.cmu.edu"]),
])
def test_data_not_found_names_env_files_and_source(no_shared, loader, files):
    import refiner.io.datasets

    with pytest.raises(ValueError) as err:
        getattr(refiner.io.datasets, loader)()
    msg = str(err.value).replace("<data>/", "")
    for part in ["$MOTION_REFINER_DATA", str(no_shared), "ericguo5513.github.io/action-to-motion", *files]:
        assert part.rstrip("/") in msg, part


def test_missing_smpl_model_says_where_it_comes_from(no_shared, monkeypatch):
    from refiner.adapters.actor import load_smpl

    monkeypatch.delenv("MOTION_REFINER_SMPL", raising=False)
    with pytest.raises(ValueError, match=r"MOTION_REFINER_SMPL.*SMPL_NEUTRAL\.pkl.*smplify\.is\.tue\.mpg\.de"):
        load_smpl(None)
