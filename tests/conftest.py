"""Shared fixtures: a seeded rng, small synthetic clips, and the real datasets from ../shared."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path:
    """``$MOTION_REFINER_DATA`` or ``../shared/data`` beside the repository."""
    return Path(os.environ.get("MOTION_REFINER_DATA", REPO.parent / "shared" / "data"))


def shared_dir() -> Path:
    return shared_data_dir().parent


def bench_json(suite: str, out: Path) -> dict:
    """Run ``motion-refiner bench SUITE --quick --out OUT`` on the real data; its ``<suite>.json``."""
    import json

    from refiner.cli.main import main

    assert main(["bench", suite, "--quick", "--data", str(shared_data_dir()), "--out", str(out)]) == 0
    return json.loads((Path(out) / f"{suite}.json").read_text())


@pytest.fixture
def rng():
    return np.random.default_rng(0)


@pytest.fixture
def tiny_clip():
    """A (41, 24, 3) clip made of two known cubic pieces joined at frame 20."""
    t = np.linspace(0.0, 1.0, 21)
    r = np.random.default_rng(1)
    a = r.normal(size=(4, 24, 3)) * 0.2
    b = r.normal(size=(4, 24, 3)) * 0.2
    basis = np.stack([t**3, t**2, t, np.ones_like(t)], -1)
    first = np.einsum("lk,kjc->ljc", basis, a)
    b[3] = first[-1]  # second piece starts where the first ends
    second = np.einsum("lk,kjc->ljc", basis, b)
    return np.concatenate([first, second[1:]]).astype(np.float32)


@pytest.fixture(scope="session")
def humanact12():
    """All 1,191 real HumanAct12 clips; fails (not skips) when the data are missing."""
    from refiner.io.datasets import load_humanact12

    path = shared_data_dir() / "humanact12" / "humanact12_joints.npz"
    if not path.is_file():
        pytest.fail(f"HumanAct12 not found at {path}; set MOTION_REFINER_DATA to the folder holding humanact12/.")
    return load_humanact12(path)


@pytest.fixture
def one_torch_thread():
    """One torch thread, as the CLI uses (tiny networks run several times faster); restored after."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture
def pm():
    from refiner.plugins.manager import get_plugin_manager

    return get_plugin_manager(autoload=False)
