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


def _humanact12_and_recognizer(data: Path | None, *, hidden: str):
    """HumanAct12 and the Action2Motion recogniser, from ``data`` (folder holding humanact12/) or the defaults."""
    from refiner.datasets import load_humanact12
    from refiner.evaluators import load_recognizer

    dataset = load_humanact12(None if data is None else Path(data) / "humanact12" / "humanact12_joints.npz")
    recognizer = load_recognizer("humanact12", hidden=hidden,
                                 directory=None if data is None else Path(data).parent / "evaluators")
    return dataset, recognizer


def bench_sanity(data: Path | None, out: Path | None, quick: bool) -> str:
    """Real held-out clips through the evaluation protocol: FID near zero and the recogniser's accuracy."""
    from refiner.metrics import evaluate

    dataset, recognizer = _humanact12_and_recognizer(data, hidden="random")
    test, train = dataset.split("test"), dataset.split("train")
    n_rep, n = (3, 300) if quick else (20, 1000)
    lines = [f"## Evaluator sanity (HumanAct12 recogniser, {len(test)} test clips of subjects 11-12 vs "
             f"{len(train)} train clips)", "",
             f"Action2Motion protocol: {n} random 60-frame crops per side (with replacement), fresh N(0,1) GRU "
             f"hidden state per replication, {n_rep} replications, mean ± 1.96·σ/√R. 'matched' draws the "
             "reference crops with the same action mixture.", ""]
    rows = []
    for label, gen, ref, match in (("test vs train", test, train, False),
                                   ("test vs train, matched", test, train, True),
                                   ("train vs train, matched (floor)", train, train, True)):
        t0 = time.perf_counter()
        ev = evaluate(recognizer, gen.motions, ref.motions, n_replications=n_rep, n_generated=n, n_real=n,
                      match_labels=match, random_state=0)
        s = ev.summary()
        rows.append([label, f"{s['fid'][0]:.3f} ± {s['fid'][1]:.3f}",
                     f"{100 * s['accuracy'][0]:.1f} ± {100 * s['accuracy'][1]:.1f}"]
                    + [f"{s[k][0]:.3f} ± {s[k][1]:.3f}" for k in ("diversity", "multimodality", "real_diversity")]
                    + [f"{time.perf_counter() - t0:.1f}"])
        print(f"  {label}: FID {s['fid'][0]:.3f}, accuracy {100 * s['accuracy'][0]:.1f} %", flush=True)
    lines.append(markdown_table(["comparison", "FID", "accuracy %", "diversity", "multimodality",
                                 "reference diversity", "seconds"], rows))
    return "\n".join(lines)


def bench_generators(data: Path | None, out: Path | None, quick: bool) -> str:
    """The shipped reference generators' samples before and after refinement, scored by the HumanAct12 recogniser."""
    import torch

    from refiner.pipeline import Refiner

    dataset, recognizer = _humanact12_and_recognizer(data, hidden="random")
    real = dataset.split("test")
    refiner = Refiner.pretrained("humanact12", split="train")
    # the paper's Table 1 protocol: 3,000 samples (250 per action), 20 replications
    per_action, n_rep = (3, 2) if quick else (250, 20)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small networks: one thread is several times faster on CPU
    try:
        return _bench_generators(dataset, recognizer, real, refiner, per_action, n_rep, out)
    finally:
        torch.set_num_threads(threads)


