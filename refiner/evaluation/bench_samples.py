"""``motion-refiner bench samples``: real generator output before and after refinement.

The real Action2Motion xyz-VAE samples in ``../shared/samples/action2motion`` (20 clips of 60
frames with their labels) are converted by the ``action2motion`` adapter, refined with their
labels by the subject-1-10 weights, and scored: the HumanAct12 recogniser's accuracy (mean over
20 random GRU hidden states, the Action2Motion protocol), bone-length variation, frames changed,
and what each clip's report says changed and why.
"""
from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np

from refiner.evaluation.bench import _humanact12_and_recognizer, markdown_table

__all__ = ["bench_samples", "sample_records"]


def sample_records(before, labels, recognizer, refiner, *, n_hidden: int = 20, actions=None) -> dict:
    """Accuracy, bone-length variation and changes of ``before`` (Motions) and their refinement;
    the refiner gets ``actions`` (default ``labels``; None each: unknown, e.g. NTU13 labels)."""
    from refiner.evaluation.physics import acceleration, bone_length_variation

    actions = list(labels) if actions is None else list(actions)
    after, reports = refiner.refine(np.stack([m.joints for m in before]), action=actions, return_report=True)
    after = [m.with_joints(a) for m, a in zip(before, after)]
    out = {}
    for label, motions in (("generated", before), ("refined", after)):
        acc = [float(np.mean(recognizer.predict(motions, crop="start", random_state=seed) == labels))
               for seed in range(n_hidden)]
        out[label] = {
            "accuracy": float(np.mean(acc)), "accuracy_std": float(np.std(acc)),
            "bone_length_variation": float(np.mean([bone_length_variation(m) for m in motions])),
            "acceleration": float(np.mean([np.mean(acceleration(m)) for m in motions])),
        }
    changed = [np.abs(a.joints - b.joints).max(-1).max(-1) > 0 for a, b in zip(after, before)]
    out["frames_changed"] = float(np.mean([c.mean() for c in changed]))
    steps = Counter(c["step"] for r in reports for c in r.changes)
    out["changes_by_step"] = dict(steps)
    out["repaired_frames"] = float(np.mean([sum(c["stop"] - c["start"] for c in r.changes if c["step"] != "skeleton")
                                            / r.n_frames for r in reports]))
    out["reports"] = [{"label": int(a), "changes": r.changes} for a, r in zip(labels, reports)]
    return out


def bench_samples(data: Path | None, out: Path | None, quick: bool) -> str:
    """Real Action2Motion samples before / after (see the module docstring)."""
    from refiner.io.datasets import default_data_dir
    from refiner.plugins.manager import convert
    from refiner.refinement.pipeline import Refiner

    _, recognizer = _humanact12_and_recognizer(data, hidden="random")
    folder = (default_data_dir() if data is None else Path(data)).parent / "samples" / "action2motion"
    path, labels_path = folder / "humanact12_xyz_vae_samples.npy", folder / "humanact12_xyz_vae_labels.npy"
    if not path.is_file():
        from refiner.io.data_sources import missing_message

        return f"## Real generator samples\n\n({missing_message('samples', path)}; skipped)"
    labels = np.load(labels_path).astype(np.int64).ravel()
    before = convert("action2motion", np.load(path), representation="xyz", recenter=True)
    if quick:
        before, labels = before[:5], labels[:5]
    refiner = Refiner.pretrained("humanact12", split="train")
    rec = sample_records(before, labels, recognizer, refiner, n_hidden=5 if quick else 20)
    lines = _section(f"Real generator samples (Action2Motion xyz VAE, {len(before)} clips, subject-1-10 weights)",
                     "HumanAct12", rec, "at least 85")
    ntu = _ntu13_records(data, folder, quick)
    if isinstance(ntu, str):
        lines += ["", ntu]
    else:
        rec["ntu13"] = ntu
        lines += [""] + _section(f"NTU13 samples (Action2Motion xyz VAE, 18 joints, skeleton 'uestc', {ntu['clips']} "
                                 "clips; refined through the HumanAct12 weights with the action unknown)",
                                 "NTU13", ntu, "not lower")
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        (Path(out) / "samples.json").write_text(json.dumps(rec, indent=1))
    return "\n".join(lines)


def _section(title: str, recogniser: str, rec: dict, accuracy_target: str) -> list[str]:
    """The markdown lines of one set of samples' :func:`sample_records`."""
    g, r = rec["generated"], rec["refined"]
    rows = [[f"{recogniser} recogniser accuracy %", 100 * g["accuracy"], 100 * r["accuracy"], accuracy_target],
            ["bone-length variation % (std / mean per bone)", 100 * g["bone_length_variation"],
             100 * r["bone_length_variation"], "under 1"],
            ["mean joint acceleration (m/s²)", g["acceleration"], r["acceleration"], ""],
            ["frames changed % (any step)", "", 100 * rec["frames_changed"], ""],
            ["frames repaired % (flaw repair only)", "", 100 * rec["repaired_frames"], ""]]
    return [f"## {title}", "", markdown_table(["figure", "generated", "refined", "target"], rows), "",
            "Changes by step (over all clips): " + (", ".join(f"{k} {v}" for k, v in rec["changes_by_step"].items())
                                                  or "none") + ".", "",
            "First clip's report: " + (json.dumps(rec["reports"][0]["changes"]) if rec["reports"] else "-")]


def _ntu13_records(data, folder: Path, quick: bool):
    """:func:`sample_records` of the 18-joint NTU13 samples with the NTU13 recogniser, or why not."""
    from refiner.evaluation.evaluators import load_recognizer
    from refiner.plugins.manager import convert
    from refiner.refinement.pipeline import Refiner

    path, labels_path = folder / "ntu13_xyz_vae_samples.npy", folder / "ntu13_xyz_vae_labels.npy"
    if not (path.is_file() and labels_path.is_file()):
        from refiner.io.data_sources import missing_message

        return f"({missing_message('samples', path)}; NTU13 samples skipped)"
    try:
        evaluators = None if data is None else Path(data).parent / "evaluators"
        recognizer = load_recognizer("ntu13", hidden="random", directory=evaluators)
    except ValueError as e:
        return f"(NTU13 samples skipped: {e})"
    labels = np.load(labels_path).astype(np.int64).ravel()
    before = convert("action2motion", np.load(path), representation="xyz", recenter=True, skeleton="uestc")
    if quick:
        before, labels = before[:5], labels[:5]
    rec = sample_records(before, labels, recognizer, Refiner.pretrained("uestc", split="train"),
                         n_hidden=5 if quick else 20, actions=[None] * len(before))
    rec["clips"] = len(before)
    return rec
