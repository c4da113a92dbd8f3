"""``motion-refiner bench``: benchmarks that print figures (speed and quality targets live here).

Every suite is a function ``(data_dir, out_dir, quick) -> str`` returning a Markdown section that
is printed as it is produced and, with ``--out``, collected into ``REPORT.md``.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["SUITES", "run_benchmarks", "markdown_table"]


def markdown_table(header: list[str], rows: list[list]) -> str:
    def fmt(v):
        return f"{v:.3f}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def bench_concepts(data: Path | None, out: Path | None, quick: bool) -> str:
    """Segmentation speed on all HumanAct12 clips, the λ table beside the paper's Table 2, K-means."""
    from sklearn.cluster import KMeans

    from refiner.anchors import root_relative
    from refiner.datasets import load_humanact12
    from refiner.segmentation import DEFAULT_PENALTY, segment

    dataset = load_humanact12(None if data is None else Path(data) / "humanact12" / "humanact12_joints.npz")
    if quick:
        dataset = dataset.subset(range(0, len(dataset), 40))
    lines = [f"## Concepts (HumanAct12, {len(dataset)} clips, {dataset.n_frames} frames)", ""]

    t0 = time.perf_counter()
    segs = [segment(m.joints, penalty=DEFAULT_PENALTY) for m in dataset]
    seconds = time.perf_counter() - t0
    lines.append(f"Segmenting all {len(dataset)} clips at λ={DEFAULT_PENALTY:g}: **{seconds:.1f} s** "
                 f"wall on this machine (target: 30 s or less for 1,191 clips).")
    print(lines[-1], flush=True)

    paper = {100: (0.89, "97.7%"), 200: (0.94, "98.6%"), 300: (1.08, "98.3%"), 400: (1.22, "97.1%")}
    rows = []
    for lam in (100.0, 200.0, 300.0, 400.0):
        seg_l = segs if lam == DEFAULT_PENALTY else [segment(m.joints, penalty=lam) for m in dataset]
        n_trans = np.array([s.n_transitions for s in seg_l])
        durations = np.concatenate([s.durations for s in seg_l])
        err = [np.linalg.norm(s.reconstruct() - m.joints, axis=-1) for s, m in zip(seg_l, dataset)]
        overall = 100 * np.concatenate([e.ravel() for e in err]).mean()
        per_action = [100 * np.concatenate([e.ravel() for e, m in zip(err, dataset) if m.action == a]).mean()
                      for a in np.unique(dataset.actions)]
        rows.append([f"{lam:g}", float(n_trans.mean()), float(durations.mean()), float(overall),
                     float(np.mean(per_action)), paper[int(lam)][0]])
        print(f"  λ={lam:g}: {rows[-1][1]:.2f} transitions/clip, {rows[-1][2]:.1f} frames each, "
              f"MPJPE {overall:.3f} cm", flush=True)
    lines += ["", "λ in cm² per joint (see `refiner.segmentation`). MPJPE of the spline reconstruction, cm.", "",
              markdown_table(["λ", "transitions / clip", "mean transition frames", "MPJPE (all frames)",
                              "MPJPE (mean of actions)", "paper Table 2 MPJPE"], rows)]

    krows = []
    for a in np.unique(dataset.actions):
        poses = np.concatenate([root_relative(m.joints[s.anchors]) for s, m in zip(segs, dataset) if m.action == a])
        flat = poses.reshape(len(poses), -1)
        row = [dataset.action_names[a], len(poses)]
        for k in (2, 4, 8, 12, 16):
            if k > len(flat):
                row.append("-")
                continue
            km = KMeans(k, n_init=2, random_state=0).fit(flat)
            row.append(float(100 * np.linalg.norm(poses - km.cluster_centers_[km.labels_].reshape(poses.shape), axis=-1).mean()))
        krows.append(row)
    lines += ["", "Anchor K-means: mean joint distance to the assigned centre (cm) by number of clusters.", "",
              markdown_table(["action", "anchors", "k=2", "k=4", "k=8", "k=12", "k=16"], krows)]
    return "\n".join(lines)


SUITES: dict[str, Callable[[Path | None, Path | None, bool], str]] = {
    "concepts": bench_concepts,
}


def run_benchmarks(suite: str, *, data: Path | None = None, out: Path | None = None, quick: bool = False) -> int:
    names = list(SUITES) if suite == "all" else [suite]
    sections = []
    for name in names:
        section = SUITES[name](data, out, quick)
        print(section, flush=True)
        print(flush=True)
        sections.append(section)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "REPORT.md").write_text("# motion-refiner benchmark report\n\n" + "\n\n".join(sections) + "\n")
        print(f"report written to {out / 'REPORT.md'}")
    return 0
