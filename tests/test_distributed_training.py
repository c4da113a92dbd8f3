"""Data-parallel training of the motion model: ``torchrun --nproc_per_node 2`` (gloo) against one process.

Two processes draw one half of every batch each (their own clips, their own random stream) and DDP averages the
gradients; one process with ``shards=2`` draws both halves and averages the same gradients, so the two runs must
log the same losses and end with the same weights, up to float rounding. Run as a script, this file is one process
of the torchrun group.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

#: A tiny network and a few steps (the comparison, not the model, is under test), then a few more from the checkpoint.
STEPS, RESUMED_STEPS = 4, 6


def _train(data: Path, out: Path, steps: int, shards=None) -> list[dict]:
    """Train the tiny configuration on the clips of ``data`` (.npz) into ``out``; the progress records logged."""
    import torch

    from refiner.refinement.motion_model import N_CONTEXT
    from refiner.refinement.networks.motion_net import MotionNetConfig
    from refiner.refinement.training.mechanisms import MECHANISMS
    from refiner.refinement.training.motion_training import TrainConfig, train_motion_model

    torch.set_num_threads(1)
    with np.load(data) as f:
        clips = [f[f"clip_{i}"] for i in range(int(f["n"]))]
        actions = [int(a) for a in f["actions"]]
    lines = []
    train_motion_model(clips, actions, skeleton="humanact12", action_names=[f"a{i}" for i in range(12)],
                       mechanisms={k: MECHANISMS[k] for k in ("time_hold", "angle_turn")}, out=out,
                       config=TrainConfig(steps=steps, batch=4, crops=(32,), checkpoint_every=2),
                       network=MotionNetConfig(n_bones=23, n_actions=12, width=16, dilations=(1, 2), n_context=N_CONTEXT),
                       log=lines.append, shards=shards)
    return [json.loads(line) for line in lines if line.startswith("{")]


@pytest.fixture(scope="module")
def clips_file(tmp_path_factory, humanact12):
    path = tmp_path_factory.mktemp("ddp") / "clips.npz"
    chosen = [m for m in humanact12 if m.n_frames >= 40][:8]
    np.savez(path, n=len(chosen), actions=[m.action for m in chosen], **{f"clip_{i}": m.joints for i, m in enumerate(chosen)})
    return path


def _torchrun(clips_file: Path, out: Path) -> list[list[dict]]:
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2", __file__,
           str(clips_file), str(out)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=240, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads((out / "log.json").read_text())


def _weights(path: Path) -> dict:
    from safetensors.torch import load_file

    return {k: v.numpy() for k, v in load_file(str(path)).items()}


def test_two_processes_train_as_one_process_with_two_shards(clips_file, tmp_path):
    """Same losses at every checkpoint and the same weights, before and after resuming from the checkpoint."""
    ddp = _torchrun(clips_file, tmp_path / "ddp")
    one = [_train(clips_file, tmp_path / "one", steps, shards=2) for steps in (STEPS, RESUMED_STEPS)]
    assert [[r["step"] for r in run] for run in ddp] == [[r["step"] for r in run] for run in one] == [[2, 4], [6]]
    for a, b in zip(ddp[0] + ddp[1], one[0] + one[1]):
        np.testing.assert_allclose([a["recon"], a["flaw"]], [b["recon"], b["flaw"]], rtol=1e-4)
    wa, wb = _weights(tmp_path / "ddp" / "motion_model.safetensors"), _weights(tmp_path / "one" / "motion_model.safetensors")
    assert wa.keys() == wb.keys()
    for k in wa:
        np.testing.assert_allclose(wa[k], wb[k], rtol=1e-4, atol=1e-5, err_msg=k)


def test_shards_must_divide_the_batch(clips_file, tmp_path):
    with pytest.raises(ValueError, match="shards"):
        _train(clips_file, tmp_path, 1, shards=3)


if __name__ == "__main__":  # one process of `torchrun --nproc_per_node 2 THIS DATA OUT`: train, then resume further
    from refiner.nn.distributed import finish_distributed, init_distributed, is_main_process

    init_distributed()
    records = [_train(Path(sys.argv[1]), Path(sys.argv[2]), steps) for steps in (STEPS, RESUMED_STEPS)]
    if is_main_process():
        (Path(sys.argv[2]) / "log.json").write_text(json.dumps(records))
    finish_distributed()