def _bench_generators(dataset, recognizer, real, refiner, per_action: int, n_rep: int, out: Path | None) -> str:
    import json

    from refiner.metrics import evaluate
    from refiner.reference_generators import GENERATOR_KINDS, load_reference_generator

    n_actions = len(dataset.action_names)
    lines = [f"## Reference generators (HumanAct12; {per_action} samples per action, refiner trained on subjects "
             f"1-10, reference: {len(real)} clips of subjects 11-12)", "",
             "Both generators were trained on subjects 1-10 (`motion-refiner train-generator`). Each sample is "
             "converted by the `action2motion` adapter and refined with its sampled action by "
             "`Refiner.pretrained(split=\"train\")`. Metrics follow the Action2Motion protocol "
             f"(`refiner.metrics.evaluate`, random GRU hidden state, {n_rep} replications, mean ± 95 % interval), "
             "real crops drawn with the generated action mixture. Accuracy is the recogniser's on the samples.", ""]
    rows, records = [], {}
    for kind in GENERATOR_KINDS:
        gen = load_reference_generator(kind)
        before = [m for a in range(n_actions)
                  for m in gen.sample_motions(a, per_action, random_state=1000 * a + 7)]
        t0 = time.perf_counter()
        joints, reports = refiner.refine(np.stack([m.joints for m in before]), action=[m.action for m in before],
                                         return_report=True)
        seconds = time.perf_counter() - t0
        after = [m.with_joints(j) for m, j in zip(before, joints)]
        changed = float(np.mean([r.changed_frames.mean() for r in reports]))
        flagged = float(np.mean([len(r.flagged_anchors) for r in reports]))
        for label, motions in (("generated", before), ("refined", after)):
            s = evaluate(recognizer, motions, real.motions, n_replications=n_rep, match_labels=True,
                         random_state=0).summary()
            row = [kind, label, f"{100 * s['accuracy'][0]:.1f} ± {100 * s['accuracy'][1]:.1f}",
                   f"{s['fid'][0]:.3f} ± {s['fid'][1]:.3f}", f"{s['diversity'][0]:.3f}",
                   f"{s['multimodality'][0]:.3f}"]
            row += [f"{100 * changed:.1f}", f"{flagged:.2f}", f"{seconds / len(before):.2f}"] if label == "refined" \
                else ["", "", ""]
            rows.append(row)
            records[f"{kind}/{label}"] = {k: list(v) for k, v in s.items()}
            print(f"  {kind} {label}: accuracy {100 * s['accuracy'][0]:.1f} %, FID {s['fid'][0]:.3f}", flush=True)
    s = evaluate(recognizer, dataset.split("train").motions, real.motions, n_replications=n_rep,
                 n_generated=per_action * n_actions, match_labels=True, random_state=0).summary()
    rows.append(["real clips (subjects 1-10)", "real", f"{100 * s['accuracy'][0]:.1f} ± {100 * s['accuracy'][1]:.1f}",
                 f"{s['fid'][0]:.3f} ± {s['fid'][1]:.3f}", f"{s['diversity'][0]:.3f}", f"{s['multimodality'][0]:.3f}",
                 "", "", ""])
    lines.append(markdown_table(["generator", "samples", "accuracy %", "FID", "diversity", "multimodality",
                                 "frames changed %", "flagged anchors / clip", "refine s / clip"], rows))
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        (Path(out) / "generators.json").write_text(json.dumps(records, indent=1))
    return "\n".join(lines)


