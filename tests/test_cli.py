import json

import pytest

from refiner.cli import main


@pytest.mark.real_data
def test_concepts_command(tmp_path, capsys):
    from conftest import shared_data_dir

    data = shared_data_dir() / "humanact12" / "humanact12_joints.npz"
    code = main(["concepts", "--dataset", "humanact12", "--data", str(data), "--split", "test",
                 "--out", str(tmp_path / "c"), "--n-clusters", "4"])
    out = capsys.readouterr().out
    assert code == 0
    assert "clips        272" in out and "transitions" in out and "walk=4" in out
    meta = json.loads((tmp_path / "c" / "concepts.json").read_text())
    assert meta["summary"]["clips"] == 272


def test_bad_data_path_is_a_clean_error(tmp_path, capsys):
    code = main(["concepts", "--data", str(tmp_path / "none.npz"), "--out", str(tmp_path / "c")])
    assert code == 2
    assert "no HumanAct12 data" in capsys.readouterr().err


@pytest.mark.real_data
def test_bench_concepts_quick(capsys):
    from conftest import shared_data_dir

    assert main(["bench", "concepts", "--quick", "--data", str(shared_data_dir())]) == 0
    out = capsys.readouterr().out
    assert "paper Table 2 MPJPE" in out and "wall on this machine" in out


@pytest.mark.real_data
@pytest.mark.slow
def test_bench_refiner_and_speed_quick(capsys, tmp_path):
    """Tiny configurations of the refiner and speed suites run and print their figures."""
    from conftest import shared_data_dir

    assert main(["bench", "refiner", "--quick", "--data", str(shared_data_dir())]) == 0
    assert main(["bench", "speed", "--quick", "--data", str(shared_data_dir()), "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "(a) real clips: MPJPE change (cm)" in out and "anchor recognition recall" in out
    assert "pose mixture (default)" in out and "median ms / clip" in out
    assert "Speed" in (tmp_path / "REPORT.md").read_text()


@pytest.mark.real_data
@pytest.mark.slow
def test_bench_generators_quick(capsys):
    """The generator benchmark (reference generators before/after) runs tiny."""
    from conftest import shared_data_dir

    assert main(["bench", "generators", "--quick", "--data", str(shared_data_dir())]) == 0
    out = capsys.readouterr().out
    assert "| a2m | refined |" in out and "| actor | generated |" in out
