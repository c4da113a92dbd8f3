"""Training of the motion model: real clips, random masks, and the flaw mechanisms of one fold.

Every batch holds random crops of real clips turned about the vertical, most spoiled by one training mechanism
(:mod:`refiner.refinement.training.mechanisms`) and half with a random window of parts hidden. The network learns the clean
features everywhere (in-filling what is hidden) and which frames and parts differ from the clean clip. Resumable:
a checkpoint every ``checkpoint_every`` steps; one progress line per checkpoint in ``log``.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch

from refiner.core.bone_directions import subtree_bones, to_bone_directions
from refiner.core.rotations import rotvec_to_rotmat
from refiner.core.skeletons import get_skeleton
from refiner.nn.distributed import OnDevice, barrier, group_device, init_distributed, is_main_process, mean_across, world
from refiner.refinement.motion_model import MotionModel, ground_context, motion_features
from refiner.refinement.networks.motion_net import MotionNet, MotionNetConfig

__all__ = ["TrainConfig", "train_motion_model", "corrupted_batch", "flaw_labels", "TRAIN_SUBJECTS", "CALIBRATION_SUBJECTS"]

#: HumanAct12: the network learns on subjects 1-8; subjects 9-10 calibrate its thresholds; 11-12 stay for the benchmark.
TRAIN_SUBJECTS = tuple(range(1, 9))
CALIBRATION_SUBJECTS = (9, 10)


def training_split(dataset) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the clips the network learns on and of those that calibrate it (real, unseen by it); the test
    subjects are in neither. HumanAct12: subjects 1-8 and 9-10; CMU: its train subjects, every 5th calibrating."""
    subjects = np.asarray(dataset.subjects)
    if dataset.name == "humanact12":
        return np.flatnonzero(np.isin(subjects, TRAIN_SUBJECTS)), np.flatnonzero(np.isin(subjects, CALIBRATION_SUBJECTS))
    train = np.unique(dataset.split("train").subjects)
    calibration = train[::5]
    learn = np.isin(subjects, train) & ~np.isin(subjects, calibration)
    return np.flatnonzero(learn), np.flatnonzero(np.isin(subjects, calibration))


@dataclass(frozen=True)
class TrainConfig:
    """Schedule and corruption of :func:`train_motion_model`."""

    steps: int = 4000
    batch: int = 32
    crops: tuple = (32, 48, 64)
    lr: float = 1e-3
    clean_share: float = 0.25
    hidden_share: float = 0.5
    severity: tuple = (0.5, 1.5)
    unknown_action_share: float = 0.3
    direction_tolerance: float = 0.1
    root_tolerance_m: float = 0.02
    checkpoint_every: int = 200
    seed: int = 0


def flaw_labels(clean, flawed, skeleton, config: TrainConfig) -> np.ndarray:
    """``(T, P)`` bool: bones whose direction moved more than ``direction_tolerance`` (unit-vector distance) and the
    root where it moved more than ``root_tolerance_m``."""
    r0, d0, _ = to_bone_directions(clean, skeleton)
    r1, d1, _ = to_bone_directions(flawed, skeleton)
    bones = np.linalg.norm(d1 - d0, axis=-1) > config.direction_tolerance
    root = np.linalg.norm(r1 - r0, axis=-1) > config.root_tolerance_m
    return np.concatenate([bones, root[:, None]], -1)


def _hidden_window(n_frames: int, skel, rng) -> np.ndarray:
    """``(T, P)`` bool: a random window of 3-20 frames of one subtree, the root, or the whole body."""
    hidden = np.zeros((n_frames, len(skel.bones) + 1), bool)
    length = int(rng.integers(3, min(20, n_frames - 2) + 1))
    start = int(rng.integers(1, n_frames - length))
    kind = rng.random()
    if kind < 0.5:
        parts = subtree_bones(skel, int(rng.integers(1, skel.n_joints)))
        if len(parts) == 0:
            parts = np.array([int(rng.integers(len(skel.bones)))])
    elif kind < 0.7:
        parts = np.array([len(skel.bones)])
    else:
        parts = np.arange(len(skel.bones) + 1)
    hidden[start:start + length, parts] = True
    return hidden


def _turned(clip, skel, rng) -> np.ndarray:
    """The clip turned about the vertical through its first root by a random angle."""
    rot = rotvec_to_rotmat(skel.up_vector * rng.uniform(0, 2 * np.pi))
    origin = clip[0, skel.root]
    return (clip - origin) @ rot.T