def bench_refiner(data: Path | None, out: Path | None, quick: bool) -> str:
    """Issue-3 figures for the shipped subject-1-10 weights on held-out subjects 11-12.

    (a) how much real clips change, (b) velocity jumps where refined windows meet kept frames
    against real data's 99th percentile, (c) anchor recognition precision / recall against the
    segmentation, (d) refine latency per 60-frame clip (CPU, batch 1), parameter counts, and the
    anchor-quality comparison behind the ``quality`` default (pose mixture vs the paper's
    encoder-feature GMM, ROC AUC on seeded anchor flaws).
    """
    import torch
    from sklearn.metrics import roc_auc_score

    from refiner.datasets import load_humanact12
    from refiner.flaws import corrupt
    from refiner.physics import boundary_velocity_jump
    from refiner.pipeline import Refiner
    from refiner.recognition import match_anchors
    from refiner.segmentation import segment

    dataset = load_humanact12(None if data is None else Path(data) / "humanact12" / "humanact12_joints.npz")
    test = dataset.split("test")
    clips = test.motions[:: (16 if quick else 1)]
    model = Refiner.pretrained("humanact12", split="train")
    lines = [f"## Refiner (shipped subject-1-10 weights, {len(clips)} held-out clips of subjects 11-12)", ""]
    counts = model.n_parameters()
    lines.append("Parameters: " + ", ".join(f"{k} {v:,}" for k, v in counts.items()) + " (paper: 6.23 M).")

    segs = [segment(m.joints) for m in clips]
    change, frames, n_changed, tp, n_pred, n_ref = 0.0, 0, 0, 0, 0, 0
    jumps, refs = [], []
    for m, seg in zip(clips, segs):
        out, report = model.refine(m, return_report=True)
        err = np.linalg.norm(out.joints - m.joints, axis=-1).mean(-1)
        change, frames = change + err.sum(), frames + m.n_frames
        n_changed += bool(report.changes)
        counts_ = match_anchors(report.anchors, seg.anchors)
        tp, n_pred, n_ref = tp + counts_[0], n_pred + counts_[1], n_ref + counts_[2]
    real_acc = np.concatenate([np.linalg.norm(np.diff(m.joints, 2, axis=0), axis=-1).max(-1) * m.fps ** 2
                               for m in clips])
    # window boundaries need changes: refine clips with seeded anchor flaws and measure every splice
    for i, (m, seg) in enumerate(zip(clips, segs)):
        bad = corrupt(m, "anchor_drift", 3, random_state=i, segmentation=seg).motion
        out, report = model.refine(bad, return_report=True)
        mask = report.changed_frames
        if mask.any() and not mask.all():
            jump = boundary_velocity_jump(out, mask)
            jumps.append(jump.jump * m.fps)  # m/s per frame -> m/s²
    p99 = float(np.percentile(real_acc, 99))
    lines += ["", markdown_table(["figure", "value", "target"], [
        ["(a) real clips: MPJPE change (cm)", float(100 * change / frames), "< 0.3"],
        ["(a) real clips changed at all", f"{n_changed} / {len(clips)}", ""],
        ["(b) largest boundary acceleration (m/s²), refined drifted clips",
         float(max(jumps)) if jumps else "no boundary", f"real p99 {p99:.1f}"],
        ["(b) median boundary acceleration (m/s²)", float(np.median(jumps)) if jumps else "-", ""],
        ["(b) boundaries above real p99", f"{int(np.sum(np.array(jumps) > p99))} / {len(jumps)}", ""],
        ["(c) anchor recognition precision (±2 frames)", float(tp / max(n_pred, 1)), ""],
        ["(c) anchor recognition recall (±2 frames)", float(tp / max(n_ref, 1)), ""],
    ])]
    print(lines[-1], flush=True)

    window = [m.joints[:60] for m in clips if m.n_frames >= 60][: (5 if quick else 50)]
    for x in window[:3]:
        model.refine(x)  # warm up
    times = []
    for x in window:
        t0 = time.perf_counter()
        model.refine(x)
        times.append(time.perf_counter() - t0)
    lines += ["", f"(d) refine latency per 60-frame clip, CPU batch 1 ({torch.get_num_threads()} threads, "
                  f"{len(times)} clips): median **{1000 * np.median(times):.1f} ms**, "
                  f"90th percentile {1000 * np.percentile(times, 90):.1f} ms (paper: 17 ms on a GPU)."]
    print(lines[-1], flush=True)

    rows = []
    rng = np.random.default_rng(0)
    for family in ("anchor_drift", "wrong_anchor"):
        labels, pose_s, enc_s = [], [], []
        for i, (m, seg) in enumerate(zip(clips, segs)):
            a = seg.anchors
            if len(a) < 3:
                continue
            donors = [d for d in test.motions if d.action == m.action and d is not m][:5]
            bad = corrupt(m, family, 2, random_state=i, donors=donors, segmentation=seg).motion
            shift = np.linalg.norm(bad.joints - m.joints, axis=-1).mean(-1)[a]
            k_bad = int(np.argmax(shift[1:-1])) + 1
            k_real = int(rng.integers(1, len(a) - 1))
            for clip, k, label in ((m.joints, k_real, 0), (bad.joints, k_bad, 1)):
                labels.append(label)
                pose_s.append(-model.anchor_quality.score(clip[a[k]][None], m.action)[0])
                enc_s.append(-model.recognizer.recognize(clip, anchors=a).scores[k])
        rows.append([family, float(roc_auc_score(labels, pose_s)), float(roc_auc_score(labels, enc_s))])
    lines += ["", "Anchor quality scores, ROC AUC separating a seeded flawed anchor (severity 2) from a real one:", "",
              markdown_table(["flaw", "pose mixture (default)", "encoder-feature GMM (paper)"], rows)]
    return "\n".join(lines)


def bench_speed(data: Path | None, out: Path | None, quick: bool) -> str:
    """Refine latency (batch 1) and throughput (large batches), peak memory and parameters, CPU and CUDA."""
    import resource

    import torch

    from refiner.datasets import load_humanact12
    from refiner.pipeline import Refiner

    dataset = load_humanact12(None if data is None else Path(data) / "humanact12" / "humanact12_joints.npz")
    clips = [m.joints[:60] for m in dataset.split("test") if m.n_frames >= 60][: (8 if quick else 64)]
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    rows = []
    for device in devices:
        model = Refiner.load(Path(__file__).resolve().parent / "weights" / "humanact12-train", device=device)
        for x in clips[:3]:
            model.refine(x)  # warm up (first calls allocate and compile kernels)
        times = []
        for x in clips:
            t0 = time.perf_counter()
            model.refine(x)
            if device == "cuda":
                torch.cuda.synchronize()
            times.append(time.perf_counter() - t0)
        batch = np.stack([clips[i % len(clips)] for i in range(8 if quick else 256)])
        model.refine(batch[:8])
        runs = []
        for _ in range(1 if quick else 3):  # the median of three calls: one call is at the mercy of the machine
            t0 = time.perf_counter()
            model.refine(batch)
            runs.append(time.perf_counter() - t0)
        throughput = len(batch) / float(np.median(runs))
        peak = (torch.cuda.max_memory_allocated() / 2**20 if device == "cuda"
                else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
        rows.append([device, f"{torch.get_num_threads()} threads" if device == "cpu" else torch.cuda.get_device_name(),
                     float(1000 * np.median(times)), float(1000 * np.percentile(times, 90)), float(throughput),
                     f"{peak:.0f} MiB" + (" (process RSS)" if device == "cpu" else " (CUDA)")])
        print(f"  {device}: median {rows[-1][2]:.1f} ms per 60-frame clip", flush=True)
    counts = Refiner.pretrained("humanact12", split="train").n_parameters()
    return "\n".join([
        f"## Speed ({len(clips)} held-out 60-frame clips; paper: 0.017 s per clip, 6.23 M parameters)", "",
        markdown_table(["device", "", "median ms / clip (batch 1)", "p90 ms", f"clips / s (batch of {8 if quick else 256})", "peak memory"], rows),
        "", "Parameters: " + ", ".join(f"{k} {v:,}" for k, v in counts.items()) + ".",
        "" if "cuda" in devices else "No CUDA device here; run the same command on a GPU machine for the GPU rows.",
    ])


def _bench_flaws(data, out, quick, **kwargs):
    from refiner.bench_flaws import bench_flaws

    return bench_flaws(data, out, quick, **kwargs)


def _bench_samples(data, out, quick):
    from refiner.bench_samples import bench_samples

    return bench_samples(data, out, quick)


SUITES: dict[str, Callable[[Path | None, Path | None, bool], str]] = {
    "concepts": bench_concepts,
    "refiner": bench_refiner,
    "speed": bench_speed,
    "sanity": bench_sanity,
    "flaws": _bench_flaws,
    "samples": _bench_samples,
    "generators": bench_generators,
}


def run_benchmarks(suite: str, *, data: Path | None = None, out: Path | None = None, quick: bool = False,
                   stride: int = 1, severities: tuple[int, ...] | None = None) -> int:
    names = list(SUITES) if suite == "all" else [suite]
    sections = []
    for name in names:
        extra = {"stride": stride, "severities": severities} if name == "flaws" else {}
        section = SUITES[name](data, out, quick, **extra)
        print(section, flush=True)
        print(flush=True)
        sections.append(section)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "REPORT.md").write_text("# motion-refiner benchmark report\n\n" + "\n\n".join(sections) + "\n")
        print(f"report written to {out / 'REPORT.md'}")
    return 0