def corrupted_batch(clips, actions, mechanisms: dict, skel, config: TrainConfig, rng) -> dict:
    """One training batch (numpy): ``features`` of the spoiled crops, ``hidden``, ``labels``, ``target`` (clean
    features) and ``action``."""
    length = int(rng.choice(config.crops))
    pool = [i for i, c in enumerate(clips) if len(c) >= length] or list(range(len(clips)))
    names = list(mechanisms)
    feats, context, hidden, labels, target, acts = [], [], [], [], [], []
    for _ in range(config.batch):
        i = int(rng.choice(pool))
        start = int(rng.integers(0, max(1, len(clips[i]) - length + 1)))
        clean = _turned(np.asarray(clips[i][start:start + length], np.float64), skel, rng)
        flawed = clean
        if names and rng.random() > config.clean_share:
            severity = rng.uniform(*config.severity)
            flawed = mechanisms[names[int(rng.integers(len(names)))]](clean, rng, severity, skeleton=skel.name)
        lab = flaw_labels(clean, flawed, skel, config)
        hid = _hidden_window(len(clean), skel, rng) if rng.random() < config.hidden_share else np.zeros_like(lab)
        feats.append(motion_features(flawed[None], skel)[0][0])
        context.append(ground_context(flawed[None], skel)[0])
        target.append(motion_features(clean[None], skel)[0][0])
        labels.append(lab & ~hid)
        hidden.append(hid)
        acts.append(None if rng.random() < config.unknown_action_share else actions[i])
    return {"features": np.stack(feats), "context": np.stack(context), "hidden": np.stack(hidden), "labels": np.stack(labels),
            "target": np.stack(target), "action": acts}


def _loss(model: MotionModel, net, batch) -> tuple[torch.Tensor, dict]:
    shown, h = model.inputs(batch["features"], batch["hidden"], batch["context"])
    lab = torch.as_tensor(batch["labels"]).float()
    target = torch.as_tensor(batch["target"])
    expand = torch.arange(h.shape[-1]).repeat_interleave(3)
    clean, logits = net(shown, h, model.action_index(batch["action"], len(shown)))
    focus = 1.0 + 4.0 * (h | lab.bool()).float()[..., expand]
    recon = (focus * (clean - target) ** 2).mean()
    flaw = torch.nn.functional.binary_cross_entropy_with_logits(logits, lab, reduction="none")
    flaw = (flaw * ~h).sum() / (~h).sum().clamp(min=1)
    return recon + flaw, {"recon": recon.item(), "flaw": flaw.item()}


def train_motion_model(clips, actions, *, skeleton: str, action_names, mechanisms: dict, out: str | Path,
                       config: TrainConfig = TrainConfig(), log=print, network: MotionNetConfig | None = None,
                       shards: int | None = None) -> MotionModel:
    """Train (or resume, from ``out/checkpoint.pt``) a :class:`MotionModel` on real ``clips`` ((T, J, 3) metres) with
    ``actions`` (index or None each); writes ``out/motion_model.safetensors`` and returns the model.

    ``network``: the network's sizes (default: :class:`MotionModel`'s). ``shards`` (default: the world size, 1 alone):
    every batch is drawn in this many equal parts, part ``k`` from clips ``k, k + shards, ...`` with a random stream of
    its own, and the gradient is the mean of the parts'. Under ``torchrun`` (:func:`refiner.nn.distributed.init_distributed`)
    rank ``k`` draws part ``k`` and DDP averages the gradients, so N processes train as one process with ``shards=N``;
    rank 0 alone writes the checkpoint, the weights and ``log``.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rank, size = world()
    shards = size if shards is None else int(shards)
    if size > 1 and shards != size:
        raise ValueError(f"under torchrun `shards` must be the world size ({size}); got {shards}.")
    if shards < 1 or config.batch % shards or len(clips) < shards:
        raise ValueError(f"`shards` must be at least 1 and divide the batch ({config.batch}) and the clips "
                         f"({len(clips)}) into non-empty parts; got {shards}.")
    log = log if rank == 0 else (lambda line: None)
    skel = get_skeleton(skeleton)
    model = MotionModel(skel.name, action_names, network)
    torch.manual_seed(config.seed)
    net = MotionNet(model.config).to(group_device())
    opt = torch.optim.AdamW(net.parameters(), lr=config.lr, weight_decay=1e-4)
    step, ckpt = 0, out / "checkpoint.pt"
    if ckpt.is_file():
        state = torch.load(ckpt, weights_only=True, map_location="cpu")
        net.load_state_dict(state["network"])
        opt.load_state_dict(state["optimizer"])
        step = int(state["step"])
        log(f"resumed at step {step}")
    mine = range(shards) if size == 1 else [rank]
    part = config if shards == 1 else replace(config, batch=config.batch // shards)
    # one part: today's stream; parts: a stream each, so N ranks draw what one process with shards=N draws
    rngs = [np.random.default_rng([config.seed, step] + ([k] if shards > 1 else [])) for k in mine]
    trained = _data_parallel(net) if size > 1 else net
    t0, running = time.perf_counter(), []
    net.train()
    while step < config.steps:
        for g in opt.param_groups:  # cosine decay with 100 warm-up steps
            g["lr"] = config.lr * min(1.0, (step + 1) / 100) * 0.5 * (1 + math.cos(math.pi * step / config.steps))
        opt.zero_grad()
        losses = []
        for k, rng in zip(mine, rngs):
            batch = corrupted_batch(clips[k::shards], actions[k::shards], mechanisms, skel, part, rng)
            loss, parts = _loss(model, trained, batch)
            (loss / len(mine)).backward()
            losses.append(parts)
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        running.append({k: float(np.mean([p[k] for p in losses])) for k in losses[0]})
        step += 1
        if step % config.checkpoint_every == 0 or step == config.steps:
            mean = mean_across({k: float(np.mean([r[k] for r in running])) for k in running[0]})
            if rank == 0:  # written whole, then renamed: a run killed while saving resumes from the previous one
                torch.save({"network": net.state_dict(), "optimizer": opt.state_dict(), "step": step}, f"{ckpt}.tmp")
                Path(f"{ckpt}.tmp").replace(ckpt)
            log(json.dumps({"step": step, "seconds": round(time.perf_counter() - t0, 1), **mean}))
            running = []
    training = {"config": {**asdict(config), "crops": list(config.crops), "severity": list(config.severity)},
                "mechanisms": sorted(mechanisms), "clips": len(clips), "steps": step, **({"shards": shards} if shards > 1 else {})}
    model.set_network(net.cpu(), training)
    if rank == 0:
        model.save(out / "motion_model.safetensors")
    barrier()
    return model


def _data_parallel(net):
    """``net`` wrapped for DDP; on a GPU it takes and gives CPU tensors (:class:`refiner.nn.distributed.OnDevice`)."""
    from torch.nn.parallel import DistributedDataParallel

    device = group_device()
    if device.type == "cuda":
        return OnDevice(DistributedDataParallel(net, device_ids=[device]), device)
    return DistributedDataParallel(net)


def main(argv=None) -> int:
    """``python -m refiner.refinement.training.motion_training --out DIR [--dataset D] [--fold 0|1] [--steps N]``: train
    on the dataset's learning clips (:func:`training_split`) with the mechanisms of every fold but ``--fold`` (all
    without it). Under ``torchrun`` the processes train one model together (:func:`train_motion_model`)."""
    import argparse

    from refiner.refinement.training.mechanisms import MECHANISMS
    from refiner.io.datasets import load_dataset

    p = argparse.ArgumentParser()
    p.add_argument("--out", required=True)
    p.add_argument("--fold", type=int, default=None, help="the fold held out (its mechanisms are not trained on)")
    p.add_argument("--steps", type=int, default=TrainConfig.steps)
    p.add_argument("--dataset", default="humanact12", choices=["humanact12", "cmu_mocap"])
    p.add_argument("--data", default=None, help="the dataset's file (default: the shared data folder's)")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    init_distributed()
    ds = load_dataset(args.dataset, args.data)
    keep = [i for i in training_split(ds)[0] if ds[i].n_frames >= min(TrainConfig.crops)]
    mechanisms = {k: m for k, m in MECHANISMS.items() if args.fold is None or m.fold != args.fold}
    log_path = Path(args.out) / "progress.log"
    Path(args.out).mkdir(parents=True, exist_ok=True)

    def log(line):
        if is_main_process():  # rank 0 writes for all
            with open(log_path, "a") as f:
                f.write(line + "\n")
    log(f"training on {len(keep)} clips, mechanisms {sorted(mechanisms)}" + (f", {world()[1]} processes" if world()[1] > 1 else ""))
    train_motion_model([ds[i].joints for i in keep], [ds[i].action for i in keep], skeleton=ds[0].skeleton,
                       action_names=ds.action_names, mechanisms=mechanisms, out=args.out,
                       config=TrainConfig(steps=args.steps), log=log)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
